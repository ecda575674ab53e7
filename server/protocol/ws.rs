//! The WebSocket messages of `GET /ws/matches/{id}` (`docs/api.md`), as
//! implemented and documented in docs/api.md.
//!
//! Server to client, JSON text with a `type`: `welcome` (once, first), `snapshot` (every
//! tick), `event` (as in the events endpoint), `finished` (once, at the end), `pong`, `error`
//! (those two, and what `belief` and `ping` hold, as the replay socket has them:
//! [`crate::protocol::socket`]). Client to server: `input`, `belief`, `ping` ([`ClientMessage`]).
//!
//! Sizes: positions are metres rounded to millimetres, headings to 1e-4 rad, scan ranges are
//! integer centimetres, belief points integer centimetres in one flat array `[x0, y0, x1, …]`.

use std::sync::OnceLock;

use axum::extract::ws::Utf8Bytes;
use serde::{Deserialize, Serialize};

use crate::game::view::{BeliefView, Frame, Visible};
use crate::maps::MapFile;
use crate::protocol::socket::{self, Limits, to_json};
use crate::protocol::{EventDto, OpponentControl, PoseDto, Status, Winner, status, winner};
use crate::protocol::{Invalid, invalid};
use lasertag_core::sim::{AgentId, Pose};
use lasertag_core::world::{Event, MarkKind};

/// Serialised forms of one frame, built by the first connection that needs them and shared
/// by all the others (so 500 spectators cost one serialisation per tick, not 500).
#[derive(Debug, Default)]
pub struct WireCache {
    spectator: OnceLock<Utf8Bytes>,
    spectator_belief: OnceLock<Utf8Bytes>,
    belief: OnceLock<String>,
    /// Compact spectator snapshots, by (with the belief, with the slow parts).
    compact: [OnceLock<axum::body::Bytes>; 4],
}

/// A message from a client. Unknown types and fields are errors.
#[derive(Debug, Clone, PartialEq)]
pub enum ClientMessage {
    /// A player's keys. Numbered (`seq`), each is applied for one tick, in order, and
    /// acknowledged in the player's snapshots; without a number, the latest holds until
    /// the next.
    Input {
        forward: f64,
        turn: f64,
        tag: bool,
        seq: Option<u64>,
        /// The tick whose robots the page was drawing (a shot is judged there, within a
        /// bound).
        view_tick: Option<u64>,
    },
    /// Switch the team's belief on or off in this connection's snapshots.
    Belief { on: bool },
    /// Answered at once with a `pong` carrying the same `t` (for the ping display).
    Ping { t: f64 },
    /// A player points at `(x, y)` (metres) for their side.
    Mark { x: f64, y: f64, kind: MarkKind },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MarkMsg {
    x: f64,
    y: f64,
    kind: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct InputMsg {
    forward: f64,
    turn: f64,
    #[serde(default)]
    tag: bool,
    #[serde(default)]
    seq: Option<u64>,
    #[serde(default)]
    view_tick: Option<u64>,
}

const TYPES: &str = "input, mark, belief or ping";

impl ClientMessage {
    /// Parses and range-checks a client's text message, naming what is wrong.
    pub fn parse(text: &str) -> Result<ClientMessage, Invalid> {
        let (kind, v) = socket::typed(text, TYPES)?;
        match kind.as_str() {
            "input" => {
                let m: InputMsg = socket::fields(v)?;
                for (field, v) in [("forward", m.forward), ("turn", m.turn)] {
                    if !(v.is_finite() && (-1.0..=1.0).contains(&v)) {
                        return Err(invalid(field, format!("{v} must be in -1..=1")));
                    }
                }
                Ok(ClientMessage::Input {
                    forward: m.forward,
                    turn: m.turn,
                    tag: m.tag,
                    seq: m.seq,
                    view_tick: m.view_tick,
                })
            }
            "mark" => {
                let m: MarkMsg = socket::fields(v)?;
                for (field, v) in [("x", m.x), ("y", m.y)] {
                    if !v.is_finite() {
                        return Err(invalid(field, format!("{v} must be a finite number")));
                    }
                }
                let kind = MarkKind::parse(&m.kind).ok_or_else(|| {
                    invalid("kind", format!("{:?} is not robot, go or danger", m.kind))
                })?;
                Ok(ClientMessage::Mark {
                    x: m.x,
                    y: m.y,
                    kind,
                })
            }
            "belief" => socket::belief(v).map(|on| ClientMessage::Belief { on }),
            "ping" => socket::ping(v).map(|t| ClientMessage::Ping { t }),
            other => Err(socket::unknown_type(other, TYPES)),
        }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct Welcome<'a> {
    #[serde(rename = "type")]
    pub kind: &'static str,
    #[serde(rename = "match")]
    pub match_id: &'a str,
    /// `player` or `spectator`.
    pub role: &'static str,
    /// The agent this connection plays, for a player: an opponent (`o0`) or a robot of the
    /// team's pursuer slots (`r1`).
    pub you: Option<String>,
    /// A player's side: `opponents` or `robots`.
    pub team: Option<&'static str>,
    pub name: Option<String>,
    pub map: MapFile,
    pub tick_hz: u32,
    pub time_limit_s: f64,
    /// The belief is sent with every this many ticks' snapshot (when switched on).
    pub belief_every: u64,
    /// Whether this connection's snapshots carry the belief now.
    pub belief: bool,
    /// How far behind the match spectators' snapshots run (0: live). A player's own view is
    /// live; once its opponent is tagged it watches as spectators do, this far behind.
    pub spectator_delay_s: f64,
    /// For a spectator of a delayed match that is younger than its delay: seconds until its
    /// view starts to move (until then it shows the match's first frame, the agents at their
    /// starts). 0 once it moves, and for a live view.
    pub view_starts_in_s: f64,
    /// How the player's body (an opponent, or a robot) moves, for prediction on the client.
    pub kinematics: Kinematics,
    /// Whether the match counts for ratings (docs/ratings.md): the page shows the player's
    /// rating change at the end.
    pub rated: bool,
    /// The version of these messages (2: numbered inputs, `ack`, compact snapshots).
    pub protocol: u32,
    /// `json` or `compact`: how this connection's snapshots come (`?format=`).
    pub format: &'static str,
    pub limits: Limits,
}

/// The motion of an agent, as the server simulates it (`core/sim/motion.rs`): each tick
/// of `dt` seconds it turns by `turn × turn_rate × dt` and moves `forward × speed × dt` along
/// the mean heading of the tick, then its disc of `radius` slides out of walls and agents.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Kinematics {
    pub dt: f64,
    /// Metres per second at `forward` 1.
    pub speed: f64,
    /// Radians per second at `turn` 1.
    pub turn_rate: f64,
    pub radius: f64,
}

impl Kinematics {
    /// How `body` moves: an opponent, or a robot (its speed and turn rate).
    pub fn of(physics: &lasertag_core::sim::Physics, body: AgentId) -> Kinematics {
        // The core's `f32`s, as the decimals they were written as (no `0.05000000074505806`).
        let exact = |v: f32| ((v as f64) * 1e6).round() / 1e6;
        let (speed, turn_rate) = match body {
            AgentId::Opponent(_) => (physics.opponent_speed, physics.opponent_turn_rate),
            AgentId::Robot(_) => (physics.robot_speed, physics.robot_turn_rate),
        };
        Kinematics {
            dt: 1.0 / lasertag_core::sim::TICK_HZ as f64,
            speed: exact(speed),
            turn_rate: exact(turn_rate),
            radius: exact(lasertag_core::sim::AGENT_RADIUS),
        }
    }
}

#[derive(Debug, Clone, Serialize)]
struct RobotWire {
    id: String,
    x: f64,
    y: f64,
    theta: f64,
    frozen: bool,
    /// The person driving it (a pursuer slot somebody holds).
    #[serde(skip_serializing_if = "Option::is_none")]
    name: Option<String>,
    /// Spectators only: where its planner sends it.
    #[serde(skip_serializing_if = "Option::is_none")]
    goal: Option<PoseDto>,
    /// Spectators, and the person driving it: this tick's ranges in centimetres, beam i at
    /// bearing (i - 90)°.
    #[serde(skip_serializing_if = "Option::is_none")]
    scan: Option<Vec<u16>>,
    /// Spectators only: where the robot believes it is, and how spread out that belief is.
    #[serde(skip_serializing_if = "Option::is_none")]
    estimate: Option<PoseDto>,
    #[serde(skip_serializing_if = "Option::is_none")]
    spread: Option<f64>,
    /// Spectators only: a sample of its localisation particles, flat `[x0, y0, …]` in cm.
    #[serde(skip_serializing_if = "Option::is_none")]
    cloud: Option<Vec<i32>>,
}

#[derive(Debug, Clone, Serialize)]
struct OpponentWire {
    /// `o0`, `o1`, …; `o?` for an anonymous sighting (a person on the robot team's view).
    id: String,
    x: f64,
    y: f64,
    /// Absent from an anonymous sighting: the robots' detector cannot tell a heading.
    #[serde(skip_serializing_if = "Option::is_none")]
    theta: Option<f64>,
    tagged: bool,
    /// Absent from an anonymous sighting.
    #[serde(skip_serializing_if = "Option::is_none")]
    control: Option<OpponentControl>,
    #[serde(skip_serializing_if = "Option::is_none")]
    name: Option<String>,
}

/// The id an anonymous sighting of an opponent goes by.
pub const ANONYMOUS_OPPONENT: &str = "o?";

#[derive(Debug, Clone, Serialize)]
struct Score {
    /// Opponents the robots have tagged.
    tags: usize,
    /// Robots the opponents have tagged (each freezes it for 10 s).
    robot_tags: u32,
    opponents: usize,
    opponents_left: usize,
    robots_frozen: usize,
}

#[derive(Debug, Clone, Serialize)]
struct Snapshot<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    tick: u64,
    time_s: f64,
    time_left_s: f64,
    status: Status,
    winner: Option<Winner>,
    /// `player` (line of sight only) or `spectator` (everything).
    view: &'static str,
    you: Option<&'a str>,
    /// A player's: the `seq` of its last numbered input applied (0 before the first).
    #[serde(skip_serializing_if = "Option::is_none")]
    ack: Option<u64>,
    robots: Vec<RobotWire>,
    opponents: Vec<OpponentWire>,
    score: Score,
}

#[derive(Debug, Clone, Serialize)]
struct RoleWire {
    id: u64,
    count: u32,
    tagged: bool,
    /// 0..=1, to two decimals, and `valid` / `suspicious` / `invalid`.
    confidence: f64,
    state: crate::protocol::ConfidenceState,
    /// Particles the tracker holds (the points below are a thinned sample).
    particles: usize,
    mean: [f64; 2],
    /// Flat `[x0, y0, x1, y1, …]` in centimetres.
    points: Vec<i32>,
}

#[derive(Debug, Clone, Serialize)]
struct BeliefWire {
    tick: u64,
    roles: Vec<RoleWire>,
}

#[derive(Debug, Clone, Serialize)]
struct EventWire<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    #[serde(flatten)]
    event: &'a EventDto,
}

#[derive(Debug, Clone, Serialize)]
struct Finished {
    #[serde(rename = "type")]
    kind: &'static str,
    tick: u64,
    winner: Option<Winner>,
    reason: Option<&'static str>,
    time_s: f64,
}

fn mm(v: f32) -> f64 {
    ((v as f64) * 1000.0).round() / 1000.0
}

fn rad(v: f32) -> f64 {
    ((v as f64) * 10_000.0).round() / 10_000.0
}

fn pose(p: Pose) -> PoseDto {
    PoseDto {
        x: mm(p.pos.x),
        y: mm(p.pos.y),
        theta: rad(p.theta),
    }
}

fn snapshot_json(frame: &Frame, you: Option<AgentId>, visible: Option<&Visible>) -> String {
    let spectator = visible.is_none();
    let you_name = you.map(|y| y.to_string());
    let snap = Snapshot {
        kind: "snapshot",
        tick: frame.tick,
        time_s: frame.time_s,
        time_left_s: ((frame.time_limit_s - frame.time_s).max(0.0) * 100.0).round() / 100.0,
        status: status(frame.status),
        winner: winner(frame.winner),
        view: match visible {
            None => "spectator",
            Some(v) if v.teammates => "teammates",
            Some(_) => "player",
        },
        you: you_name.as_deref(),
        ack: you.and_then(|id| match id {
            AgentId::Opponent(i) => frame.opponents.get(i).map(|o| o.ack),
            AgentId::Robot(i) => frame.robots.get(i).map(|r| r.ack),
        }),
        robots: frame
            .robots
            .iter()
            .enumerate()
            .filter(|(i, _)| visible.is_none_or(|v| v.robots[*i]))
            .map(|(i, r)| RobotWire {
                id: AgentId::Robot(i).to_string(),
                x: mm(r.pose.pos.x),
                y: mm(r.pose.pos.y),
                theta: rad(r.pose.theta),
                frozen: r.frozen,
                name: r.player.as_deref().map(str::to_string),
                goal: if spectator { r.goal.map(pose) } else { None },
                scan: (spectator || you == Some(AgentId::Robot(i))).then(|| {
                    r.scan
                        .iter()
                        .map(|v| (v * 100.0).round().clamp(0.0, u16::MAX as f32) as u16)
                        .collect()
                }),
                estimate: spectator.then(|| pose(r.estimate)),
                spread: spectator.then(|| mm(r.spread)),
                cloud: spectator.then(|| r.cloud.iter().flatten().copied().collect()),
            })
            .collect(),
        opponents: {
            let anonymous = visible.is_some_and(|v| v.anonymous);
            let mut shown: Vec<OpponentWire> = frame
                .opponents
                .iter()
                .enumerate()
                .filter(|(i, _)| visible.is_none_or(|v| v.opponents[*i]))
                .map(|(i, o)| OpponentWire {
                    id: if anonymous {
                        ANONYMOUS_OPPONENT.to_string()
                    } else {
                        AgentId::Opponent(i).to_string()
                    },
                    x: mm(o.pose.pos.x),
                    y: mm(o.pose.pos.y),
                    theta: (!anonymous).then(|| rad(o.pose.theta)),
                    tagged: o.tagged,
                    control: (!anonymous).then(|| o.control.into()),
                    name: (!anonymous)
                        .then(|| o.player.as_deref().map(str::to_string))
                        .flatten(),
                })
                .collect();
            if anonymous {
                // In the order of where they are: the slots' order would tell who is who.
                shown.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
            }
            shown
        },
        score: Score {
            tags: frame.opponents.iter().filter(|o| o.tagged).count(),
            robot_tags: frame.robot_tags,
            opponents: frame.opponents.len(),
            opponents_left: frame.opponents.iter().filter(|o| !o.tagged).count(),
            robots_frozen: frame.robots.iter().filter(|r| r.frozen).count(),
        },
    };
    to_json(&snap)
}

fn belief_json(b: &BeliefView) -> String {
    to_json(&BeliefWire {
        tick: b.tick,
        roles: b
            .roles
            .iter()
            .map(|r| RoleWire {
                id: r.id,
                count: r.count,
                tagged: r.tagged,
                confidence: (r.confidence as f64 * 100.0).round() / 100.0,
                state: r.state.into(),
                particles: r.particles,
                mean: [mm(r.mean[0]), mm(r.mean[1])],
                points: r.points.iter().flat_map(|p| [p[0], p[1]]).collect(),
            })
            .collect(),
    })
}

/// The frame's shared encodings (made by the first viewer that asks).
fn cache(frame: &Frame) -> Option<&WireCache> {
    frame.encoded.get::<WireCache>()
}

/// `make()`, kept in `cell` of the frame's cache when there is one.
fn cached<T: Clone>(cell: Option<&OnceLock<T>>, make: impl FnOnce() -> T) -> T {
    match cell {
        Some(cell) => cell.get_or_init(make).clone(),
        None => make(),
    }
}

/// Appends `"belief": …`, the belief `frame` carries, to a serialised snapshot object.
fn with_belief(snapshot: String, frame: &Frame) -> String {
    match &frame.belief {
        Some(b) => {
            let belief = cached(cache(frame).map(|c| &c.belief), || belief_json(b));
            append_belief(snapshot, &belief)
        }
        None => snapshot,
    }
}

/// Appends `"belief": <belief>` (serialised) to a serialised snapshot object.
fn append_belief(mut snapshot: String, belief: &str) -> String {
    if snapshot.ends_with('}') {
        snapshot.pop();
        snapshot.push_str(",\"belief\":");
        snapshot.push_str(belief);
        snapshot.push('}');
    }
    snapshot
}

/// The snapshot every spectator gets: serialised once per frame and shared.
pub fn spectator_snapshot(frame: &Frame, belief: bool) -> Utf8Bytes {
    let plain = || {
        cached(cache(frame).map(|c| &c.spectator), || {
            Utf8Bytes::from(snapshot_json(frame, None, None))
        })
    };
    if belief && frame.belief.is_some() {
        cached(cache(frame).map(|c| &c.spectator_belief), || {
            Utf8Bytes::from(with_belief(plain().as_str().to_string(), frame))
        })
    } else {
        plain()
    }
}

/// A spectator's compact snapshot (see [`crate::protocol::compact`]): serialised once per
/// frame and variant, and shared.
pub fn spectator_compact(frame: &Frame, belief: bool, slow: bool) -> axum::body::Bytes {
    let belief = belief && frame.belief.is_some();
    cached(
        cache(frame).map(|c| &c.compact[belief as usize * 2 + slow as usize]),
        || {
            let belief = frame.belief.as_deref().filter(|_| belief);
            crate::protocol::compact::snapshot(frame, None, None, belief, slow).into()
        },
    )
}

/// A player's snapshot: what its body sees (an opponent's line of sight, a robot's laser,
/// [`crate::game::view::visible_to`]), plus the belief that `belief` (a frame carrying one)
/// holds, when given.
pub fn player_snapshot(
    frame: &Frame,
    you: AgentId,
    visible: &Visible,
    belief: Option<&Frame>,
) -> Utf8Bytes {
    let json = snapshot_json(frame, Some(you), Some(visible));
    Utf8Bytes::from(match belief {
        // A robot's own belief is this player's alone: serialised for it, not shared.
        Some(b) => match b.own_belief(you) {
            Some(own) => append_belief(json, &belief_json(own)),
            None => with_belief(json, b),
        },
        None => json,
    })
}

/// An `event` message.
pub fn event(e: &Event) -> Utf8Bytes {
    Utf8Bytes::from(to_json(&EventWire {
        kind: "event",
        event: &crate::protocol::event(e),
    }))
}

/// An `event` message as a player is told of it live: a person on the robot team
/// (`anonymous`) is not told which opponent shot, was hit or was tagged, which the team's
/// detector cannot tell (`o?`); a join or a departure is public and keeps its slot.
pub fn event_seen(e: &Event, anonymous: bool) -> Utf8Bytes {
    if !anonymous {
        return event(e);
    }
    let mut dto = crate::protocol::event(e);
    let hide = |id: &mut Option<String>| {
        if id.as_deref().is_some_and(|i| i.starts_with('o')) {
            *id = Some(ANONYMOUS_OPPONENT.to_string());
        }
    };
    hide(&mut dto.by);
    hide(&mut dto.target);
    if let Some(hit) = dto.hit.as_mut() {
        hide(hit);
    }
    Utf8Bytes::from(to_json(&EventWire {
        kind: "event",
        event: &dto,
    }))
}

/// The `moved` message: the match goes on on another server, at `url` when known (else the
/// lobby, `GET /api/matches/{id}` on any node, says where); the socket closes after it.
#[derive(Serialize)]
struct Moved<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    url: Option<&'a str>,
}

pub fn moved(url: Option<&str>) -> Utf8Bytes {
    Utf8Bytes::from(to_json(&Moved { kind: "moved", url }))
}

/// The `finished` message, from the match's `finished` event.
pub fn finished(frame: &Frame) -> Utf8Bytes {
    let e = frame.finished.as_ref().map(crate::protocol::event);
    let e = e.as_ref();
    Utf8Bytes::from(to_json(&Finished {
        kind: "finished",
        tick: e.map_or(frame.tick, |e| e.tick),
        winner: winner(frame.winner),
        reason: e.and_then(|e| e.reason),
        time_s: e.and_then(|e| e.time_s).unwrap_or(frame.time_s),
    }))
}

/// The `finished` a client gets when the server shuts down before its match has ended:
/// nobody won, reason `server_shutdown` (the same as the match's own `finished` event then).
pub fn finished_by_shutdown(frame: &Frame) -> Utf8Bytes {
    if frame.status == lasertag_core::world::MatchStatus::Finished {
        return finished(frame);
    }
    Utf8Bytes::from(to_json(&Finished {
        kind: "finished",
        tick: frame.tick,
        winner: None,
        reason: Some("server_shutdown"),
        time_s: frame.time_s,
    }))
}

pub fn welcome(w: &Welcome<'_>) -> Utf8Bytes {
    Utf8Bytes::from(to_json(w))
}

#[cfg(test)]
mod tests;
