//! Every JSON shape of the HTTP and WebSocket interface (`docs/api.md`), and the
//! conversions between them and the core's and the game's plain types: the game decides, this
//! floor above it only speaks. Nothing else in the crate derives serde (map files aside, in
//! `maps/`, and the history's stored form, in `store/codec.rs`), so the wire format is
//! decided here and only here.
//!
//! Requests are parsed strictly: unknown fields are errors, and every error names the field
//! ([`parse`] wraps serde with the JSON path of the failure).
//!
//! What a match shows of itself (its summary, ground truth, the team's belief, the event
//! log) is in [`state`]; requests and the small shapes are here.

pub mod bounds;
pub mod compact;
pub mod difficulties;
mod difficulty_name;
pub mod fleet;
mod join;
pub mod parties;
mod planners;
mod policies;
mod refusal;
pub mod replay_ws;
pub mod replays;
pub mod robots;
pub mod rules;
pub mod settings;
pub mod socket;
mod starts;
pub mod state;
pub mod ws;

pub use state::{
    Belief, ConfidenceState, DetectionDto, EventDto, Events, MatchState, MatchStats, MatchSummary,
    OpponentState, PoseDto, RobotState, Role, belief, belief_of, event, finish_reason, notes,
    owners_summary, read_belief, read_events, read_state, read_stats, read_summary, state, stats,
    summary,
};

use serde::de::DeserializeOwned;

use crate::schema;
use lasertag_core::difficulty::Difficulty;
use lasertag_core::planner::coordinated;
use lasertag_core::settings::FieldError;
use lasertag_core::sim::Odometry;
use lasertag_core::{localise, radio, tracker};
use serde::{Deserialize, Serialize};
use settings::{Echo, Overrides};
use utoipa::ToSchema;

use lasertag_core::bots::BotKind;
use lasertag_core::planner::PlannerKind;
use lasertag_core::sim::{AgentId, TICK_HZ};
use lasertag_core::world::{ControlKind, FinishReason, MatchConfig};
use lasertag_core::world::{EventKind, MatchStatus, Side, World};

pub use difficulty_name::DifficultyName;
pub use join::{
    ClaimRequest, JoinRequest, JoinTeam, Joined, NameKept, ShowcaseJoinRequest, ShowcaseSeat,
};
pub(crate) use planners::planner_dto;
pub use planners::{Controller, Planner, PlannerChoice, planner_name};
pub use policies::{PolicyCreated, PolicyInfo};
pub use refusal::{Invalid, invalid};

/// Deserialises with serde, naming the JSON path of whatever is wrong (`root` when it is
/// the whole document).
pub fn deserialize_at<'de, T, D>(de: D, root: &str) -> Result<T, Invalid>
where
    T: Deserialize<'de>,
    D: serde::Deserializer<'de>,
{
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let message = e.into_inner().to_string();
        invalid(if path == "." { root.to_owned() } else { path }, message)
    })
}

/// Parses a request body, naming the JSON path of whatever is wrong.
pub fn parse<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, Invalid> {
    deserialize_at(&mut serde_json::Deserializer::from_slice(bytes), "body")
}

// Metres to a millimetre and radians to a ten-thousandth: f32 noise digits help nobody and
// bloat the JSON. The core's research engine rounds with the same functions, so that its
// observations are the API's bit for bit.
use lasertag_core::env::{mm, rad};

#[derive(Debug, Serialize, ToSchema)]
pub struct ErrorBody {
    /// What is wrong, naming the field.
    pub error: String,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct Health {
    pub status: &'static str,
    pub version: &'static str,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct MapInfo {
    pub name: String,
    pub width: f64,
    pub height: f64,
}

/// The reply to `POST /api/maps`: the map and the secret that deletes it (shown only here).
#[derive(Debug, Serialize, ToSchema)]
pub struct MapCreated {
    #[serde(flatten)]
    pub map: MapInfo,
    /// `Authorization: Bearer <owner_token>` deletes the map.
    pub owner_token: String,
}

/// The reply to `POST /api/matches`: the summary and the secret that changes the match
/// (shown only here).
#[derive(Debug, Serialize, ToSchema)]
pub struct MatchCreated {
    #[serde(flatten)]
    pub summary: MatchSummary,
    /// `Authorization: Bearer <owner_token>` steps, commands and deletes the match.
    pub owner_token: String,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum OpponentControl {
    Bot,
    Api,
    Human,
}

/// The wire names of the core's controller kinds (the core stays free of serde).
impl From<ControlKind> for OpponentControl {
    fn from(kind: ControlKind) -> Self {
        match kind {
            ControlKind::Bot => OpponentControl::Bot,
            ControlKind::Api => OpponentControl::Api,
            ControlKind::Human => OpponentControl::Human,
        }
    }
}

impl From<OpponentControl> for ControlKind {
    fn from(control: OpponentControl) -> Self {
        match control {
            OpponentControl::Bot => ControlKind::Bot,
            OpponentControl::Api => ControlKind::Api,
            OpponentControl::Human => ControlKind::Human,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum OpponentBot {
    Wander,
    Evade,
    Idle,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Clock {
    Realtime,
    Manual,
}

impl From<crate::game::view::Clock> for Clock {
    fn from(c: crate::game::view::Clock) -> Self {
        match c {
            crate::game::view::Clock::Realtime => Clock::Realtime,
            crate::game::view::Clock::Manual => Clock::Manual,
        }
    }
}

impl From<Clock> for crate::game::view::Clock {
    fn from(c: Clock) -> Self {
        match c {
            Clock::Realtime => crate::game::view::Clock::Realtime,
            Clock::Manual => crate::game::view::Clock::Manual,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum StartPlacement {
    /// The map's spawns, in order, wrapping.
    Spawns,
    /// Random free, mutually reachable points (seeded).
    Random,
}

/// Body of `POST /api/matches`. Every field but `map` is optional.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateMatch {
    /// A map name, or an inline map object.
    #[schema(schema_with = schema::map_or_name)]
    pub map: serde_json::Value,
    /// [`bounds::ROBOTS`].
    #[serde(default, deserialize_with = "schema::opt_int")]
    #[schema(schema_with = bounds::robots_schema)]
    pub robots: Option<i64>,
    /// [`bounds::OPPONENTS`].
    #[serde(default, deserialize_with = "schema::opt_int")]
    #[schema(schema_with = bounds::opponents_schema)]
    pub opponents: Option<i64>,
    pub opponent_control: Option<OpponentControl>,
    pub opponent_bot: Option<OpponentBot>,
    /// [`bounds::PURSUER_SLOTS`]: people on the robot team.
    #[serde(default, deserialize_with = "schema::opt_int")]
    #[schema(schema_with = bounds::pursuer_slots_schema)]
    pub pursuer_slots: Option<i64>,
    /// One planner for the whole team, or one per robot (`["coordinated", "api"]`: robot r1
    /// driven from outside beside a planned r0; the built-in ones must agree).
    #[schema(schema_with = planners::choice_schema)]
    pub planner: Option<PlannerChoice>,
    /// A robot-team preset: sets `robots`, `planner`, `time_limit_s` (each unless given
    /// here too) and the robots' speed and tag cool-down (docs/difficulty.md).
    pub difficulty: Option<DifficultyName>,
    /// The team's opponent tracker (docs/settings.md).
    #[schema(schema_with = settings::tracker_request)]
    pub tracker: Option<Overrides<tracker::Settings>>,
    /// Weights of the `coordinated` planner (ignored by the others).
    #[schema(schema_with = settings::coordination_request)]
    pub coordination: Option<Overrides<coordinated::Settings>>,
    pub clock: Option<Clock>,
    /// 0..=18446744073709551615 (default 0). Only for a match people may not join: one
    /// they may join gets a secret seed the server chooses (400 when one is given).
    #[serde(default, deserialize_with = "schema::opt_seed")]
    #[schema(schema_with = schema::seed)]
    pub seed: Option<u64>,
    /// [`bounds::TIME_LIMIT_S`].
    #[schema(schema_with = bounds::time_limit_s_schema)]
    pub time_limit_s: Option<f64>,
    /// Where agents start when no explicit starts are given (default `spawns`).
    pub placement: Option<StartPlacement>,
    /// Explicit robot starts `[x, y, heading]`, one per robot.
    #[schema(schema_with = bounds::robot_starts_schema)]
    pub robot_starts: Option<Vec<[f64; 3]>>,
    /// Explicit opponent starts `[x, y]`, one per opponent.
    #[schema(schema_with = bounds::opponent_starts_schema)]
    pub opponent_starts: Option<Vec<[f64; 2]>>,
    /// Whether people may take over bot opponents (default false; the showcase allows it).
    pub bots_joinable: Option<bool>,
    /// [`bounds::SPECTATOR_DELAY_S`].
    #[schema(schema_with = bounds::spectator_delay_s_schema)]
    pub spectator_delay_s: Option<f64>,
    /// Whether robots localise themselves from odometry, laser and landmarks (default true;
    /// false leaves each robot its odometry alone, which drifts).
    pub localisation: Option<bool>,
    /// The team radio (default perfect: `{"latency_ticks": 0, "loss": 0.0}`).
    #[schema(schema_with = settings::radio_request)]
    pub radio: Option<Overrides<radio::Settings>>,
    /// The robots' wheel odometry noise (default
    /// `{"distance": 0.05, "heading_deg_per_m": 2, "turn": 0.02}`).
    #[schema(schema_with = settings::odometry_request)]
    pub odometry: Option<Overrides<Odometry>>,
    /// The robots' localisers (default `{"beams": 30}`).
    #[schema(schema_with = settings::localiser_request)]
    pub localiser: Option<Overrides<localise::Settings>>,
}

/// A validated `CreateMatch`: the core's config plus what only the shell cares about.
#[derive(Debug, Clone)]
pub struct MatchRequest {
    pub map: serde_json::Value,
    pub config: MatchConfig,
    pub clock: Clock,
    pub bots_joinable: bool,
    /// Whether people may play it (`view::people_may_play`): its seed is the server's to
    /// choose, and secret.
    pub people: bool,
    /// Ticks the truth is held back (0 when no person may play).
    pub spectator_delay_ticks: u64,
    /// The robot team's preset, if one was asked for.
    pub difficulty: Option<Difficulty>,
    /// Whether the match counts for ratings ([`CreateMatch::rated`]).
    pub rated: bool,
}

/// Default of `spectator_delay_s` ([`bounds::SPECTATOR_DELAY_S`]).
pub const SPECTATOR_DELAY_S: f64 = bounds::SPECTATOR_DELAY_S.default_value();

fn refused(field: &str, message: String) -> FieldError {
    FieldError {
        field: field.to_string(),
        message,
    }
}

impl CreateMatch {
    /// Checks ranges and fills in defaults; an error names the field.
    pub fn validate(self) -> Result<MatchRequest, FieldError> {
        let rated = self.rated();
        let difficulty = self.difficulty.map(DifficultyName::kind);
        let preset = difficulty.map(Difficulty::preset);
        let given_robots = match self.robots {
            Some(_) => Some(bounds::ROBOTS.integer(self.robots)? as usize),
            None => None,
        };
        let planners::Resolved {
            planner,
            robots: listed_robots,
            outside: outside_robots,
            policy,
        } = planners::resolve(self.planner.as_ref(), given_robots)?;
        // A preset fills in what the request leaves out; what it gives wins (a planner per
        // robot gives the robots too).
        let robots = match (listed_robots, preset) {
            (Some(n), _) => bounds::ROBOTS.integer(Some(n as i64))? as usize,
            (None, Some(p)) => p.robots,
            (None, None) => bounds::ROBOTS.integer(None)? as usize,
        };
        let opponents = bounds::OPPONENTS.integer(self.opponents)? as usize;
        let pursuer_slots = bounds::PURSUER_SLOTS.integer(self.pursuer_slots)? as usize;
        if pursuer_slots > robots {
            return Err(refused(
                "pursuer_slots",
                format!(
                    "{pursuer_slots} seats on a team of {robots} robots: at most one per robot"
                ),
            ));
        }
        if let Some(PlannerChoice::PerRobot(list)) = &self.planner
            && let Some(i) = (robots - pursuer_slots..robots).find(|&i| list[i] != Planner::Api)
        {
            return Err(refused(
                "planner",
                format!(
                    "r{i} is a pursuer slot (the last {pursuer_slots} robots are): a person drives it, so list it as \"api\""
                ),
            ));
        }
        let time_limit_s = match (self.time_limit_s, preset) {
            (None, Some(p)) => p.time_limit_s as f64,
            _ => bounds::TIME_LIMIT_S.number(self.time_limit_s)?,
        };
        let placement = starts::placement(
            &self.robot_starts.unwrap_or_default(),
            &self.opponent_starts.unwrap_or_default(),
            (robots, opponents),
            self.placement == Some(StartPlacement::Random),
        )?;
        let config = MatchConfig {
            robots,
            opponents,
            opponent_control: self.opponent_control.unwrap_or(OpponentControl::Bot).into(),
            opponent_bot: match self.opponent_bot.unwrap_or(OpponentBot::Wander) {
                OpponentBot::Wander => BotKind::Wander,
                OpponentBot::Evade => BotKind::Evade,
                OpponentBot::Idle => BotKind::Idle,
            },
            planner: match (planner, preset) {
                (Some(kind), _) => kind,
                (None, Some(p)) => p.planner,
                (None, None) => PlannerKind::Coordinated,
            },
            policy: match (planner, preset) {
                (Some(_), _) => policy,
                (None, Some(p)) => p.policy.map(str::to_string),
                (None, None) => None,
            },
            outside_robots,
            pursuer_slots,
            seed: self.seed.unwrap_or(0),
            time_limit_ticks: (time_limit_s * TICK_HZ as f64).round().max(1.0) as u64,
            placement,
            ..MatchConfig::default()
        };
        let physics = lasertag_core::sim::Physics {
            odometry: self
                .odometry
                .unwrap_or_default()
                .apply(Odometry::default())?,
            ..difficulty.map_or(config.physics.clone(), |d| {
                d.physics(config.physics.clone())
            })
        };
        let localiser = self
            .localiser
            .unwrap_or_default()
            .apply(localise::Settings::for_odometry(&physics))?;
        let config = MatchConfig {
            tracker: self.tracker.unwrap_or_default().apply(config.tracker)?,
            coordination: self
                .coordination
                .unwrap_or_default()
                .apply(config.coordination)?,
            localisation: self.localisation.unwrap_or(true),
            radio: self.radio.unwrap_or_default().apply(config.radio)?,
            localiser,
            physics,
            ..config
        };
        let bots_joinable = self.bots_joinable.unwrap_or(false);
        let delay_s = bounds::SPECTATOR_DELAY_S.number(self.spectator_delay_s)?;
        let people = crate::game::view::people_may_play(&config, bots_joinable);
        if people && self.seed.is_some() {
            return Err(refused(
                "seed",
                "a match people may join (opponent_control human, bots_joinable, or pursuer_slots) gets a \
                 secret seed that the server chooses, so that nobody can rebuild it while it \
                 runs; leave seed out (it is shown with the replay once the match has ended)"
                    .to_string(),
            ));
        }
        Ok(MatchRequest {
            map: self.map,
            config,
            clock: self.clock.unwrap_or(Clock::Realtime),
            bots_joinable,
            people,
            spectator_delay_ticks: if people {
                (delay_s * TICK_HZ as f64).round() as u64
            } else {
                0
            },
            difficulty,
            rated,
        })
    }

    /// Whether a match made from this request counts for ratings (docs/ratings.md): one
    /// person against a preset exactly as it was measured — a `difficulty` and nothing that
    /// changes the robot team, its clock or where anyone starts (`placement` too); one
    /// opponent, a person's seat; a real-time clock (nobody steps it); strangers held back by
    /// at least the default delay; and (checked where the maps are) a map the presets were
    /// measured on, shipped by the server. Its owner token then reads it as late as
    /// everyone else, and its seed stays secret from the owner too: nobody in it can see its
    /// truth live.
    fn rated(&self) -> bool {
        let team_as_measured = self.robots.is_none()
            && self.planner.is_none()
            && self.time_limit_s.is_none()
            && self.tracker.is_none()
            && self.coordination.is_none()
            && self.localisation.is_none()
            && self.radio.is_none()
            && self.odometry.is_none()
            && self.localiser.is_none()
            && self.robot_starts.is_none()
            && self.opponent_starts.is_none()
            && self.placement.is_none()
            && self.pursuer_slots.unwrap_or(0) == 0;
        // Strangers read a match as late as its delay: a shorter one than the default would
        // let a second program show the player where the robots are.
        let held_back = self
            .spectator_delay_s
            .is_none_or(|d| d >= bounds::SPECTATOR_DELAY_S.default.unwrap_or(0.0));
        self.difficulty.is_some()
            && team_as_measured
            && held_back
            && self.opponents.unwrap_or(1) == 1
            && self.opponent_control == Some(OpponentControl::Human)
            && self.clock.unwrap_or(Clock::Realtime) == Clock::Realtime
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    Running,
    Finished,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Winner {
    Robots,
    Opponents,
}

pub(crate) fn status(s: MatchStatus) -> Status {
    match s {
        MatchStatus::Running => Status::Running,
        MatchStatus::Finished => Status::Finished,
    }
}

pub(crate) fn winner(w: Option<Side>) -> Option<Winner> {
    w.map(|w| match w {
        Side::Robots => Winner::Robots,
        Side::Opponents => Winner::Opponents,
    })
}

/// Body of `POST /api/matches/{id}/step`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct StepRequest {
    /// [`bounds::STEP_TICKS`].
    #[serde(deserialize_with = "schema::int")]
    #[schema(schema_with = bounds::step_ticks_schema)]
    pub ticks: i64,
}

impl StepRequest {
    /// The ticks to advance, checked ([`bounds::STEP_TICKS`]).
    pub fn ticks(&self) -> Result<u64, Invalid> {
        Ok(bounds::STEP_TICKS.integer(Some(self.ticks))? as u64)
    }
}

/// Body of `POST /api/matches/{id}/opponents/{oid}/command`: exactly one field.
#[derive(Debug, Clone, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct OpponentCommand {
    /// Replaces the route: straight legs at top speed, stopping at the last point.
    #[schema(schema_with = schema::waypoints)]
    pub waypoints: Option<Vec<[f64; 2]>>,
    /// `true` halts the opponent.
    pub stop: Option<bool>,
    /// `true` fires its tag device once.
    pub tag: Option<bool>,
}

impl OpponentCommand {
    pub fn order(self) -> Result<lasertag_core::world::OpponentOrder, Invalid> {
        use lasertag_core::world::OpponentOrder;
        match (self.waypoints, self.stop, self.tag) {
            (Some(w), None, None) => {
                if w.len() > 1_000 {
                    return Err(invalid(
                        "waypoints",
                        format!("{} points, the limit is 1000", w.len()),
                    ));
                }
                for (i, p) in w.iter().enumerate() {
                    if !(p[0].is_finite() && p[1].is_finite())
                        || p[0].abs() > schema::MAX_COORDINATE
                        || p[1].abs() > schema::MAX_COORDINATE
                    {
                        return Err(invalid(
                            format!("waypoints[{i}]"),
                            format!("[{}, {}] is not a finite point", p[0], p[1]),
                        ));
                    }
                }
                Ok(OpponentOrder::Waypoints(
                    w.iter()
                        .map(|p| nalgebra::Point2::new(p[0] as f32, p[1] as f32))
                        .collect(),
                ))
            }
            (None, Some(true), None) => Ok(OpponentOrder::Stop),
            (None, None, Some(true)) => Ok(OpponentOrder::Tag),
            (None, Some(false), None) => Err(invalid("stop", "must be true")),
            (None, None, Some(false)) => Err(invalid("tag", "must be true")),
            _ => Err(invalid("body", "give exactly one of waypoints, stop, tag")),
        }
    }
}

#[cfg(test)]
mod tests;
