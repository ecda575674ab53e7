//! The messages of the replay WebSocket, `GET /ws/replays/{id}` (docs/api.md).
//!
//! Snapshots and events are the live socket's own ([`crate::protocol::ws`]), so a page
//! draws a replay with the renderer it draws a match with; what is new is here: the first
//! message (`replay`, the live `welcome`'s counterpart), `replay_status` whenever playing,
//! pausing or the speed changes, and the client's controls ([`ReplayControl`]). `pong`,
//! `belief` and `ping` are the live socket's ([`crate::protocol::socket`]); `error` too, with
//! its text in `message` as well as in `error` (the live socket's field, which pages read).

use axum::extract::ws::Utf8Bytes;
use serde::{Deserialize, Serialize};

use crate::maps::MapFile;
use crate::protocol::socket::{self, Limits, to_json};
use crate::protocol::ws::Kinematics;
use crate::protocol::{Invalid, invalid};

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
        let (kind, v) = socket::typed(text, TYPES)?;
        match kind.as_str() {
            "play" => socket::fields::<Nothing>(v).map(|_| ReplayControl::Play),
            "pause" => socket::fields::<Nothing>(v).map(|_| ReplayControl::Pause),
            "seek" => {
                let tick = socket::fields::<SeekMsg>(v)?.tick;
                u64::try_from(tick)
                    .map(|tick| ReplayControl::Seek { tick })
                    .map_err(|_| invalid("tick", format!("{tick} must be 0 or more")))
            }
            "speed" => Ok(ReplayControl::Speed {
                speed: check_speed("speed", socket::fields::<SpeedMsg>(v)?.speed)?,
            }),
            "belief" => socket::belief(v).map(|on| ReplayControl::Belief { on }),
            "ping" => socket::ping(v).map(|t| ReplayControl::Ping { t }),
            other => Err(socket::unknown_type(other, TYPES)),
        }
    }
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
    pub limits: Limits,
}

#[derive(Debug, Clone, Serialize)]
struct Status {
    #[serde(rename = "type")]
    kind: &'static str,
    tick: u64,
    playing: bool,
    speed: f64,
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
