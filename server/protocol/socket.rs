//! What the WebSockets say alike (`GET /ws/matches/{id}` and `GET /ws/replays/{id}`,
//! docs/api.md): how a client's text message names its `type`, the controls both take
//! (`belief`, `ping`), the limits a first message announces, and the `pong` and `error`
//! answers. Each socket's own messages are in [`crate::protocol::ws`] and
//! [`crate::protocol::replay_ws`].

use axum::extract::ws::Utf8Bytes;
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::config::Config;
use crate::protocol::{Invalid, deserialize_at, invalid};

/// A client's text message taken apart: its `type`, and the rest for that type's fields.
/// `types` lists the types the socket takes ("input, belief or ping"), for the errors.
pub fn typed(text: &str, types: &str) -> Result<(String, serde_json::Value), Invalid> {
    let mut v: serde_json::Value =
        serde_json::from_str(text).map_err(|e| invalid("message", format!("not JSON: {e}")))?;
    let Some(obj) = v.as_object_mut() else {
        return Err(invalid("message", "must be a JSON object with a \"type\""));
    };
    match obj.remove("type") {
        Some(serde_json::Value::String(s)) => Ok((s, v)),
        Some(_) => Err(invalid("type", "must be a string")),
        None => Err(invalid("type", format!("missing ({types})"))),
    }
}

/// The refusal of a `type` the socket does not take.
pub fn unknown_type(kind: &str, types: &str) -> Invalid {
    invalid("type", format!("unknown message type {kind:?} ({types})"))
}

/// Deserialises a message's fields strictly (unknown fields are errors), naming the field
/// of the failure.
pub fn fields<T: DeserializeOwned>(v: serde_json::Value) -> Result<T, Invalid> {
    deserialize_at(v, "message")
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct BeliefMsg {
    on: bool,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PingMsg {
    t: f64,
}

/// `belief`'s fields: whether the team's belief goes out with the snapshots.
pub fn belief(v: serde_json::Value) -> Result<bool, Invalid> {
    Ok(fields::<BeliefMsg>(v)?.on)
}

/// `ping`'s fields: the `t` its `pong` carries back, a finite number.
pub fn ping(v: serde_json::Value) -> Result<f64, Invalid> {
    let t = fields::<PingMsg>(v)?.t;
    if !t.is_finite() {
        return Err(invalid("t", format!("{t} must be a finite number")));
    }
    Ok(t)
}

/// What a client may send, announced in a socket's first message, and what is particular
/// to the socket.
#[derive(Debug, Clone, Serialize)]
pub struct Limits {
    pub max_message_bytes: usize,
    /// Sustained messages per second.
    pub messages_per_s: f64,
    /// Messages that may come at once.
    pub burst: f64,
    /// The live socket's: seconds a dropped player has to come back with the same token.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reconnect_s: Option<f64>,
    /// The replay socket's: seeks carried out per second at most: more are not refused,
    /// only the latest waiting one is shown when the next is due.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seeks_per_s: Option<f64>,
}

impl Limits {
    /// The message limits of `config`, nothing particular.
    pub fn of(config: &Config) -> Limits {
        Limits {
            max_message_bytes: config.max_message_bytes,
            messages_per_s: config.messages_per_s,
            burst: config.message_burst,
            reconnect_s: None,
            seeks_per_s: None,
        }
    }
}

#[derive(Debug, Clone, Serialize)]
struct ErrorWire<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    error: &'a str,
    /// The replay socket's: the same text as `error`.
    #[serde(skip_serializing_if = "Option::is_none")]
    message: Option<&'a str>,
}

#[derive(Debug, Clone, Serialize)]
struct Pong {
    #[serde(rename = "type")]
    kind: &'static str,
    t: f64,
}

pub(crate) fn to_json<T: Serialize>(v: &T) -> String {
    // Plain structs of numbers and strings: serialising them cannot fail.
    serde_json::to_string(v).unwrap_or_else(|e| format!(r#"{{"type":"error","error":"{e}"}}"#))
}

/// `error`: what was wrong with the client's last message.
pub fn error(message: &str) -> Utf8Bytes {
    Utf8Bytes::from(to_json(&ErrorWire {
        kind: "error",
        error: message,
        message: None,
    }))
}

/// `error` with the text in `message` as well (the replay socket's).
pub fn error_with_message(message: &str) -> Utf8Bytes {
    Utf8Bytes::from(to_json(&ErrorWire {
        kind: "error",
        error: message,
        message: Some(message),
    }))
}

/// `pong`: a `ping`'s answer, with its `t`.
pub fn pong(t: f64) -> Utf8Bytes {
    Utf8Bytes::from(to_json(&Pong { kind: "pong", t }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_answers_keep_their_shapes() {
        assert_eq!(error("x").as_str(), r#"{"type":"error","error":"x"}"#);
        assert_eq!(
            error_with_message("x").as_str(),
            r#"{"type":"error","error":"x","message":"x"}"#
        );
        assert_eq!(pong(1.5).as_str(), r#"{"type":"pong","t":1.5}"#);
    }

    #[test]
    fn limits_name_only_what_the_socket_has() {
        let limits = Limits {
            max_message_bytes: 1,
            messages_per_s: 2.0,
            burst: 3.0,
            reconnect_s: Some(4.0),
            seeks_per_s: None,
        };
        assert_eq!(
            to_json(&limits),
            r#"{"max_message_bytes":1,"messages_per_s":2.0,"burst":3.0,"reconnect_s":4.0}"#
        );
    }

    #[test]
    fn a_message_names_what_is_wrong_with_its_type() {
        let e = |text: &str| typed(text, "a or b").unwrap_err().to_string();
        assert!(e("[]").starts_with("message: must be a JSON object"));
        assert!(e("nope").starts_with("message: not JSON"));
        assert_eq!(e(r#"{"type":1}"#), "type: must be a string");
        assert_eq!(e(r#"{"t":1}"#), "type: missing (a or b)");
        let (kind, rest) = typed(r#"{"type":"ping","t":2}"#, "a or b").unwrap();
        assert_eq!(kind, "ping");
        assert_eq!(ping(rest), Ok(2.0));
    }
}
