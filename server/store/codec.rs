//! How a match is written down for the store: its settings ([`StoredSettings`]: everything
//! [`MatchConfig`] holds that a match can differ in, plus the shell's clock and delay) and
//! its inputs ([`encode_inputs`]: JSON lines, one input a line, deflated in chunks).
//!
//! The core has no serde on purpose, so these shapes live here, beside the one place that
//! reads them back. Settings groups go through their declared fields (`settings::Group`), as
//! requests do; fields a request cannot set are derived as a request derives them
//! (`localise::Settings::for_odometry`): a stored match rebuilds its config, field for field.

use std::io::{Read, Write};

use flate2::Compression;
use flate2::read::DeflateDecoder;
use flate2::write::DeflateEncoder;
use lasertag_core::difficulty::Difficulty;
use lasertag_core::settings::{Group, Value};
use lasertag_core::sim::{AgentId, Odometry};
use lasertag_core::world::{
    FinishReason, HumanInput, MarkKind, MatchConfig, OpponentOrder, Placement, RobotOrder, World,
    WorldInput,
};
use lasertag_core::{localise, planner, radio, tracker};
use nalgebra::Point2;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value as Json};

mod live;
mod names;
mod party;
pub use live::{StoredLive, StoredPerson, StoredSeat};
pub use names::StoredClock;
use names::{StoredBot, StoredControl, StoredDifficulty, StoredPlanner};
pub use party::{MemberRecord, PartyRecord};

/// A stored match that cannot be read back.
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    #[error("stored settings: {0}")]
    Settings(String),
    #[error("stored inputs: {0}")]
    Inputs(String),
    #[error("stored checkpoint: {0}")]
    Checkpoint(String),
}

/// The version of [`StoredSettings`] this build writes and reads.
const SETTINGS_VERSION: u32 = 1;

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// Everything that defines a match besides its map, as the store keeps it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StoredSettings {
    v: u32,
    robots: usize,
    opponents: usize,
    opponent_control: StoredControl,
    opponent_bot: StoredBot,
    planner: StoredPlanner,
    /// The trained policy that drove the robots (`MatchConfig::policy`): a replay needs only
    /// its name (the actions are in the record), a resumed match its model.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    policy: Option<String>,
    /// Robots driven from outside beside planned ones (`MatchConfig::outside_robots`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    outside_robots: Vec<bool>,
    /// Robots that are seats for people (`MatchConfig::pursuer_slots`).
    #[serde(default, skip_serializing_if = "is_zero")]
    pursuer_slots: usize,
    seed: u64,
    time_limit_ticks: u64,
    placement: StoredPlacement,
    localisation: bool,
    tracker: Map<String, Json>,
    coordination: Map<String, Json>,
    radio: Map<String, Json>,
    odometry: Map<String, Json>,
    localiser: Map<String, Json>,
    pub clock: StoredClock,
    pub bots_joinable: bool,
    pub spectator_delay_ticks: u64,
    /// The robot team's preset (its robot speed and tag cool-down are stored nowhere else).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    difficulty: Option<StoredDifficulty>,
    /// Whether it counted for ratings (docs/ratings.md).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub rated: bool,
}

#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
enum StoredPlacement {
    Spawns,
    Random,
    Given {
        robots: Vec<[f32; 3]>,
        opponents: Vec<[f32; 2]>,
    },
}

/// A settings group as a JSON object of every declared field.
fn group_out<G: Group>(g: &G) -> Map<String, Json> {
    G::FIELDS
        .iter()
        .filter_map(|f| {
            let v = match g.get(f.name)? {
                Value::Integer(i) => Json::from(i),
                Value::Number(x) => Json::from(x),
                Value::Bool(b) => Json::from(b),
            };
            Some((f.name.to_string(), v))
        })
        .collect()
}

/// `base` with the fields of `m` set, each checked as a request's would be.
fn group_in<G: Group>(mut base: G, m: &Map<String, Json>) -> Result<G, CodecError> {
    for (name, v) in m {
        let value = match v {
            Json::Bool(b) => Value::Bool(*b),
            Json::Number(n) => match n.as_i64() {
                Some(i)
                    if G::field(name)
                        .is_some_and(|f| f.kind == lasertag_core::settings::Kind::Integer) =>
                {
                    Value::Integer(i)
                }
                _ => Value::Number(n.as_f64().unwrap_or(f64::NAN)),
            },
            other => {
                return Err(CodecError::Settings(format!(
                    "{}.{name}: {other} is not a setting",
                    G::NAME
                )));
            }
        };
        base.set(name, value)
            .map_err(|e| CodecError::Settings(e.within(G::NAME).to_string()))?;
    }
    Ok(base)
}

impl StoredSettings {
    /// `config` as stored, with the shell's clock, spectator delay and the team's preset.
    pub fn of(
        config: &MatchConfig,
        clock: StoredClock,
        bots_joinable: bool,
        spectator_delay_ticks: u64,
        difficulty: Option<Difficulty>,
        rated: bool,
    ) -> StoredSettings {
        StoredSettings {
            v: SETTINGS_VERSION,
            robots: config.robots,
            opponents: config.opponents,
            opponent_control: StoredControl::of(config.opponent_control),
            opponent_bot: StoredBot::of(config.opponent_bot),
            planner: StoredPlanner::of(config.planner),
            policy: config.policy.clone(),
            outside_robots: config.outside_robots.clone(),
            pursuer_slots: config.pursuer_slots,
            seed: config.seed,
            time_limit_ticks: config.time_limit_ticks,
            placement: match &config.placement {
                Placement::Spawns => StoredPlacement::Spawns,
                Placement::Random => StoredPlacement::Random,
                Placement::Given { robots, opponents } => StoredPlacement::Given {
                    robots: robots.clone(),
                    opponents: opponents.clone(),
                },
            },
            localisation: config.localisation,
            tracker: group_out(&config.tracker),
            coordination: group_out(&config.coordination),
            radio: group_out(&config.radio),
            odometry: group_out(&config.physics.odometry),
            localiser: group_out(&config.localiser),
            clock,
            bots_joinable,
            spectator_delay_ticks,
            difficulty: difficulty.map(StoredDifficulty::of),
            rated,
        }
    }

    /// The robot team's preset the match was created with.
    pub fn difficulty(&self) -> Option<Difficulty> {
        self.difficulty.map(StoredDifficulty::kind)
    }

    /// The config the match ran with.
    pub fn config(&self) -> Result<MatchConfig, CodecError> {
        if self.v != SETTINGS_VERSION {
            return Err(CodecError::Settings(format!(
                "version {} (this server reads {SETTINGS_VERSION})",
                self.v
            )));
        }
        let base = MatchConfig::default();
        let physics = lasertag_core::sim::Physics {
            odometry: group_in(Odometry::default(), &self.odometry)?,
            ..self
                .difficulty()
                .map_or(base.physics.clone(), |d| d.physics(base.physics.clone()))
        };
        let localiser = group_in(localise::Settings::for_odometry(&physics), &self.localiser)?;
        Ok(MatchConfig {
            robots: self.robots,
            opponents: self.opponents,
            opponent_control: self.opponent_control.kind(),
            opponent_bot: self.opponent_bot.kind(),
            planner: self.planner.kind(),
            policy: self.policy.clone(),
            outside_robots: self.outside_robots.clone(),
            pursuer_slots: self.pursuer_slots,
            seed: self.seed,
            time_limit_ticks: self.time_limit_ticks,
            placement: match &self.placement {
                StoredPlacement::Spawns => Placement::Spawns,
                StoredPlacement::Random => Placement::Random,
                StoredPlacement::Given { robots, opponents } => Placement::Given {
                    robots: robots.clone(),
                    opponents: opponents.clone(),
                },
            },
            physics,
            tracker: group_in(tracker::Settings::default(), &self.tracker)?,
            coordination: group_in(
                planner::coordinated::Settings::default(),
                &self.coordination,
            )?,
            localisation: self.localisation,
            localiser,
            radio: group_in(radio::Settings::default(), &self.radio)?,
        })
    }
}

/// One input as a line of the store.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(tag = "k", rename_all = "lowercase")]
enum StoredInput {
    /// A person's keys: forward, turn, trigger, the tick their screen showed.
    Keys {
        t: u64,
        s: usize,
        f: f32,
        r: f32,
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        g: bool,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        v: Option<u64>,
    },
    Opponent {
        t: u64,
        s: usize,
        o: StoredOrder,
    },
    Robot {
        t: u64,
        r: usize,
        o: StoredOrder,
    },
    Seat {
        t: u64,
        s: usize,
        name: String,
    },
    Unseat {
        t: u64,
        s: usize,
        name: String,
    },
    SeatRobot {
        t: u64,
        r: usize,
        name: String,
    },
    /// A person's keys for robot `n` (a pursuer slot), as `Keys` are an opponent's.
    RobotKeys {
        t: u64,
        n: usize,
        f: f32,
        r: f32,
        g: bool,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        v: Option<u64>,
    },
    UnseatRobot {
        t: u64,
        r: usize,
        name: String,
    },
    /// A person's mark: the agent (`o0`, `r1`) and its name, the point, the kind's name.
    Mark {
        t: u64,
        a: String,
        name: String,
        x: f32,
        y: f32,
        m: String,
    },
    End {
        t: u64,
        reason: String,
    },
}

/// An opponent's or a robot's order.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
enum StoredOrder {
    Drive { f: f32, r: f32, g: bool },
    Waypoints(Vec<[f32; 2]>),
    Stop,
    Tag,
}

fn points(p: &[Point2<f32>]) -> Vec<[f32; 2]> {
    p.iter().map(|p| [p.x, p.y]).collect()
}

fn unpoints(p: &[[f32; 2]]) -> Vec<Point2<f32>> {
    p.iter().map(|p| Point2::new(p[0], p[1])).collect()
}

/// The agent a stored name (`o0`, `r1`) stands for.
fn agent_of(name: &str) -> Option<AgentId> {
    let (kind, n) = name.split_at_checked(1)?;
    let n = n.parse().ok()?;
    match kind {
        "o" => Some(AgentId::Opponent(n)),
        "r" => Some(AgentId::Robot(n)),
        _ => None,
    }
}

/// The reason a stored name stands for.
pub fn reason_of(name: &str) -> Option<FinishReason> {
    FinishReason::ALL.into_iter().find(|r| r.name() == name)
}

impl StoredInput {
    fn of(tick: u64, input: &WorldInput) -> StoredInput {
        let t = tick;
        match input {
            WorldInput::Keys { slot, input } => StoredInput::Keys {
                t,
                s: *slot,
                f: input.forward,
                r: input.turn,
                g: input.tag,
                v: input.seen_tick,
            },
            WorldInput::Opponent { slot, order } => StoredInput::Opponent {
                t,
                s: *slot,
                o: match order {
                    OpponentOrder::Waypoints(p) => StoredOrder::Waypoints(points(p)),
                    OpponentOrder::Stop => StoredOrder::Stop,
                    OpponentOrder::Tag => StoredOrder::Tag,
                },
            },
            WorldInput::Robot { robot, order } => StoredInput::Robot {
                t,
                r: *robot,
                o: match order {
                    RobotOrder::Drive { forward, turn, tag } => StoredOrder::Drive {
                        f: *forward,
                        r: *turn,
                        g: *tag,
                    },
                    RobotOrder::Waypoints(p) => StoredOrder::Waypoints(points(p)),
                    RobotOrder::Stop => StoredOrder::Stop,
                },
            },
            WorldInput::Seat { slot, name } => StoredInput::Seat {
                t,
                s: *slot,
                name: name.clone(),
            },
            WorldInput::Unseat { slot, name } => StoredInput::Unseat {
                t,
                s: *slot,
                name: name.clone(),
            },
            WorldInput::RobotKeys { robot, input } => StoredInput::RobotKeys {
                t,
                n: *robot,
                f: input.forward,
                r: input.turn,
                g: input.tag,
                v: input.seen_tick,
            },
            WorldInput::SeatRobot { robot, name } => StoredInput::SeatRobot {
                t,
                r: *robot,
                name: name.clone(),
            },
            WorldInput::UnseatRobot { robot, name } => StoredInput::UnseatRobot {
                t,
                r: *robot,
                name: name.clone(),
            },
            WorldInput::Mark { by, name, at, kind } => StoredInput::Mark {
                t,
                a: by.to_string(),
                name: name.clone(),
                x: at.x,
                y: at.y,
                m: kind.name().to_string(),
            },
            WorldInput::End(reason) => StoredInput::End {
                t,
                reason: reason.name().to_string(),
            },
        }
    }

    fn input(self) -> Result<(u64, WorldInput), String> {
        Ok(match self {
            StoredInput::Keys { t, s, f, r, g, v } => (
                t,
                WorldInput::Keys {
                    slot: s,
                    input: HumanInput {
                        forward: f,
                        turn: r,
                        tag: g,
                        seen_tick: v,
                    },
                },
            ),
            StoredInput::Opponent { t, s, o } => {
                let order = match o {
                    StoredOrder::Waypoints(p) => OpponentOrder::Waypoints(unpoints(&p)),
                    StoredOrder::Stop => OpponentOrder::Stop,
                    StoredOrder::Tag => OpponentOrder::Tag,
                    StoredOrder::Drive { .. } => return Err("an opponent cannot drive".into()),
                };
                (t, WorldInput::Opponent { slot: s, order })
            }
            StoredInput::Robot { t, r, o } => {
                let order = match o {
                    StoredOrder::Drive { f, r, g } => RobotOrder::Drive {
                        forward: f,
                        turn: r,
                        tag: g,
                    },
                    StoredOrder::Waypoints(p) => RobotOrder::Waypoints(unpoints(&p)),
                    StoredOrder::Stop => RobotOrder::Stop,
                    StoredOrder::Tag => return Err("a robot's tag is a drive order".into()),
                };
                (t, WorldInput::Robot { robot: r, order })
            }
            StoredInput::Seat { t, s, name } => (t, WorldInput::Seat { slot: s, name }),
            StoredInput::Unseat { t, s, name } => (t, WorldInput::Unseat { slot: s, name }),
            StoredInput::SeatRobot { t, r, name } => (t, WorldInput::SeatRobot { robot: r, name }),
            StoredInput::RobotKeys { t, n, f, r, g, v } => (
                t,
                WorldInput::RobotKeys {
                    robot: n,
                    input: HumanInput {
                        forward: f,
                        turn: r,
                        tag: g,
                        seen_tick: v,
                    },
                },
            ),
            StoredInput::UnseatRobot { t, r, name } => {
                (t, WorldInput::UnseatRobot { robot: r, name })
            }
            StoredInput::Mark {
                t,
                a,
                name,
                x,
                y,
                m,
            } => (
                t,
                WorldInput::Mark {
                    by: agent_of(&a).ok_or_else(|| format!("no agent {a:?}"))?,
                    name,
                    at: Point2::new(x, y),
                    kind: MarkKind::parse(&m).ok_or_else(|| format!("no mark kind {m:?}"))?,
                },
            ),
            StoredInput::End { t, reason } => (
                t,
                WorldInput::End(
                    reason_of(&reason).ok_or_else(|| format!("no finish reason {reason:?}"))?,
                ),
            ),
        })
    }
}

/// `inputs` as a deflated chunk of JSON lines.
pub fn encode_inputs(inputs: &[(u64, WorldInput)]) -> Vec<u8> {
    // The lines are written out first and deflated in one call: the encoder's every `write`
    // zeroes its 32 KB output buffer, which cost more than the compression itself when each
    // line was written on its own (a chunk of a stepped match holds thousands).
    let mut text = Vec::with_capacity(64 * inputs.len());
    for (tick, input) in inputs {
        // Writing to memory and serialising plain data cannot fail.
        let _ = serde_json::to_writer(&mut text, &StoredInput::of(*tick, input));
        text.push(b'\n');
    }
    let mut out = DeflateEncoder::new(Vec::with_capacity(text.len() / 4), Compression::fast());
    let _ = out.write_all(&text);
    out.finish().unwrap_or_default()
}

/// `world`'s checkpoint, deflated: `None` past `max_bytes`.
pub fn encode_checkpoint(world: &World, max_bytes: u64) -> Option<Vec<u8>> {
    let state = world.checkpoint();
    let mut out = DeflateEncoder::new(Vec::with_capacity(state.len() / 2), Compression::fast());
    let _ = out.write_all(&state);
    let bytes = out.finish().unwrap_or_default();
    (bytes.len() as u64 <= max_bytes).then_some(bytes)
}

/// The match a checkpoint written by [`encode_checkpoint`] was taken of, from `fresh` (a
/// new world on that match's map and settings).
pub fn decode_checkpoint(fresh: World, bytes: &[u8]) -> Result<World, CodecError> {
    // A damaged store cannot make the reader inflate without end: no match's state comes
    // near this.
    const MOST_STATE_BYTES: u64 = 1 << 28;
    let mut state = Vec::new();
    DeflateDecoder::new(bytes)
        .take(MOST_STATE_BYTES)
        .read_to_end(&mut state)
        .map_err(|e| CodecError::Checkpoint(format!("not deflated: {e}")))?;
    fresh
        .restored(&state)
        .map_err(|e| CodecError::Checkpoint(e.to_string()))
}

/// The inputs of one chunk written by [`encode_inputs`].
pub fn decode_inputs(chunk: &[u8]) -> Result<Vec<(u64, WorldInput)>, CodecError> {
    let mut text = String::new();
    DeflateDecoder::new(chunk)
        .read_to_string(&mut text)
        .map_err(|e| CodecError::Inputs(format!("not a deflated chunk: {e}")))?;
    text.lines()
        .enumerate()
        .map(|(i, line)| {
            serde_json::from_str::<StoredInput>(line)
                .map_err(|e| e.to_string())
                .and_then(StoredInput::input)
                .map_err(|e| CodecError::Inputs(format!("line {}: {e}", i + 1)))
        })
        .collect()
}

#[cfg(test)]
mod tests;
