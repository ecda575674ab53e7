//! A match as the API shows it: its summary in listings, the ground-truth state, the robot
//! team's belief and the event log, from the core's types, coordinates to the millimetre.
//!
//! Long file: the four views of one match read alike (the same roundings, the same names of
//! agents and sides), and a reader checks one against another in one place.

use super::*;
use crate::game::delay::HeldBelief;
use crate::game::view::{self, Frame, MatchMeta, TrackingFrame};
use crate::game::{MatchError, Reading};

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
    /// The planner asked for (the team's: robots driven from outside beside it are
    /// `robot_planners`' `api` ones).
    pub planner: Planner,
    /// The trained policy driving the team (`policy:<name>`; `planner` then reads `api`).
    pub policy: Option<String>,
    /// Each robot's controller, `r0` first: the team's planner, `api` for one driven from
    /// outside, `policy` for one a trained policy drives, or `person` for a pursuer slot.
    pub robot_planners: Vec<Controller>,
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
    /// The seed; null while a match people may join runs, except to its owner and the
    /// operator (the match is a pure function of its settings, seed and inputs: a public
    /// seed would let anyone rebuild it live). Shown to everyone once it has ended.
    #[schema(schema_with = crate::schema::seed_shown)]
    pub seed: Option<u64>,
    pub players: usize,
    /// WebSocket spectators connected now.
    pub spectators: usize,
    /// Opponent slots a person can take now (`POST /api/matches/{id}/players`).
    pub free_slots: usize,
    /// Robots that are seats for people on the robot team (the last ones).
    pub pursuer_slots: usize,
    /// Of those, the ones a person can take now (`POST /api/matches/{id}/players` with
    /// `"team": "robots"`).
    pub free_pursuer_slots: usize,
    pub bots_joinable: bool,
    /// The robot team's preset, when the match was created with one.
    pub difficulty: Option<DifficultyName>,
    /// Whether it counts for ratings (docs/ratings.md): then its owner token reads it late,
    /// like everybody, and does not see its seed while it runs.
    pub rated: bool,
    /// Caveats a user should know, e.g. a fallback in effect.
    pub notes: Vec<String>,
    /// How far behind the match its state, belief, events and spectator view run for
    /// everyone but its owner: `spectator_delay_s` as asked when people may play it, 0
    /// (live) when they may not.
    pub spectator_delay_s: f64,
    /// The node that hosts the match, when the server runs in a fleet (`--fleet`); absent
    /// otherwise. Its API and WebSocket are at `node.url`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub node: Option<NodeRef>,
}

/// The node that hosts a match: `node` in listings when the server runs in a fleet.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, ToSchema)]
pub struct NodeRef {
    /// The node's id (`--node-id`).
    pub id: String,
    /// Where clients reach it (`--public-url`): its API is under `<url>/api`, its
    /// WebSockets under `<url>/ws`.
    pub url: String,
    /// Whether it is the node that answered.
    pub local: bool,
    /// Whether it is shutting down: it takes no new matches; its running ones go on until
    /// they end or the drain ends them.
    pub draining: bool,
}

/// Caveats about a match: settings that were accepted but do nothing as asked.
pub fn notes(c: &MatchConfig) -> Vec<String> {
    let mut notes = Vec::new();
    if !c.localisation
        && matches!(c.planner, PlannerKind::Coordinated | PlannerKind::Search)
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

/// A match as listings show it to everybody: a secret seed is null (see
/// [`view::Summary::seed_secret`]).
pub fn summary(s: &view::Summary) -> MatchSummary {
    summary_showing(s, !s.seed_secret())
}

/// A match as its owner and the operator see it, and as a replay shows it: with its seed.
pub fn owners_summary(s: &view::Summary) -> MatchSummary {
    summary_showing(s, true)
}

fn summary_showing(s: &view::Summary, seed: bool) -> MatchSummary {
    let c = &*s.config;
    let meta = &s.meta;
    MatchSummary {
        id: meta.id.clone(),
        map: meta.map.clone(),
        clock: meta.clock.into(),
        tick: s.tick,
        tick_hz: TICK_HZ,
        time_s: s.time_s,
        time_limit_s: c.time_limit_ticks as f64 / TICK_HZ as f64,
        status: status(s.status),
        winner: winner(s.winner),
        robots: s.robots,
        opponents: s.opponents,
        opponents_left: s.opponents_left,
        opponent_control: c.opponent_control.into(),
        opponent_bot: match c.opponent_bot {
            BotKind::Wander => OpponentBot::Wander,
            BotKind::Evade => OpponentBot::Evade,
            BotKind::Idle => OpponentBot::Idle,
        },
        planner: planner_dto(s.planner),
        policy: c.policy.clone(),
        robot_planners: super::planners::per_robot(c),
        planner_active: planner_dto(s.planner),
        tracker: Echo(c.tracker.clone()),
        coordination: Echo(c.coordination.clone()),
        localisation: c.localisation,
        radio: Echo(c.radio.clone()),
        odometry: Echo(c.physics.odometry),
        localiser: Echo(c.localiser.clone()),
        seed: seed.then_some(c.seed),
        players: meta.players,
        spectators: meta.spectators,
        free_slots: meta.free_slots,
        pursuer_slots: c.pursuer_slots,
        free_pursuer_slots: meta.free_pursuer_slots,
        bots_joinable: meta.bots_joinable,
        difficulty: meta.difficulty.map(DifficultyName::of),
        rated: meta.rated,
        notes: notes(c),
        spectator_delay_s: meta.spectator_delay_ticks as f64 / TICK_HZ as f64,
        node: None,
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
    /// The longest wall-clock interval between two of its real-time ticks so far,
    /// milliseconds (50 when every tick came on time; 0 before its second tick).
    pub longest_tick_gap_ms: f64,
    /// Frames published to viewers so far.
    pub frames_published: u64,
    pub spectators: usize,
    pub players_connected: usize,
}

/// The stats of match `id`.
pub fn stats(id: &str, s: &view::Stats) -> MatchStats {
    MatchStats {
        id: id.to_string(),
        tick: s.tick,
        ticks_measured: s.ticks_measured,
        tick_us_p50: s.tick_us_p50,
        tick_us_p99: s.tick_us_p99,
        tick_us_max: s.tick_us_max,
        tick_us_mean: s.tick_us_mean,
        late_ticks: s.late_ticks,
        longest_tick_gap_ms: s.longest_tick_gap_ms,
        frames_published: s.frames_published,
        spectators: s.spectators,
        players_connected: s.players_connected,
    }
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
    /// The trained policy that drives the team, as in the summary.
    pub policy: Option<String>,
    /// Each robot's controller, as in the summary.
    pub robot_planners: Vec<Controller>,
    pub planner_active: Planner,
    pub notes: Vec<String>,
    pub robots: Vec<RobotState>,
    pub opponents: Vec<OpponentState>,
    pub tracking: Tracking,
}

/// How close the robot team's belief is to the truth at this tick: GOSPA (α = 2) between
/// the points its untagged roles put opponents at (a role for k opponents gives k points)
/// and the opponents still in the arena, with
/// `gospa^p = localisation^p + c^p/2 · (missed + false)`. See docs/tracker.md.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Tracking {
    /// The GOSPA distance, metres: 0 when every estimate is on its opponent.
    pub gospa: f64,
    /// The assigned pairs' part, `(Σ d^p)^(1/p)` over pairs nearer than `c`, metres.
    pub localisation: f64,
    /// Opponents matched to no estimate within `c`.
    pub missed: u32,
    /// Estimates matched to no opponent within `c`.
    #[serde(rename = "false")]
    pub false_targets: u32,
    /// Cut-off, metres.
    pub c: f64,
    /// Order.
    pub p: f64,
}

impl From<TrackingFrame> for Tracking {
    fn from(t: TrackingFrame) -> Self {
        Tracking {
            gospa: mm(t.gospa.distance),
            localisation: mm(t.gospa.localisation),
            missed: t.gospa.missed as u32,
            false_targets: t.gospa.false_targets as u32,
            c: t.params.c as f64,
            p: t.params.p as f64,
        }
    }
}

/// The ground truth of `frame` (the latest one for those who may see it live, an older
/// one held back for everybody else); `config` is the match's, for what does not change.
pub fn state(frame: &Frame, meta: &MatchMeta, config: &MatchConfig) -> MatchState {
    MatchState {
        id: meta.id.clone(),
        map: meta.map.clone(),
        tick: frame.tick,
        time_s: frame.time_s,
        tick_hz: TICK_HZ,
        status: status(frame.status),
        winner: winner(frame.winner),
        planner: planner_dto(config.planner),
        policy: config.policy.clone(),
        robot_planners: super::planners::per_robot(config),
        planner_active: planner_dto(config.planner),
        notes: notes(config),
        robots: frame
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
                frozen: r.frozen,
                goal: r.goal.map(pose),
                scan: r.scan.iter().map(|v| mm(*v)).collect(),
                detections: r
                    .detections
                    .iter()
                    .map(|d| DetectionDto {
                        range: mm(d.range),
                        bearing: rad(d.bearing),
                    })
                    .collect(),
            })
            .collect(),
        opponents: frame
            .opponents
            .iter()
            .enumerate()
            .map(|(i, o)| OpponentState {
                id: AgentId::Opponent(i).to_string(),
                x: mm(o.pose.pos.x),
                y: mm(o.pose.pos.y),
                theta: rad(o.pose.theta),
                tagged: o.tagged,
                control: o.control.into(),
            })
            .collect(),
        tracking: frame.tracking.into(),
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

/// Robot `robot`'s belief in `world` now, or the team's merged one; `None` for a robot the
/// match does not have.
pub fn belief_of(world: &World, robot: Option<usize>) -> Option<Belief> {
    HeldBelief::of(world, robot).map(|b| belief(&b, robot))
}

/// `held` as the API shows it, for `robot` (or the team when `None`).
pub fn belief(held: &HeldBelief, robot: Option<usize>) -> Belief {
    Belief {
        tick: held.tick,
        robot: robot.map(|i| AgentId::Robot(i).to_string()),
        roles: held
            .roles
            .iter()
            .map(|r| Role {
                id: r.id,
                count: r.count,
                tagged: r.tagged,
                confidence: (r.confidence as f64 * 1000.0).round() / 1000.0,
                state: r.state.into(),
                particles: r.particles.iter().map(|p| [mm(p.x), mm(p.y)]).collect(),
                weights: r.weights.iter().map(|w| *w as f64).collect(),
            })
            .collect(),
    }
}

/// One entry of the event log. Fields beyond `seq`, `tick` and `kind` depend on the kind.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct EventDto {
    pub seq: u64,
    pub tick: u64,
    /// `shot`, `tag`, `robot_tagged`, `role_split`, `role_merge`, `player_joined`,
    /// `player_left`, `mark`, `finished`.
    pub kind: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub by: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target: Option<String>,
    /// For `shot`: the agent hit, or null for a miss.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hit: Option<Option<String>>,
    /// For `player_joined` and `player_left`: the opponent slot the person took or left, ...
    #[serde(skip_serializing_if = "Option::is_none")]
    pub opponent: Option<String>,
    /// ... or the robot, for a person on the robot team (a pursuer seat).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub robot: Option<String>,
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
    /// For `mark`: the point marked, in metres.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub x: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub y: Option<f64>,
    /// For `mark`: `robot` (a robot seen there), `go` or `danger`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mark: Option<&'static str>,
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
        robot: None,
        name: None,
        winner: None,
        reason: None,
        time_s: None,
        role: None,
        from: None,
        count: None,
        x: None,
        y: None,
        mark: None,
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
        EventKind::PlayerJoined { agent, name } | EventKind::PlayerLeft { agent, name } => {
            dto.kind = if matches!(e.kind, EventKind::PlayerJoined { .. }) {
                "player_joined"
            } else {
                "player_left"
            };
            match agent {
                AgentId::Opponent(_) => dto.opponent = Some(agent.to_string()),
                AgentId::Robot(_) => dto.robot = Some(agent.to_string()),
            }
            dto.name = Some(name.clone());
        }
        EventKind::Mark { by, name, at, kind } => {
            // `by` is the marker's name, as their teammates call them; the agent is in
            // `opponent` or `robot`, as for seats.
            dto.kind = "mark";
            dto.by = Some(name.clone());
            match by {
                AgentId::Opponent(_) => dto.opponent = Some(by.to_string()),
                AgentId::Robot(_) => dto.robot = Some(by.to_string()),
            }
            dto.x = Some(lasertag_core::env::mm(at.x));
            dto.y = Some(lasertag_core::env::mm(at.y));
            dto.mark = Some(kind.name());
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
    reason.name()
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Events {
    pub events: Vec<EventDto>,
}

// What the handlers ask a match for (`MatchHandle::read`): each converts what its reader may
// see, on the match's task.

/// The ground truth, as the reader may see it.
pub fn read_state(r: &mut Reading<'_>) -> Result<MatchState, MatchError> {
    let frame = r.frame();
    Ok(state(&frame, r.meta(), r.config()))
}

/// The match as its owner sees it (its seed included), now.
pub fn read_summary(r: &mut Reading<'_>) -> Result<MatchSummary, MatchError> {
    Ok(owners_summary(&r.summary()))
}

/// How the match's task keeps up.
pub fn read_stats(r: &mut Reading<'_>) -> Result<MatchStats, MatchError> {
    Ok(stats(&r.meta().id, &r.stats()))
}

/// Robot `robot`'s belief, or the team's, as the reader may see it.
pub fn read_belief(
    robot: Option<usize>,
) -> impl FnOnce(&mut Reading<'_>) -> Result<Belief, MatchError> + Send + 'static {
    move |r| Ok(belief(&*r.belief(robot)?, robot))
}

/// The events after `since` the reader may see.
pub fn read_events(
    since: u64,
) -> impl FnOnce(&mut Reading<'_>) -> Result<Events, MatchError> + Send + 'static {
    move |r| {
        Ok(Events {
            events: r.events(since).iter().map(event).collect(),
        })
    }
}
