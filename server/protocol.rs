//! Every JSON shape of the HTTP and WebSocket interface (`../shared/spec/http-api.md`), and the
//! conversions between them and the core's plain types. Nothing else in the crate derives serde
//! (map files aside, in `maps.rs`), so the wire format is decided here and only here.
//!
//! Requests are parsed strictly: unknown fields are errors, and every error names the field
//! ([`parse`] wraps serde with the JSON path of the failure).
//!
//! Long file: the match API's JSON shapes in one place, to read the wire format in one
//! file; the state, belief and event shapes are the next seam to split out.

pub mod frame;
pub mod settings;
pub mod ws;

use serde::de::DeserializeOwned;

use crate::schema;
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
use lasertag_core::world::{ControlKind, FinishReason, MatchConfig, Placement};
use lasertag_core::world::{EventKind, MatchStatus, Side, World};

/// A request part that was refused: the JSON path of what is wrong, and why.
pub use lasertag_core::settings::FieldError as Invalid;

/// `Invalid` at `field`.
pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Invalid {
    Invalid {
        field: field.into(),
        message: message.into(),
    }
}

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

/// Rounds metres to a millimetre: f32 noise digits help nobody and bloat the JSON.
fn mm(v: f32) -> f64 {
    ((v as f64) * 1000.0).round() / 1000.0
}

fn rad(v: f32) -> f64 {
    ((v as f64) * 10_000.0).round() / 10_000.0
}

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
pub enum Planner {
    Coordinated,
    Baseline,
    Idle,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Clock {
    Realtime,
    Manual,
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
    /// 1..=8 robots (default 2).
    #[serde(default, deserialize_with = "schema::opt_int")]
    #[schema(minimum = 1, maximum = 8)]
    pub robots: Option<i64>,
    /// 1..=32 opponents (default 1).
    #[serde(default, deserialize_with = "schema::opt_int")]
    #[schema(minimum = 1, maximum = 32)]
    pub opponents: Option<i64>,
    pub opponent_control: Option<OpponentControl>,
    pub opponent_bot: Option<OpponentBot>,
    pub planner: Option<Planner>,
    /// The team's opponent tracker (docs/settings.md).
    #[schema(schema_with = settings::tracker_request)]
    pub tracker: Option<Overrides<tracker::Settings>>,
    /// Weights of the `coordinated` planner (ignored by the others).
    #[schema(schema_with = settings::coordination_request)]
    pub coordination: Option<Overrides<coordinated::Settings>>,
    pub clock: Option<Clock>,
    /// 0..=18446744073709551615 (default 0).
    #[serde(default, deserialize_with = "schema::opt_seed")]
    #[schema(schema_with = schema::seed)]
    pub seed: Option<u64>,
    /// Seconds, in (0, 86400] (default 300).
    #[schema(exclusive_minimum = 0.0, maximum = 86_400.0)]
    pub time_limit_s: Option<f64>,
    /// Where agents start when no explicit starts are given (default `spawns`).
    pub placement: Option<StartPlacement>,
    /// Explicit robot starts `[x, y, heading]`, one per robot.
    #[schema(schema_with = schema::robot_starts)]
    pub robot_starts: Option<Vec<[f64; 3]>>,
    /// Explicit opponent starts `[x, y]`, one per opponent.
    #[schema(schema_with = schema::opponent_starts)]
    pub opponent_starts: Option<Vec<[f64; 2]>>,
    /// Whether people may take over bot opponents (default false; the showcase allows it).
    pub bots_joinable: Option<bool>,
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
}

fn refused(field: &str, message: String) -> FieldError {
    FieldError {
        field: field.to_string(),
        message,
    }
}

fn in_range(field: &str, v: i64, lo: i64, hi: i64) -> Result<i64, FieldError> {
    if (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(refused(field, format!("{v} must be in {lo}..={hi}")))
    }
}

fn finite_in(field: &str, v: f64, lo: f64, hi: f64, lo_open: bool) -> Result<f64, FieldError> {
    let ok = v.is_finite() && (if lo_open { v > lo } else { v >= lo }) && v <= hi;
    if ok {
        Ok(v)
    } else {
        let open = if lo_open { "(" } else { "[" };
        Err(refused(
            field,
            format!("{v} must be finite and in {open}{lo}, {hi}]"),
        ))
    }
}

impl CreateMatch {
    /// Checks ranges and fills in defaults; an error names the field.
    pub fn validate(self) -> Result<MatchRequest, FieldError> {
        let robots = in_range("robots", self.robots.unwrap_or(2), 1, 8)? as usize;
        let opponents = in_range("opponents", self.opponents.unwrap_or(1), 1, 32)? as usize;
        let time_limit_s = finite_in(
            "time_limit_s",
            self.time_limit_s.unwrap_or(300.0),
            0.0,
            86_400.0,
            true,
        )?;
        let check_points = |field: &str, pts: &[&[f64]]| -> Result<(), FieldError> {
            for (i, p) in pts.iter().enumerate() {
                if let Some(v) = p
                    .iter()
                    .find(|v| !v.is_finite() || v.abs() > schema::MAX_COORDINATE)
                {
                    return Err(refused(
                        &format!("{field}[{i}]"),
                        format!("{v} is not a finite coordinate"),
                    ));
                }
            }
            Ok(())
        };
        let robot_starts = self.robot_starts.unwrap_or_default();
        let opponent_starts = self.opponent_starts.unwrap_or_default();
        check_points(
            "robot_starts",
            &robot_starts.iter().map(|p| &p[..]).collect::<Vec<_>>(),
        )?;
        check_points(
            "opponent_starts",
            &opponent_starts.iter().map(|p| &p[..]).collect::<Vec<_>>(),
        )?;
        let placement = if !robot_starts.is_empty() || !opponent_starts.is_empty() {
            Placement::Given {
                robots: robot_starts
                    .iter()
                    .map(|p| [p[0] as f32, p[1] as f32, p[2] as f32])
                    .collect(),
                opponents: opponent_starts
                    .iter()
                    .map(|p| [p[0] as f32, p[1] as f32])
                    .collect(),
            }
        } else if self.placement == Some(StartPlacement::Random) {
            Placement::Random
        } else {
            Placement::Spawns
        };
        let config = MatchConfig {
            robots,
            opponents,
            opponent_control: self.opponent_control.unwrap_or(OpponentControl::Bot).into(),
            opponent_bot: match self.opponent_bot.unwrap_or(OpponentBot::Wander) {
                OpponentBot::Wander => BotKind::Wander,
                OpponentBot::Evade => BotKind::Evade,
                OpponentBot::Idle => BotKind::Idle,
            },
            planner: planner_kind(self.planner.unwrap_or(Planner::Coordinated)),
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
            ..config.physics
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
        Ok(MatchRequest {
            map: self.map,
            config,
            clock: self.clock.unwrap_or(Clock::Realtime),
            bots_joinable: self.bots_joinable.unwrap_or(false),
        })
    }
}

fn planner_kind(p: Planner) -> PlannerKind {
    match p {
        Planner::Coordinated => PlannerKind::Coordinated,
        Planner::Baseline => PlannerKind::Baseline,
        Planner::Idle => PlannerKind::Idle,
    }
}

/// The planner's name as the API spells it (also the `kind` label of the tick metrics).
pub fn planner_name(p: PlannerKind) -> &'static str {
    match p {
        PlannerKind::Coordinated => "coordinated",
        PlannerKind::Baseline => "baseline",
        PlannerKind::Idle => "idle",
    }
}

fn planner_dto(p: PlannerKind) -> Planner {
    match p {
        PlannerKind::Coordinated => Planner::Coordinated,
        PlannerKind::Baseline => Planner::Baseline,
        PlannerKind::Idle => Planner::Idle,
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

/// What the shell knows about a match besides its world.
#[derive(Debug, Clone)]
pub struct MatchMeta {
    pub id: String,
    pub map: String,
    pub clock: Clock,
    pub players: usize,
    /// WebSocket spectators connected now.
    pub spectators: usize,
    /// Opponent slots a person can take now.
    pub free_slots: usize,
    /// Whether people may take over bot opponents (the showcase).
    pub bots_joinable: bool,
}

/// A match in listings and the reply to `POST /api/matches`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct MatchSummary {
    pub id: String,
    pub map: String,
    pub clock: Clock,
    pub tick: u64,
    pub tick_hz: u32,
    pub time_s: f64,
    pub time_limit_s: f64,
    pub status: Status,
    pub winner: Option<Winner>,
    pub robots: usize,
    pub opponents: usize,
    pub opponents_left: usize,
    pub opponent_control: OpponentControl,
    pub opponent_bot: OpponentBot,
    /// The planner asked for.
    pub planner: Planner,
    /// Deprecated: always equal to `planner` (no planner falls back to another); kept so
    /// that clients reading it do not break.
    #[schema(deprecated)]
    pub planner_active: Planner,
    #[schema(schema_with = settings::tracker_echo)]
    pub tracker: Echo<tracker::Settings>,
    #[schema(schema_with = settings::coordination_echo)]
    pub coordination: Echo<coordinated::Settings>,
    /// Whether robots localise themselves (else their estimate is their odometry alone).
    pub localisation: bool,
    /// The team radio; with a latency or loss each robot keeps its own belief.
    #[schema(schema_with = settings::radio_echo)]
    pub radio: Echo<radio::Settings>,
    /// The robots' wheel odometry noise.
    #[schema(schema_with = settings::odometry_echo)]
    pub odometry: Echo<Odometry>,
    /// The robots' localisers (what they weigh when `localisation` is on).
    #[schema(schema_with = settings::localiser_echo)]
    pub localiser: Echo<localise::Settings>,
    pub seed: u64,
    pub players: usize,
    /// WebSocket spectators connected now.
    pub spectators: usize,
    /// Opponent slots a person can take now (`POST /api/matches/{id}/players`).
    pub free_slots: usize,
    pub bots_joinable: bool,
    /// Caveats a user should know, e.g. a fallback in effect.
    pub notes: Vec<String>,
}

/// Caveats about a match: settings that were accepted but do nothing as asked.
pub fn notes(world: &World) -> Vec<String> {
    let c = &world.config;
    let mut notes = Vec::new();
    if !c.localisation
        && c.planner == PlannerKind::Coordinated
        && c.coordination.landmark_weight > 0.0
    {
        notes.push(
            "coordination.landmark_weight has no effect without localisation: a landmark in \
             view corrects nothing when robots dead-reckon"
                .to_string(),
        );
    }
    notes
}

pub fn summary(world: &World, meta: &MatchMeta) -> MatchSummary {
    let c = &world.config;
    MatchSummary {
        id: meta.id.clone(),
        map: meta.map.clone(),
        clock: meta.clock,
        tick: world.tick,
        tick_hz: TICK_HZ,
        time_s: world.time_s(),
        time_limit_s: c.time_limit_ticks as f64 / TICK_HZ as f64,
        status: status(world.status),
        winner: winner(world.winner),
        robots: world.robots.len(),
        opponents: world.opponents.len(),
        opponents_left: world.opponents.iter().filter(|o| !o.tagged).count(),
        opponent_control: c.opponent_control.into(),
        opponent_bot: match c.opponent_bot {
            BotKind::Wander => OpponentBot::Wander,
            BotKind::Evade => OpponentBot::Evade,
            BotKind::Idle => OpponentBot::Idle,
        },
        planner: planner_dto(world.team.kind()),
        planner_active: planner_dto(world.team.kind()),
        tracker: Echo(c.tracker.clone()),
        coordination: Echo(c.coordination.clone()),
        localisation: c.localisation,
        radio: Echo(c.radio.clone()),
        odometry: Echo(c.physics.odometry),
        localiser: Echo(c.localiser.clone()),
        seed: c.seed,
        players: meta.players,
        spectators: meta.spectators,
        free_slots: meta.free_slots,
        bots_joinable: meta.bots_joinable,
        notes: notes(world),
    }
}

/// `GET /api/matches/{id}/stats`: how the match's task keeps up (wall-clock measurements of
/// the shell, not part of the deterministic match).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct MatchStats {
    pub id: String,
    pub tick: u64,
    /// Ticks in the window the percentiles cover (the most recent ones, up to 4096).
    pub ticks_measured: usize,
    /// Compute time of one tick (the step plus building the published frame), microseconds.
    pub tick_us_p50: f64,
    pub tick_us_p99: f64,
    pub tick_us_max: f64,
    pub tick_us_mean: f64,
    /// Real-time ticks that were late by more than a whole tick period (skipped, not burst).
    pub late_ticks: u64,
    /// Frames published to viewers so far.
    pub frames_published: u64,
    pub spectators: usize,
    pub players_connected: usize,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct PoseDto {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

fn pose(p: lasertag_core::sim::Pose) -> PoseDto {
    PoseDto {
        x: mm(p.pos.x),
        y: mm(p.pos.y),
        theta: rad(p.theta),
    }
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct DetectionDto {
    pub range: f64,
    pub bearing: f64,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct RobotState {
    pub id: String,
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    /// The robot's own belief of its pose (its localiser's point estimate; the true pose
    /// when the match runs without localisation).
    pub estimate: PoseDto,
    /// Standard deviation of the localiser's position belief, metres (0 without localisation).
    pub spread: f64,
    pub frozen: bool,
    /// Where its planner sends it, or null.
    pub goal: Option<PoseDto>,
    /// This tick's ranges, beam i at bearing (i - 90)°; empty while frozen.
    pub scan: Vec<f64>,
    /// This tick's anonymous sightings.
    pub detections: Vec<DetectionDto>,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct OpponentState {
    pub id: String,
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    pub tagged: bool,
    pub control: OpponentControl,
}

/// Full ground-truth state of a match.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct MatchState {
    pub id: String,
    pub map: String,
    pub tick: u64,
    pub time_s: f64,
    pub tick_hz: u32,
    pub status: Status,
    pub winner: Option<Winner>,
    pub planner: Planner,
    pub planner_active: Planner,
    pub notes: Vec<String>,
    pub robots: Vec<RobotState>,
    pub opponents: Vec<OpponentState>,
}

pub fn state(world: &World, meta: &MatchMeta) -> MatchState {
    MatchState {
        id: meta.id.clone(),
        map: meta.map.clone(),
        tick: world.tick,
        time_s: world.time_s(),
        tick_hz: TICK_HZ,
        status: status(world.status),
        winner: winner(world.winner),
        planner: planner_dto(world.team.kind()),
        planner_active: planner_dto(world.team.kind()),
        notes: notes(world),
        robots: world
            .robots
            .iter()
            .enumerate()
            .map(|(i, r)| RobotState {
                id: AgentId::Robot(i).to_string(),
                x: mm(r.pose.pos.x),
                y: mm(r.pose.pos.y),
                theta: rad(r.pose.theta),
                estimate: pose(r.estimate),
                spread: mm(r.spread),
                frozen: world.robot_frozen(i),
                goal: r.command.goal.map(pose),
                scan: r.scan.ranges.iter().map(|v| mm(*v)).collect(),
                detections: r
                    .scan
                    .detections
                    .iter()
                    .map(|d| DetectionDto {
                        range: mm(d.range),
                        bearing: rad(d.bearing),
                    })
                    .collect(),
            })
            .collect(),
        opponents: world
            .opponents
            .iter()
            .enumerate()
            .map(|(i, o)| OpponentState {
                id: AgentId::Opponent(i).to_string(),
                x: mm(o.pose.pos.x),
                y: mm(o.pose.pos.y),
                theta: rad(o.pose.theta),
                tagged: o.tagged,
                control: o.control.kind().into(),
            })
            .collect(),
    }
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Role {
    pub id: u64,
    pub count: u32,
    pub tagged: bool,
    /// The team's trust in this cloud, 0..=1: 1 when just confirmed by a sighting.
    pub confidence: f64,
    /// `valid` (≥ 0.5), `suspicious` (≥ 0.15: worth a look) or `invalid` (a guess).
    pub state: ConfidenceState,
    pub particles: Vec<[f64; 2]>,
    pub weights: Vec<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum ConfidenceState {
    Valid,
    Suspicious,
    Invalid,
}

impl From<lasertag_core::tracker::Confidence> for ConfidenceState {
    fn from(c: lasertag_core::tracker::Confidence) -> Self {
        match c {
            lasertag_core::tracker::Confidence::Valid => ConfidenceState::Valid,
            lasertag_core::tracker::Confidence::Suspicious => ConfidenceState::Suspicious,
            lasertag_core::tracker::Confidence::Invalid => ConfidenceState::Invalid,
        }
    }
}

/// The robot team's belief about the opponents: one robot's own (`?robot=r1`), or the
/// team's merged view.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Belief {
    pub tick: u64,
    /// The robot whose belief this is; absent for the team's merged view.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub robot: Option<String>,
    pub roles: Vec<Role>,
}

/// Robot `robot`'s belief, or the team's merged one (with a perfect radio both are the
/// shared tracker's; see `Team::merged_belief`). `None` for a robot the match does not have.
pub fn belief(world: &World, robot: Option<usize>) -> Option<Belief> {
    let roles = match robot {
        Some(i) => {
            std::borrow::Cow::Borrowed(&world.team.belief_of(i, world.robots.len())?.roles[..])
        }
        None => world.team.merged_belief(),
    };
    Some(Belief {
        tick: world.tick,
        robot: robot.map(|i| AgentId::Robot(i).to_string()),
        roles: roles
            .iter()
            .map(|r| Role {
                id: r.id,
                count: r.count,
                tagged: r.tagged,
                confidence: (r.confidence as f64 * 1000.0).round() / 1000.0,
                state: r.confidence_state().into(),
                particles: r.particles().iter().map(|p| [mm(p.x), mm(p.y)]).collect(),
                weights: r.weights().iter().map(|w| *w as f64).collect(),
            })
            .collect(),
    })
}

/// One entry of the event log. Fields beyond `seq`, `tick` and `kind` depend on the kind.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct EventDto {
    pub seq: u64,
    pub tick: u64,
    /// `shot`, `tag`, `robot_tagged`, `role_split`, `role_merge`, `player_joined`,
    /// `player_left`, `finished`.
    pub kind: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub by: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target: Option<String>,
    /// For `shot`: the agent hit, or null for a miss.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hit: Option<Option<String>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub opponent: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub winner: Option<Winner>,
    /// For `finished`: `all_tagged`, `time_limit`, `stopped`, `server_shutdown` or
    /// `abandoned`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_s: Option<f64>,
    /// For `role_split` and `role_merge`: the role that results.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub role: Option<u64>,
    /// For `role_split` and `role_merge`: the role it came from / the role merged away.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub from: Option<u64>,
    /// For `role_merge`: the opponents the merged role stands for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub count: Option<u32>,
}

pub fn event(e: &lasertag_core::world::Event) -> EventDto {
    let mut dto = EventDto {
        seq: e.seq,
        tick: e.tick,
        kind: "",
        by: None,
        target: None,
        hit: None,
        opponent: None,
        name: None,
        winner: None,
        reason: None,
        time_s: None,
        role: None,
        from: None,
        count: None,
    };
    match &e.kind {
        EventKind::Shot { by, hit } => {
            dto.kind = "shot";
            dto.by = Some(by.to_string());
            dto.hit = Some(hit.map(|h| h.to_string()));
        }
        EventKind::Tag { by, target } => {
            dto.kind = "tag";
            dto.by = Some(by.to_string());
            dto.target = Some(target.to_string());
        }
        EventKind::RobotTagged { by, target } => {
            dto.kind = "robot_tagged";
            dto.by = Some(by.to_string());
            dto.target = Some(target.to_string());
        }
        EventKind::RoleSplit { role, from } => {
            dto.kind = "role_split";
            dto.role = Some(*role);
            dto.from = Some(*from);
        }
        EventKind::RoleMerge { role, from, count } => {
            dto.kind = "role_merge";
            dto.role = Some(*role);
            dto.from = Some(*from);
            dto.count = Some(*count);
        }
        EventKind::PlayerJoined { opponent, name } => {
            dto.kind = "player_joined";
            dto.opponent = Some(opponent.to_string());
            dto.name = Some(name.clone());
        }
        EventKind::PlayerLeft { opponent, name } => {
            dto.kind = "player_left";
            dto.opponent = Some(opponent.to_string());
            dto.name = Some(name.clone());
        }
        EventKind::Finished { winner: w, reason } => {
            dto.kind = "finished";
            dto.winner = winner(*w);
            dto.reason = Some(finish_reason(*reason));
            dto.time_s = Some(e.tick as f64 / TICK_HZ as f64);
        }
    }
    dto
}

/// The wire name of why a match ended.
pub fn finish_reason(reason: FinishReason) -> &'static str {
    match reason {
        FinishReason::AllTagged => "all_tagged",
        FinishReason::TimeLimit => "time_limit",
        FinishReason::Stopped => "stopped",
        FinishReason::ServerShutdown => "server_shutdown",
        FinishReason::Abandoned => "abandoned",
    }
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Events {
    pub events: Vec<EventDto>,
}

/// Body of `POST /api/matches/{id}/step`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct StepRequest {
    /// 1..=100000
    #[serde(deserialize_with = "schema::int")]
    #[schema(minimum = 1, maximum = 100_000)]
    pub ticks: i64,
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

/// Body of `POST /api/matches/{id}/players`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JoinRequest {
    /// 1 to 32 characters, none of them control characters, not all whitespace (leading
    /// and trailing whitespace is trimmed off).
    #[schema(
        min_length = 1,
        max_length = 32,
        pattern = r"^[^\u0000-\u001F\u007F-\u009F]*[^\s\u0000-\u001F\u007F-\u009F][^\u0000-\u001F\u007F-\u009F]*$"
    )]
    pub name: String,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Joined {
    pub player_id: String,
    pub opponent_id: String,
    pub token: String,
}

#[cfg(test)]
mod tests;
