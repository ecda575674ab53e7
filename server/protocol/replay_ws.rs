//! The messages of the replay WebSocket, `GET /ws/replays/{id}` (docs/api.md).
//!
//! Snapshots and events are the live socket's own ([`crate::protocol::ws`]), so a page
//! draws a replay with the renderer it draws a match with; what is new is here: the first
//! message (`replay`, the live `welcome`'s counterpart), `replay_status` whenever playing,
//! pausing or the speed changes, and the client's controls ([`ReplayControl`]).

use axum::extract::ws::Utf8Bytes;
use serde::{Deserialize, Serialize};

use crate::maps::MapFile;
use crate::protocol::ws::Kinematics;
use crate::protocol::{Invalid, deserialize_at, invalid};

/// The slowest and fastest a replay plays, as multiples of real time.
pub const MIN_SPEED: f64 = 0.25;
pub const MAX_SPEED: f64 = 8.0;

/// A control message from a replay's viewer. Unknown types and fields are errors.
#[derive(Debug, Clone, PartialEq)]
pub enum ReplayControl {
    Play,
    Pause,
    /// Show tick `tick` now (and play on from there if playing).
    Seek {
        tick: u64,
    },
    Speed {
        speed: f64,
    },
    /// Switch the team's belief on or off in the snapshots, as on the live socket.
    Belief {
        on: bool,
    },
    /// Answered with a `pong` carrying the same `t`, as on the live socket.
    Ping {
        t: f64,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Nothing {}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SeekMsg {
    /// An integer, also written as `40.0` (as everywhere in the API).
    #[serde(deserialize_with = "crate::schema::int")]
    tick: i64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SpeedMsg {
    speed: f64,
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

fn fields<T: serde::de::DeserializeOwned>(v: serde_json::Value) -> Result<T, Invalid> {
    deserialize_at(v, "message")
}

const TYPES: &str = "play, pause, seek, speed, belief or ping";

/// `speed` if it is a speed a replay plays at, else what is wrong with it.
pub fn check_speed(field: &str, speed: f64) -> Result<f64, Invalid> {
    if speed.is_finite() && (MIN_SPEED..=MAX_SPEED).contains(&speed) {
        Ok(speed)
    } else {
        Err(invalid(
            field,
            format!("{speed} must be in {MIN_SPEED}..={MAX_SPEED}"),
        ))
    }
}

impl ReplayControl {
    /// Parses and range-checks a viewer's text message, naming what is wrong. Whether a
    /// seek's tick is one of the replay's is for the caller, who knows the replay.
    pub fn parse(text: &str) -> Result<ReplayControl, Invalid> {
        let mut v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| invalid("message", format!("not JSON: {e}")))?;
        let Some(obj) = v.as_object_mut() else {
            return Err(invalid("message", "must be a JSON object with a \"type\""));
        };
        let kind = match obj.remove("type") {
            Some(serde_json::Value::String(s)) => s,
            Some(_) => return Err(invalid("type", "must be a string")),
            None => return Err(invalid("type", format!("missing ({TYPES})"))),
        };
        match kind.as_str() {
            "play" => fields::<Nothing>(v).map(|_| ReplayControl::Play),
            "pause" => fields::<Nothing>(v).map(|_| ReplayControl::Pause),
            "seek" => {
                let tick = fields::<SeekMsg>(v)?.tick;
                u64::try_from(tick)
                    .map(|tick| ReplayControl::Seek { tick })
                    .map_err(|_| invalid("tick", format!("{tick} must be 0 or more")))
            }
            "speed" => Ok(ReplayControl::Speed {
                speed: check_speed("speed", fields::<SpeedMsg>(v)?.speed)?,
            }),
            "belief" => Ok(ReplayControl::Belief {
                on: fields::<BeliefMsg>(v)?.on,
            }),
            "ping" => {
                let t = fields::<PingMsg>(v)?.t;
                if !t.is_finite() {
                    return Err(invalid("t", format!("{t} must be a finite number")));
                }
                Ok(ReplayControl::Ping { t })
            }
            other => Err(invalid(
                "type",
                format!("unknown message type {other:?} ({TYPES})"),
            )),
        }
    }
}

/// Limits a viewer should know (sent in the first message).
#[derive(Debug, Clone, Serialize)]
pub struct ReplayLimits {
    pub max_message_bytes: usize,
    /// Sustained messages per second, and how many may come at once.
    pub messages_per_s: f64,
    pub burst: f64,
    /// Seeks carried out per second at most: more are not refused, only the latest waiting
    /// one is shown when the next is due.
    pub seeks_per_s: f64,
}

/// The first message on a replay socket: the replay, and what the live `welcome` gives a
/// page to draw with.
#[derive(Debug, Clone, Serialize)]
pub struct ReplayWelcome<'a> {
    #[serde(rename = "type")]
    pub kind: &'static str,
    pub id: &'a str,
    pub map: MapFile,
    /// The replay's last tick.
    pub ticks: u64,
    /// The tick shown first.
    pub tick: u64,
    pub tick_hz: u32,
    pub time_limit_s: f64,
    pub speed: f64,
    pub playing: bool,
    /// `full` (everything, as spectators saw it) or the opponent whose view this is.
    pub view: String,
    /// As in the live `welcome`: `player` (a person's fogged view) or `spectator`.
    pub role: &'static str,
    pub you: Option<String>,
    /// The person who played `you`, when one did.
    pub name: Option<String>,
    pub belief_every: u64,
    pub belief: bool,
    pub kinematics: Kinematics,
    pub protocol: u32,
    pub format: &'static str,
    pub limits: ReplayLimits,
}

#[derive(Debug, Clone, Serialize)]
struct Status {
    #[serde(rename = "type")]
    kind: &'static str,
    tick: u64,
    playing: bool,
    speed: f64,
}

#[derive(Debug, Clone, Serialize)]
struct ErrorWire<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    /// `error` as on the live socket (pages already read it), `message` the same text.
    error: &'a str,
    message: &'a str,
}

fn to_json<T: Serialize>(v: &T) -> String {
    // Plain structs of numbers and strings: serialising them cannot fail.
    serde_json::to_string(v).unwrap_or_else(|e| format!(r#"{{"type":"error","error":"{e}"}}"#))
}

pub fn welcome(w: &ReplayWelcome<'_>) -> Utf8Bytes {
    Utf8Bytes::from(to_json(w))
}

/// `replay_status`: where the replay is, whether it plays and how fast.
pub fn status(tick: u64, playing: bool, speed: f64) -> Utf8Bytes {
    Utf8Bytes::from(to_json(&Status {
        kind: "replay_status",
        tick,
        playing,
        speed,
    }))
}

pub fn error(message: &str) -> Utf8Bytes {
    Utf8Bytes::from(to_json(&ErrorWire {
        kind: "error",
        error: message,
        message,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn controls_are_parsed_strictly() {
        assert_eq!(
            ReplayControl::parse(r#"{"type":"play"}"#),
            Ok(ReplayControl::Play)
        );
        assert_eq!(
            ReplayControl::parse(r#"{"type":"seek","tick":40.0}"#),
            Ok(ReplayControl::Seek { tick: 40 })
        );
        assert_eq!(
            ReplayControl::parse(r#"{"type":"seek","tick":40}"#),
            Ok(ReplayControl::Seek { tick: 40 })
        );
        assert_eq!(
            ReplayControl::parse(r#"{"type":"speed","speed":0.25}"#),
            Ok(ReplayControl::Speed { speed: 0.25 })
        );
        let e = |text: &str| match ReplayControl::parse(text) {
            Ok(m) => panic!("{text} parsed as {m:?}"),
            Err(e) => e.to_string(),
        };
        assert_eq!(
            e(r#"{"type":"speed","speed":9}"#),
            "speed: 9 must be in 0.25..=8"
        );
        assert!(e(r#"{"type":"pause","x":1}"#).contains("unknown field `x`"));
        assert_eq!(
            e(r#"{"type":"seek","tick":-1}"#),
            "tick: -1 must be 0 or more"
        );
        assert!(e(r#"{"type":"seek","tick":1.5}"#).starts_with("tick"));
        assert!(e(r#"{"type":"rewind"}"#).starts_with("type: unknown message type"));
        assert!(e(r#"{"tick":3}"#).starts_with("type: missing"));
        assert!(e("[]").starts_with("message"));
        assert!(e("not json").starts_with("message: not JSON"));
    }
}
