//! One match: the tick pipeline over plain data.
//!
//! [`World::step`] runs, in order:
//! 1. inputs — opponents' motions (bots decide now; API routes; people's latest keys) and the
//!    robots' commands decided at the end of the previous tick;
//! 2. motion — every agent moves, then collisions resolve (robots first, then opponents,
//!    each in id order, so the result is deterministic);
//! 3. sensing — every robot that is not frozen scans, detects and sights landmarks; then
//!    each robot localises (odometry, laser and landmarks into its own particle filter);
//! 4. rules — shots (robots first), freezes, eliminations, the end of the match;
//! 5. team — the robots' brain reads what they sensed and decides the next tick's commands;
//! 6. events — appended to the log with increasing `seq`.
//!
//! Randomness comes from one seed split into independent ChaCha streams (sensing, bots,
//! team, tracker, set-up, odometry, localisers, radio), so changing, say, a bot's behaviour
//! does not shift the laser noise.

use std::collections::VecDeque;
use std::sync::Arc;

use nalgebra::Point2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::bots::{Bot, BotKind};
use crate::localise::dead_reckoning::DeadReckoning;
use crate::localise::{LikelihoodField, Localiser, Observation};
use crate::planner::{PlannerKind, RobotCommand, RobotView, Team, TeamView};
use crate::sim::arena::Arena;
use crate::sim::sensors::{self, Detection, LandmarkSighting, Scan};
use crate::sim::{AGENT_RADIUS, AgentId, Motion, Physics, Pose, TICK_HZ, motion, rules};
use crate::tracker::{Tracker, TrackerEvent};

/// Who controls every opponent slot of a match.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControlKind {
    Bot,
    Api,
    Human,
}

/// Where agents start.
#[derive(Debug, Clone, PartialEq)]
pub enum Placement {
    /// The map's spawns, in order, wrapping (displaced to the nearest free spot when taken).
    Spawns,
    /// Random free points of the arena, all mutually reachable (for experiments).
    Random,
    /// Explicit starts: robots `(x, y, heading)` and opponents `(x, y)`; empty lists fall back to spawns.
    Given {
        robots: Vec<[f32; 3]>,
        opponents: Vec<[f32; 2]>,
    },
}

/// Everything that defines a match besides the map.
#[derive(Debug, Clone)]
pub struct MatchConfig {
    pub robots: usize,
    pub opponents: usize,
    pub opponent_control: ControlKind,
    pub opponent_bot: BotKind,
    pub planner: PlannerKind,
    pub seed: u64,
    pub time_limit_ticks: u64,
    pub placement: Placement,
    pub physics: Physics,
    pub tracker: crate::tracker::Settings,
    /// Weights of the `coordinated` planner.
    pub coordination: crate::planner::coordinated::Settings,
    /// Robots localise themselves (MCL from odometry, laser and landmarks); when off, each
    /// robot's estimate is its odometry alone (dead reckoning, which drifts). Either way no
    /// decision reads the true pose.
    pub localisation: bool,
    pub localiser: crate::localise::Settings,
    /// The team radio: perfect (the default) keeps one shared tracker; a latency or loss
    /// gives every robot its own (see `crate::radio`).
    pub radio: crate::radio::Settings,
}

impl Default for MatchConfig {
    fn default() -> Self {
        MatchConfig {
            robots: 2,
            opponents: 1,
            opponent_control: ControlKind::Bot,
            opponent_bot: BotKind::Wander,
            planner: PlannerKind::Coordinated,
            seed: 0,
            time_limit_ticks: 300 * TICK_HZ as u64,
            placement: Placement::Spawns,
            physics: Physics::default(),
            tracker: crate::tracker::Settings::default(),
            coordination: crate::planner::coordinated::Settings::default(),
            localisation: true,
            localiser: crate::localise::Settings::default(),
            radio: crate::radio::Settings::default(),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    Robots,
    Opponents,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MatchStatus {
    Running,
    Finished,
}

/// Why a match ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FinishReason {
    AllTagged,
    TimeLimit,
    /// Ended from outside (deleted through the API).
    Stopped,
    /// The server is shutting down: nobody won.
    ServerShutdown,
    /// Nobody took part for too long (the server's clean-up): nobody won.
    Abandoned,
}

/// Points within a tick where [`World::step_marked`] calls its observer, so that the shell
/// can time the team's halves without the core reading a clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepMark {
    /// The tracker's update is about to start.
    Tracker,
    /// The tracker is done; the planner is about to start.
    Planner,
    /// The planner is done.
    Planned,
}

#[derive(Debug, Clone, PartialEq)]
pub enum EventKind {
    /// A tag device fired; `hit` is the agent it hit, if any.
    Shot {
        by: AgentId,
        hit: Option<AgentId>,
    },
    /// A robot tagged an opponent, eliminating it.
    Tag {
        by: AgentId,
        target: AgentId,
    },
    /// An opponent tagged a robot, freezing it.
    RobotTagged {
        by: AgentId,
        target: AgentId,
    },
    /// The tracker split role `role` off role `from` for one newly seen opponent.
    RoleSplit {
        role: u64,
        from: u64,
    },
    /// The tracker merged role `from` into `role`, which now stands for `count` opponents.
    RoleMerge {
        role: u64,
        from: u64,
        count: u32,
    },
    PlayerJoined {
        opponent: AgentId,
        name: String,
    },
    PlayerLeft {
        opponent: AgentId,
        name: String,
    },
    Finished {
        winner: Option<Side>,
        reason: FinishReason,
    },
}

#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    pub seq: u64,
    pub tick: u64,
    pub kind: EventKind,
}

#[derive(Debug, Clone)]
pub struct Robot {
    pub pose: Pose,
    /// The robot's own belief about its pose: its localiser's point estimate, or its
    /// odometry when localisation is off. Everything the team decides starts from this.
    pub estimate: Pose,
    /// Standard deviation of the robot's position belief (m): its localiser's, or with
    /// localisation off the dead-reckoning uncertainty, which only grows.
    pub spread: f32,
    /// Dead-reckoned pose from the wheel odometry (starts at the true start pose).
    pub odometry: Pose,
    /// The uncertainty of `odometry` (used for `spread` when there is no localiser).
    pub dead_reckoning: DeadReckoning,
    /// Landmarks recognised this tick.
    pub landmarks: Vec<LandmarkSighting>,
    pub localiser: Option<Box<Localiser>>,
    pub frozen_until: u64,
    pub cooldown_until: u64,
    pub scan: Scan,
    pub command: RobotCommand,
}

/// A route given to an API-driven opponent.
#[derive(Debug, Clone, Default)]
pub struct ApiRoute {
    pub waypoints: VecDeque<Point2<f32>>,
    pub fire: bool,
}

/// A person's latest keys.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct HumanInput {
    pub forward: f32,
    pub turn: f32,
    pub tag: bool,
}

#[derive(Debug, Clone)]
pub enum Control {
    Bot(Bot),
    Api(ApiRoute),
    Human(HumanInput),
}

#[derive(Debug, Clone)]
pub struct Opponent {
    pub pose: Pose,
    pub tagged: bool,
    pub cooldown_until: u64,
    pub control: Control,
}

/// An external order for an API-driven opponent.
#[derive(Debug, Clone, PartialEq)]
pub enum OpponentOrder {
    Waypoints(Vec<Point2<f32>>),
    Stop,
    Tag,
}

/// Why an order or input was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OrderError {
    #[error("no opponent {0} in this match")]
    UnknownOpponent(String),
    #[error("opponent {0} is not API-controlled")]
    NotApiControlled(String),
    #[error("opponent {0} has been tagged")]
    Tagged(String),
    #[error("{field}: [{x}, {y}] lies outside the arena")]
    OutsideArena { field: String, x: f32, y: f32 },
}

/// A match could not be set up as asked.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SetupError {
    #[error("{0}: no free place for this agent")]
    NoRoom(String),
    #[error("{field}: {message}")]
    BadStart { field: String, message: String },
}

#[derive(Debug, Clone)]
pub struct World {
    pub arena: Arc<Arena>,
    pub config: MatchConfig,
    pub tick: u64,
    pub status: MatchStatus,
    pub winner: Option<Side>,
    pub robots: Vec<Robot>,
    pub opponents: Vec<Opponent>,
    pub team: Team,
    events: Vec<Event>,
    rng_sense: ChaCha8Rng,
    rng_bots: ChaCha8Rng,
    rng_odometry: ChaCha8Rng,
    rng_localise: ChaCha8Rng,
}

/// Independent streams of the match seed.
const STREAM_SENSE: u64 = 1;
const STREAM_BOTS: u64 = 2;
const STREAM_TEAM: u64 = 3;
const STREAM_SETUP: u64 = 4;
const STREAM_TRACKER: u64 = 5;
/// Odometry and landmark-sighting noise (a stream of its own so the laser's draws don't shift).
const STREAM_ODOMETRY: u64 = 6;
/// The robots' localisers (the team's side).
const STREAM_LOCALISE: u64 = 7;
/// The team radio's losses (a stream of its own: a perfect radio draws from it too, and
/// no other stream shifts when the radio changes).
const STREAM_RADIO: u64 = 8;

fn stream(seed: u64, id: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(id);
    rng
}

impl World {
    pub fn new(arena: Arc<Arena>, config: MatchConfig) -> Result<World, SetupError> {
        let mut setup = stream(config.seed, STREAM_SETUP);
        let (robot_starts, opponent_starts) = place_agents(&arena, &config, &mut setup)?;
        let mut rng_localise = stream(config.seed, STREAM_LOCALISE);
        let field = config
            .localisation
            .then(|| LikelihoodField::of(&arena, &config.localiser, config.physics.laser_range));
        let robots = robot_starts
            .into_iter()
            .map(|pose| Robot {
                pose,
                estimate: pose,
                spread: 0.0,
                odometry: pose,
                dead_reckoning: DeadReckoning::new(pose),
                landmarks: Vec::new(),
                localiser: field.as_ref().map(|f| {
                    Box::new(Localiser::new(
                        f.clone(),
                        &arena,
                        config.localiser.clone(),
                        pose,
                        pose,
                        &mut rng_localise,
                    ))
                }),
                frozen_until: 0,
                cooldown_until: 0,
                scan: Scan::default(),
                command: RobotCommand::default(),
            })
            .collect();
        let opponents = opponent_starts
            .into_iter()
            .map(|pose| Opponent {
                pose,
                tagged: false,
                cooldown_until: 0,
                control: match config.opponent_control {
                    ControlKind::Bot => Control::Bot(Bot::new(config.opponent_bot)),
                    ControlKind::Api => Control::Api(ApiRoute::default()),
                    ControlKind::Human => Control::Human(HumanInput::default()),
                },
            })
            .collect();
        let mut tracker_settings = config.tracker.clone();
        tracker_settings.opponent_speed = config.physics.opponent_speed;
        tracker_settings.tag_half_angle = config.physics.tag_half_angle;
        tracker_settings.tag_range = config.physics.tag_range;
        let tracker = Tracker::new(
            &arena,
            tracker_settings,
            config.opponents as u32,
            stream(config.seed, STREAM_TRACKER),
        );
        let team = Team::new(
            config.planner,
            &arena,
            &config.physics,
            crate::planner::coordinated::Settings {
                // Without a localiser a landmark in view corrects nothing: an uncertain robot
                // still avoids narrow passages, but has no reason to seek landmarks.
                landmark_weight: if config.localisation {
                    config.coordination.landmark_weight
                } else {
                    0.0
                },
                ..config.coordination.clone()
            },
            config.robots,
            tracker,
            stream(config.seed, STREAM_TEAM),
        )
        .with_radio(
            crate::radio::Radio::new(config.radio.clone(), stream(config.seed, STREAM_RADIO)),
            config.robots,
        );
        let mut world = World {
            team,
            robots,
            opponents,
            tick: 0,
            status: MatchStatus::Running,
            winner: None,
            events: Vec::new(),
            rng_sense: stream(config.seed, STREAM_SENSE),
            rng_bots: stream(config.seed, STREAM_BOTS),
            rng_odometry: stream(config.seed, STREAM_ODOMETRY),
            rng_localise,
            arena,
            config,
        };
        // Robots see the world before their first decision.
        world.sense();
        world.localise();
        world.think(&mut |_| {});
        Ok(world)
    }

    pub fn time_s(&self) -> f64 {
        self.tick as f64 / TICK_HZ as f64
    }

    pub fn events(&self) -> &[Event] {
        &self.events
    }

    /// Events with `seq > since`, oldest first.
    pub fn events_since(&self, since: u64) -> &[Event] {
        // seq is index + 1, so this is a slice, not a search.
        let start = (since as usize).min(self.events.len());
        &self.events[start..]
    }

    fn push(&mut self, kind: EventKind) {
        let seq = self.events.len() as u64 + 1;
        self.events.push(Event {
            seq,
            tick: self.tick,
            kind,
        });
    }

    pub fn robot_frozen(&self, i: usize) -> bool {
        self.tick < self.robots[i].frozen_until
    }

    /// Advances the match by one tick (see the module docs for the stages).
    pub fn step(&mut self) {
        self.step_marked(&mut |_| {});
    }

    /// [`World::step`], calling `mark` at the [`StepMark`]s of the team stage (not at all in
    /// a tick that ends the match before it). The match is the same whatever `mark` does.
    pub fn step_marked(&mut self, mark: &mut dyn FnMut(StepMark)) {
        if self.status == MatchStatus::Finished {
            return;
        }
        self.tick += 1;
        let motions = self.inputs();
        self.move_agents(&motions);
        self.sense();
        self.localise();
        self.rules();
        self.think(mark);
    }

    /// Stage 1: this tick's motion of every agent (robots first, then opponents).
    pub fn inputs(&mut self) -> Vec<Motion> {
        let mut motions: Vec<Motion> = (0..self.robots.len())
            .map(|i| {
                if self.robot_frozen(i) {
                    Motion::Stop
                } else {
                    self.robots[i].command.motion
                }
            })
            .collect();
        let robot_centres: Vec<Point2<f32>> = self.robots.iter().map(|r| r.pose.pos).collect();
        for o in &mut self.opponents {
            let m = if o.tagged {
                Motion::Stop
            } else {
                match &mut o.control {
                    Control::Bot(bot) => bot.decide(
                        &self.arena,
                        o.pose,
                        &robot_centres,
                        self.tick,
                        &mut self.rng_bots,
                    ),
                    Control::Api(route) => {
                        while let Some(w) = route.waypoints.front() {
                            if (w - o.pose.pos).norm() < 1e-3 {
                                route.waypoints.pop_front();
                            } else {
                                break;
                            }
                        }
                        route
                            .waypoints
                            .front()
                            .map_or(Motion::Stop, |w| Motion::Toward(*w))
                    }
                    Control::Human(input) => Motion::Drive {
                        forward: input.forward,
                        turn: input.turn,
                    },
                }
            };
            motions.push(m);
        }
        motions
    }

    /// Centres of every agent in the arena (eliminated opponents have left it).
    fn present(&self) -> Vec<(AgentId, Point2<f32>)> {
        let robots = self
            .robots
            .iter()
            .enumerate()
            .map(|(i, r)| (AgentId::Robot(i), r.pose.pos));
        let opponents = self
            .opponents
            .iter()
            .enumerate()
            .filter(|(_, o)| !o.tagged)
            .map(|(i, o)| (AgentId::Opponent(i), o.pose.pos));
        robots.chain(opponents).collect()
    }

    /// Stage 2.
    pub fn move_agents(&mut self, motions: &[Motion]) {
        let p = &self.config.physics;
        let mut centres = self.present();
        let nr = self.robots.len();
        for (k, (id, _)) in centres.clone().iter().enumerate() {
            let (pose, m, speed, turn) = match *id {
                AgentId::Robot(i) => (
                    self.robots[i].pose,
                    motions[i],
                    p.robot_speed,
                    p.robot_turn_rate,
                ),
                AgentId::Opponent(i) => (
                    self.opponents[i].pose,
                    motions[nr + i],
                    p.opponent_speed,
                    p.opponent_turn_rate,
                ),
            };
            if m == Motion::Stop {
                continue;
            }
            let proposed = motion::propose(pose, m, speed, turn);
            let others: Vec<Point2<f32>> = centres
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != k)
                .map(|(_, (_, c))| *c)
                .collect();
            let pos = motion::resolve(&self.arena, pose.pos, proposed.pos, &others);
            let new = Pose {
                pos,
                theta: proposed.theta,
            };
            centres[k].1 = pos;
            match *id {
                AgentId::Robot(i) => {
                    let r = &mut self.robots[i];
                    r.odometry =
                        sensors::odometry_step(p, r.odometry, r.pose, new, &mut self.rng_odometry);
                    r.pose = new;
                }
                AgentId::Opponent(i) => self.opponents[i].pose = new,
            }
        }
    }

    /// Stage 3.
    pub fn sense(&mut self) {
        let present = self.present();
        for i in 0..self.robots.len() {
            if self.robot_frozen(i) {
                self.robots[i].scan = Scan::default();
                self.robots[i].landmarks.clear();
                continue;
            }
            let others: Vec<_> = present
                .iter()
                .filter(|(id, _)| *id != AgentId::Robot(i))
                .copied()
                .collect();
            self.robots[i].scan = sensors::scan(
                &self.arena,
                &self.config.physics,
                self.robots[i].pose,
                &others,
                &mut self.rng_sense,
            );
            if self.config.localisation {
                self.robots[i].landmarks = sensors::sight_landmarks(
                    &self.arena,
                    &self.config.physics,
                    self.robots[i].pose,
                    &mut self.rng_odometry,
                );
            }
        }
    }

    /// Stage 3b: every robot updates its belief about its own pose from its odometry and
    /// what it sensed (the truth stays with the referee).
    pub fn localise(&mut self) {
        let p = &self.config.physics;
        // A robot masks the beams that end on a teammate where it believes that teammate is:
        // its estimate after the last tick, as the radio last told (never the truth).
        let estimates: Vec<Point2<f32>> = self.robots.iter().map(|r| r.estimate.pos).collect();
        for (i, r) in self.robots.iter_mut().enumerate() {
            let Some(loc) = r.localiser.as_mut() else {
                r.estimate = r.odometry;
                r.dead_reckoning.update(p, r.odometry);
                r.spread = r.dead_reckoning.spread();
                continue;
            };
            loc.predict(r.odometry);
            let own = loc.estimate();
            let mut movers = r.scan.detections.clone();
            for j in 0..estimates.len() {
                let Some(mate) = self.team.believed_teammate(i, j, &estimates) else {
                    continue;
                };
                let d = mate - own.pos;
                let range = d.norm();
                if j != i && range > 1e-3 && range < p.laser_range {
                    movers.push(Detection {
                        range,
                        bearing: own.bearing_to(mate),
                    });
                }
            }
            let obs = Observation {
                ranges: &r.scan.ranges,
                laser_fov: p.laser_fov,
                laser_range: p.laser_range,
                landmarks: &r.landmarks,
                movers: &movers,
            };
            loc.correct(&obs, &mut self.rng_localise);
            r.estimate = loc.estimate();
            r.spread = loc.spread();
        }
    }

    /// Stage 4.
    pub fn rules(&mut self) {
        let tick = self.tick;
        let cooldown = self.config.physics.tag_cooldown_ticks;
        // Who pulls a trigger this tick: robots by their command, opponents by control.
        let mut shooters: Vec<AgentId> = Vec::new();
        for (i, r) in self.robots.iter().enumerate() {
            if r.command.tag && !self.robot_frozen(i) && tick >= r.cooldown_until {
                shooters.push(AgentId::Robot(i));
            }
        }
        for (i, o) in self.opponents.iter_mut().enumerate() {
            let wants = match &mut o.control {
                Control::Api(route) => std::mem::take(&mut route.fire),
                Control::Human(input) => input.tag,
                Control::Bot(_) => false,
            };
            if wants && !o.tagged && tick >= o.cooldown_until {
                shooters.push(AgentId::Opponent(i));
            }
        }
        for shooter in shooters {
            // An opponent eliminated earlier this tick no longer fires.
            let (pose, alive) = match shooter {
                AgentId::Robot(i) => (self.robots[i].pose, !self.robot_frozen(i)),
                AgentId::Opponent(i) => (self.opponents[i].pose, !self.opponents[i].tagged),
            };
            if !alive {
                continue;
            }
            let others: Vec<_> = self
                .present()
                .into_iter()
                .filter(|(id, _)| *id != shooter)
                .collect();
            let hit = rules::shot_target(&self.arena, &self.config.physics, pose, &others);
            match shooter {
                AgentId::Robot(i) => self.robots[i].cooldown_until = tick + cooldown,
                AgentId::Opponent(i) => self.opponents[i].cooldown_until = tick + cooldown,
            }
            self.push(EventKind::Shot { by: shooter, hit });
            match (shooter, hit) {
                (AgentId::Robot(_), Some(AgentId::Opponent(t))) => {
                    self.opponents[t].tagged = true;
                    self.push(EventKind::Tag {
                        by: shooter,
                        target: AgentId::Opponent(t),
                    });
                }
                (AgentId::Opponent(_), Some(AgentId::Robot(t))) => {
                    // Its scan of this tick was taken before the hit and still counts;
                    // it senses nothing from the next tick on.
                    self.robots[t].frozen_until = tick + self.config.physics.freeze_ticks;
                    self.push(EventKind::RobotTagged {
                        by: shooter,
                        target: AgentId::Robot(t),
                    });
                }
                _ => {} // a miss, or a teammate in the way
            }
        }
        if self.opponents.iter().all(|o| o.tagged) {
            self.finish(Side::Robots, FinishReason::AllTagged);
        } else if tick >= self.config.time_limit_ticks {
            self.finish(Side::Opponents, FinishReason::TimeLimit);
        }
    }

    fn finish(&mut self, winner: Side, reason: FinishReason) {
        self.end(Some(winner), reason);
    }

    fn end(&mut self, winner: Option<Side>, reason: FinishReason) {
        if self.status == MatchStatus::Finished {
            return;
        }
        self.status = MatchStatus::Finished;
        self.winner = winner;
        self.push(EventKind::Finished { winner, reason });
    }

    /// Ends a running match from outside (deletion): the opponents were not all caught.
    pub fn stop(&mut self) {
        self.finish(Side::Opponents, FinishReason::Stopped);
    }

    /// Ends a running match from outside for `reason`: [`FinishReason::Stopped`] as
    /// [`World::stop`]; a shutdown or abandonment has no winner. A finished match is left
    /// as it is.
    pub fn stop_because(&mut self, reason: FinishReason) {
        match reason {
            FinishReason::ServerShutdown | FinishReason::Abandoned => self.end(None, reason),
            _ => self.stop(),
        }
    }

    /// Stage 5: the robots' brain decides from what they sensed.
    pub fn think(&mut self, mark: &mut dyn FnMut(StepMark)) {
        let tick = self.tick;
        // A tag device reports its own hits: the robots that tagged an opponent this tick.
        let hits: Vec<usize> = self
            .events
            .iter()
            .rev()
            .take_while(|e| e.tick == tick)
            .filter_map(|e| match e.kind {
                EventKind::Tag {
                    by: AgentId::Robot(r),
                    ..
                } => Some(r),
                _ => None,
            })
            .collect();
        let view = TeamView {
            tick,
            robots: self
                .robots
                .iter()
                .enumerate()
                .map(|(i, r)| RobotView {
                    hit: hits.contains(&i),
                    pose: r.estimate,
                    spread: r.spread,
                    frozen: tick < r.frozen_until,
                    can_fire: tick + 1 >= r.cooldown_until,
                    scan: &r.scan.ranges,
                    detections: &r.scan.detections,
                })
                .collect(),
        };
        mark(StepMark::Tracker);
        let tracker_events = self.team.track(&self.arena, &self.config.physics, &view);
        mark(StepMark::Planner);
        let commands = self.team.plan(&self.arena, &self.config.physics, &view);
        mark(StepMark::Planned);
        for (r, c) in self.robots.iter_mut().zip(commands) {
            r.command = c;
        }
        for e in tracker_events {
            self.push(match e {
                TrackerEvent::Split { role, from } => EventKind::RoleSplit { role, from },
                TrackerEvent::Merge { role, from, count } => {
                    EventKind::RoleMerge { role, from, count }
                }
            });
        }
    }

    /// Replaces an API-driven opponent's route, stops it, or fires its device on the next tick.
    pub fn order_opponent(&mut self, index: usize, order: OpponentOrder) -> Result<(), OrderError> {
        let (w, h) = (self.arena.width(), self.arena.height());
        let name = format!("o{index}");
        let o = self
            .opponents
            .get_mut(index)
            .ok_or_else(|| OrderError::UnknownOpponent(name.clone()))?;
        let Control::Api(route) = &mut o.control else {
            return Err(OrderError::NotApiControlled(name));
        };
        if o.tagged {
            return Err(OrderError::Tagged(name));
        }
        match order {
            OpponentOrder::Waypoints(points) => {
                for (k, p) in points.iter().enumerate() {
                    if !(p.x.is_finite()
                        && p.y.is_finite()
                        && p.x >= 0.0
                        && p.y >= 0.0
                        && p.x <= w
                        && p.y <= h)
                    {
                        return Err(OrderError::OutsideArena {
                            field: format!("waypoints[{k}]"),
                            x: p.x,
                            y: p.y,
                        });
                    }
                }
                route.waypoints = points.into();
            }
            OpponentOrder::Stop => route.waypoints.clear(),
            OpponentOrder::Tag => route.fire = true,
        }
        Ok(())
    }

    /// Sets a person's latest keys for a human-controlled opponent.
    pub fn set_human_input(&mut self, index: usize, input: HumanInput) -> bool {
        match self.opponents.get_mut(index).map(|o| &mut o.control) {
            Some(Control::Human(current)) => {
                *current = input;
                true
            }
            _ => false,
        }
    }

    pub fn log_player(&mut self, index: usize, name: String, joined: bool) {
        let opponent = AgentId::Opponent(index);
        self.push(if joined {
            EventKind::PlayerJoined { opponent, name }
        } else {
            EventKind::PlayerLeft { opponent, name }
        });
    }

    /// A digest of the whole observable state, for determinism tests.
    pub fn digest(&self) -> u64 {
        let mut h = Fnv::default();
        h.write(self.tick);
        h.write(self.status as u64);
        for r in &self.robots {
            h.pose(r.pose);
            h.write(r.frozen_until);
            h.write(r.cooldown_until);
            r.scan
                .ranges
                .iter()
                .for_each(|v| h.write(v.to_bits() as u64));
            for d in &r.scan.detections {
                h.write(d.range.to_bits() as u64);
                h.write(d.bearing.to_bits() as u64);
            }
            if let Some(g) = r.command.goal {
                h.pose(g);
            }
        }
        for o in &self.opponents {
            h.pose(o.pose);
            h.write(o.tagged as u64);
        }
        h.write(self.events.len() as u64);
        h.0
    }
}

#[derive(Debug)]
struct Fnv(u64);

impl Default for Fnv {
    fn default() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv {
    fn write(&mut self, v: u64) {
        for b in v.to_le_bytes() {
            self.0 ^= b as u64;
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }

    fn pose(&mut self, p: Pose) {
        self.write(p.pos.x.to_bits() as u64);
        self.write(p.pos.y.to_bits() as u64);
        self.write(p.theta.to_bits() as u64);
    }
}

/// Start poses for every robot and opponent (see [`Placement`]).
fn place_agents(
    arena: &Arena,
    config: &MatchConfig,
    rng: &mut ChaCha8Rng,
) -> Result<(Vec<Pose>, Vec<Pose>), SetupError> {
    let def = &arena.def;
    let mut taken: Vec<Point2<f32>> = Vec::new();
    let mut robots = Vec::with_capacity(config.robots);
    let mut opponents = Vec::with_capacity(config.opponents);
    let random_cells: Vec<usize> = if config.placement == Placement::Random {
        reachable_cells(arena)
    } else {
        Vec::new()
    };
    let mut pick_random = |taken: &[Point2<f32>], id: String| -> Result<Point2<f32>, SetupError> {
        for _ in 0..10_000 {
            let Some(&cell) = random_cells.get(rng.random_range(0..random_cells.len().max(1)))
            else {
                break;
            };
            let p = arena.grid.centre(cell);
            if taken.iter().all(|t| (t - p).norm() >= 1.0) {
                return Ok(p);
            }
        }
        Err(SetupError::NoRoom(id))
    };
    for i in 0..config.robots {
        let id = format!("r{i}");
        let (pos, theta) = match &config.placement {
            Placement::Random => {
                let p = pick_random(&taken, id)?;
                (p, 0.0)
            }
            Placement::Given { robots: given, .. } if !given.is_empty() => {
                let s = given.get(i).ok_or_else(|| SetupError::BadStart {
                    field: "robot_starts".into(),
                    message: format!(
                        "has {} entries, the match has {} robots",
                        given.len(),
                        config.robots
                    ),
                })?;
                let p = Point2::new(s[0], s[1]);
                check_given(arena, &taken, p, format!("robot_starts[{i}]"))?;
                (p, s[2])
            }
            _ => {
                let s = def.robot_spawns[i % def.robot_spawns.len()];
                (
                    free_near(arena, &taken, Point2::new(s[0], s[1]))
                        .ok_or(SetupError::NoRoom(id))?,
                    s[2],
                )
            }
        };
        taken.push(pos);
        robots.push(Pose { pos, theta });
    }
    for i in 0..config.opponents {
        let id = format!("o{i}");
        let pos = match &config.placement {
            Placement::Random => pick_random(&taken, id)?,
            Placement::Given {
                opponents: given, ..
            } if !given.is_empty() => {
                let s = given.get(i).ok_or_else(|| SetupError::BadStart {
                    field: "opponent_starts".into(),
                    message: format!(
                        "has {} entries, the match has {} opponents",
                        given.len(),
                        config.opponents
                    ),
                })?;
                let p = Point2::new(s[0], s[1]);
                check_given(arena, &taken, p, format!("opponent_starts[{i}]"))?;
                p
            }
            _ => {
                let s = def.opponent_spawns[i % def.opponent_spawns.len()];
                free_near(arena, &taken, s).ok_or(SetupError::NoRoom(id))?
            }
        };
        taken.push(pos);
        // Face the middle of the arena: a sensible default for a person who just joined.
        let centre = Point2::new(arena.width() / 2.0, arena.height() / 2.0) - pos;
        opponents.push(Pose {
            pos,
            theta: centre.y.atan2(centre.x),
        });
    }
    Ok((robots, opponents))
}

fn check_given(
    arena: &Arena,
    taken: &[Point2<f32>],
    p: Point2<f32>,
    field: String,
) -> Result<(), SetupError> {
    if !(p.x.is_finite() && p.y.is_finite() && arena.disc_is_free(p, AGENT_RADIUS)) {
        return Err(SetupError::BadStart {
            field,
            message: format!("[{}, {}] is not free space for an agent", p.x, p.y),
        });
    }
    if taken.iter().any(|t| (t - p).norm() < 2.0 * AGENT_RADIUS) {
        return Err(SetupError::BadStart {
            field,
            message: format!("[{}, {}] overlaps another agent", p.x, p.y),
        });
    }
    Ok(())
}

/// `want` itself when free of walls and agents, else the nearest passable cell that is.
fn free_near(arena: &Arena, taken: &[Point2<f32>], want: Point2<f32>) -> Option<Point2<f32>> {
    let clear = |p: Point2<f32>| {
        taken
            .iter()
            .all(|t| (t - p).norm() >= 2.0 * AGENT_RADIUS + 0.05)
    };
    if arena.disc_is_free(want, AGENT_RADIUS) && clear(want) {
        return Some(want);
    }
    let g = &arena.grid;
    let mut cells: Vec<(f32, usize)> = (0..g.len())
        .filter(|&c| g.passable(c))
        .map(|c| ((g.centre(c) - want).norm_squared(), c))
        .filter(|(d, _)| *d < 25.0)
        .collect();
    cells.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    cells
        .into_iter()
        .map(|(_, c)| g.centre(c))
        .find(|p| clear(*p))
}

/// Passable cells reachable from the first robot spawn (so random starts can meet).
fn reachable_cells(arena: &Arena) -> Vec<usize> {
    let s = arena.def.robot_spawns[0];
    match crate::nav::DistanceField::from_point(&arena.grid, Point2::new(s[0], s[1])) {
        Some(f) => (0..arena.grid.len()).filter(|&c| f.reachable(c)).collect(),
        None => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::arena::MapDef;

    /// A 12 m × 6 m room with one pillar.
    fn duel() -> Arc<Arena> {
        Arc::new(Arena::new(MapDef {
            name: "duel".into(),
            width: 12.0,
            height: 6.0,
            obstacles: vec![vec![
                Point2::new(5.5, 4.5),
                Point2::new(6.5, 4.5),
                Point2::new(6.5, 5.5),
                Point2::new(5.5, 5.5),
            ]],
            robot_spawns: vec![[1.0, 3.0, 0.0], [1.0, 1.0, 0.0]],
            opponent_spawns: vec![Point2::new(11.0, 5.0), Point2::new(11.0, 1.0)],
            landmarks: vec![],
        }))
    }

    fn config(planner: PlannerKind, control: ControlKind) -> MatchConfig {
        MatchConfig {
            robots: 1,
            opponents: 1,
            opponent_control: control,
            planner,
            ..MatchConfig::default()
        }
    }

    #[test]
    fn agents_start_at_spawns_in_order_wrapping_and_never_overlap() {
        let cfg = MatchConfig {
            robots: 3,
            opponents: 3,
            ..config(PlannerKind::Idle, ControlKind::Api)
        };
        let w = World::new(duel(), cfg).unwrap();
        assert_eq!(w.robots[0].pose.pos, Point2::new(1.0, 3.0));
        assert_eq!(w.robots[1].pose.pos, Point2::new(1.0, 1.0));
        assert_eq!(w.opponents[1].pose.pos, Point2::new(11.0, 1.0));
        let all: Vec<_> = w.present();
        for (i, a) in all.iter().enumerate() {
            for b in &all[i + 1..] {
                assert!((a.1 - b.1).norm() >= 2.0 * AGENT_RADIUS, "{a:?} {b:?}");
            }
        }
    }

    #[test]
    fn a_robot_tags_an_opponent_that_walks_into_view() {
        let mut w = World::new(duel(), config(PlannerKind::Baseline, ControlKind::Api)).unwrap();
        w.order_opponent(0, OpponentOrder::Waypoints(vec![Point2::new(4.0, 3.0)]))
            .unwrap();
        for _ in 0..2_000 {
            w.step();
            if w.status == MatchStatus::Finished {
                break;
            }
        }
        assert_eq!(w.winner, Some(Side::Robots));
        assert!(w.events().iter().any(|e| matches!(
            e.kind,
            EventKind::Tag {
                target: AgentId::Opponent(0),
                ..
            }
        )));
    }

    #[test]
    fn an_opponent_freezes_a_robot_in_front_of_it() {
        let mut w = World::new(duel(), config(PlannerKind::Idle, ControlKind::Api)).unwrap();
        w.opponents[0].pose = Pose::new(4.0, 3.0, std::f32::consts::PI);
        w.order_opponent(0, OpponentOrder::Tag).unwrap();
        w.step();
        assert!(w.robot_frozen(0));
        assert!(
            w.events()
                .iter()
                .any(|e| matches!(e.kind, EventKind::RobotTagged { .. }))
        );
        // Cool-down: a second order within 1 s does not fire.
        w.order_opponent(0, OpponentOrder::Tag).unwrap();
        w.step();
        assert!(
            w.robots[0].scan.ranges.is_empty(),
            "from the tick after the hit, a frozen robot does not sense"
        );
        let shots = w
            .events()
            .iter()
            .filter(|e| matches!(e.kind, EventKind::Shot { .. }))
            .count();
        assert_eq!(shots, 1);
        for _ in 0..200 {
            w.step();
        }
        assert!(!w.robot_frozen(0), "frozen for 10 s only");
    }

    #[test]
    fn the_time_limit_ends_the_match_for_the_opponents() {
        let cfg = MatchConfig {
            time_limit_ticks: 40,
            ..config(PlannerKind::Idle, ControlKind::Bot)
        };
        let mut w = World::new(duel(), cfg).unwrap();
        for _ in 0..100 {
            w.step();
        }
        assert_eq!(w.tick, 40);
        assert_eq!(w.winner, Some(Side::Opponents));
    }

    #[test]
    fn orders_are_checked() {
        let mut w = World::new(duel(), config(PlannerKind::Idle, ControlKind::Api)).unwrap();
        assert!(matches!(
            w.order_opponent(0, OpponentOrder::Waypoints(vec![Point2::new(13.0, 1.0)])),
            Err(OrderError::OutsideArena { .. })
        ));
        assert!(matches!(
            w.order_opponent(3, OpponentOrder::Stop),
            Err(OrderError::UnknownOpponent(_))
        ));
        let mut b = World::new(duel(), config(PlannerKind::Idle, ControlKind::Bot)).unwrap();
        assert!(matches!(
            b.order_opponent(0, OpponentOrder::Stop),
            Err(OrderError::NotApiControlled(_))
        ));
    }

    #[test]
    fn random_placement_is_seeded_and_free() {
        let cfg = |seed| MatchConfig {
            placement: Placement::Random,
            seed,
            robots: 2,
            opponents: 2,
            ..config(PlannerKind::Idle, ControlKind::Bot)
        };
        let a = World::new(duel(), cfg(5)).unwrap();
        let b = World::new(duel(), cfg(5)).unwrap();
        let c = World::new(duel(), cfg(6)).unwrap();
        assert_eq!(a.digest(), b.digest());
        assert_ne!(a.digest(), c.digest());
        for r in &a.robots {
            assert!(a.arena.disc_is_free(r.pose.pos, AGENT_RADIUS));
        }
    }

    #[test]
    fn an_evading_bot_runs_from_a_robot_it_sees() {
        let cfg = MatchConfig {
            opponent_bot: BotKind::Evade,
            opponent_control: ControlKind::Bot,
            placement: Placement::Given {
                robots: vec![[3.0, 2.0, 0.0]],
                opponents: vec![[5.0, 2.0]],
            },
            ..config(PlannerKind::Idle, ControlKind::Bot)
        };
        let mut w = World::new(duel(), cfg).unwrap();
        for _ in 0..200 {
            w.step();
        }
        let robot = w.robots[0].pose.pos;
        let bot = w.opponents[0].pose.pos;
        let hidden = !w.arena.line_of_sight(robot, bot);
        assert!(
            (bot - robot).norm() > 5.0 || hidden,
            "the bot fled: {bot:?}"
        );
    }

    #[test]
    fn a_wandering_bot_keeps_moving_and_stays_in_free_space() {
        let cfg = MatchConfig {
            time_limit_ticks: 100_000,
            ..config(PlannerKind::Idle, ControlKind::Bot)
        };
        let mut w = World::new(duel(), cfg).unwrap();
        let mut visited = Vec::new();
        for t in 0..2_000 {
            w.step();
            let p = w.opponents[0].pose.pos;
            assert!(
                w.arena.disc_is_free(p, AGENT_RADIUS - 1e-3),
                "tick {t}: {p:?}"
            );
            if t % 200 == 0 {
                visited.push(p);
            }
        }
        let spread = visited
            .iter()
            .map(|p| (p - visited[0]).norm())
            .fold(0.0, f32::max);
        assert!(spread > 3.0, "wandered about: {visited:?}");
    }

    /// Regression (review of the tracker): a robot that tags an opponent in the same tick as
    /// it is itself frozen still reports the hit, so the role counts keep adding up.
    #[test]
    fn a_hit_by_a_robot_frozen_in_the_same_tick_still_counts() {
        let cfg = MatchConfig {
            opponents: 2,
            placement: Placement::Given {
                robots: vec![[3.0, 3.0, 0.0]],
                opponents: vec![[6.0, 3.0], [1.0, 3.0]],
            },
            ..config(PlannerKind::Baseline, ControlKind::Api)
        };
        let mut w = World::new(duel(), cfg).unwrap();
        // o1 stands behind the robot; turn it to face the robot.
        w.opponents[1].pose.theta = 0.0;
        assert!(
            w.robots[0].command.tag,
            "the robot sees o0 dead ahead and fires"
        );
        w.order_opponent(1, OpponentOrder::Tag).unwrap();
        w.step();
        assert!(w.opponents[0].tagged, "o0 was hit");
        assert!(
            w.robot_frozen(0),
            "and the robot was frozen in the same tick"
        );
        assert_eq!(w.team.trackers[0].untagged_count(), 1);
    }
}
