//! One match: the tick pipeline over plain data.
//!
//! [`World::step`] runs, in order:
//! 1. inputs — opponents' motions (bots decide now; API routes; people's latest keys) and the
//!    robots' commands decided at the end of the previous tick (or, for robots driven from
//!    outside, their last orders);
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
//!
//! Long file: the six stages of a tick read best in one place, in their order.

use std::collections::VecDeque;
use std::sync::Arc;

use nalgebra::Point2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::bots::{Bot, BotKind};
use crate::checkpoint::{CheckpointError, Plain, Restore};
use crate::localise::dead_reckoning::DeadReckoning;
use crate::localise::{LikelihoodField, Localiser, Observation};
use crate::planner::{PlannerKind, RobotCommand, RobotView, Team, TeamView};
use crate::sim::arena::Arena;
use crate::sim::sensors::{self, Detection, LandmarkSighting, Scan};
use crate::sim::{AGENT_RADIUS, AgentId, Motion, Physics, Pose, TICK_HZ, motion, rules};
use crate::tracker::{Tracker, TrackerEvent};

mod agents;
mod config;
mod digest;
mod events;
mod inputs;
mod placement;
mod robot_api;

pub use agents::*;
pub use config::*;
pub use events::*;
pub use inputs::*;
use placement::*;
pub use robot_api::*;

/// A match could not be set up as asked.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SetupError {
    #[error("{0}: no free place for this agent")]
    NoRoom(String),
    #[error("{field}: {message}")]
    BadStart { field: String, message: String },
}

/// Where every agent stood at the end of one tick.
#[derive(Debug, Clone)]
struct Trail {
    tick: u64,
    robots: Vec<Point2<f32>>,
    opponents: Vec<Point2<f32>>,
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
    /// Every agent's position at the end of each of the last ticks (oldest first), to judge
    /// a person's shot where their screen showed the other side (lag compensation).
    trail: std::collections::VecDeque<Trail>,
    /// The robots' laser fan, shaped once from `config.physics` for every scan.
    laser: sensors::Laser,
    rng_sense: ChaCha8Rng,
    rng_bots: ChaCha8Rng,
    rng_odometry: ChaCha8Rng,
    rng_localise: ChaCha8Rng,
    /// The path-search work robots' orders may take (`set_route_budget`), and what is left
    /// of it: limits of the shell, no part of the match.
    route_budget: u64,
    route_work: u64,
}

/// How far back a person's shot may be judged (500 ms at 20 Hz): what a player 300 ms away
/// has behind the robots they see (the round trip, the page's drawing delay and the wait for
/// the next input tick), short enough that a robot is not tagged long after it left cover.
/// Valve's Source engine allows a second.
pub const MAX_REWIND_TICKS: u64 = 10;

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
                api: ApiDrive::default(),
                aim_tick: None,
                seated: false,
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
                bench: None,
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
            trail: Default::default(),
            laser: sensors::Laser::new(&config.physics),
            rng_sense: stream(config.seed, STREAM_SENSE),
            rng_bots: stream(config.seed, STREAM_BOTS),
            rng_odometry: stream(config.seed, STREAM_ODOMETRY),
            rng_localise,
            route_budget: u64::MAX,
            route_work: u64::MAX,
            arena,
            config,
        };
        // Robots see the world before their first decision.
        world.sense();
        world.localise();
        world.think(&mut |_| {});
        Ok(world)
    }

    /// Its state as a checkpoint: what [`World::restored`] brings back (see
    /// [`crate::checkpoint`]).
    pub fn checkpoint(&self) -> Vec<u8> {
        let mut w = crate::checkpoint::Writer::new();
        Restore::save(self, &mut w);
        w.into_bytes()
    }

    /// The match `checkpoint` was taken of, from `self`: a fresh [`World::new`] on the map
    /// and settings that match had (they build what the checkpoint leaves out). On an
    /// error the half-restored world is dropped; build a fresh one to try anything else.
    pub fn restored(mut self, checkpoint: &[u8]) -> Result<World, CheckpointError> {
        let mut r = crate::checkpoint::Reader::new(checkpoint)?;
        Restore::restore(&mut self, &mut r)?;
        r.finish()?;
        Ok(self)
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

    /// Where the untagged opponents are: the truth a belief about them is measured against.
    pub fn untagged_opponents(&self) -> Vec<Point2<f32>> {
        self.opponents
            .iter()
            .filter(|o| !o.tagged)
            .map(|o| o.pose.pos)
            .collect()
    }

    /// Advances the match by one tick (see the module docs for the stages): true when it
    /// did. A finished match stays as it is and answers false, so a loop that steps until
    /// a tick stops on it rather than spinning (`while world.tick < n && world.step() {}`).
    pub fn step(&mut self) -> bool {
        self.step_marked(&mut |_| {})
    }

    /// [`World::step`], calling `mark` at the [`StepMark`]s of the team stage (not at all in
    /// a tick that ends the match before it). The match is the same whatever `mark` does.
    /// True when the match advanced (it had not finished).
    pub fn step_marked(&mut self, mark: &mut dyn FnMut(StepMark)) -> bool {
        if self.status == MatchStatus::Finished {
            return false;
        }
        self.tick += 1;
        let motions = self.inputs();
        self.move_agents(&motions);
        self.sense();
        self.localise();
        self.rules();
        self.think(mark);
        self.keep_trail();
        true
    }

    /// Notes where every agent ended this tick, keeping [`MAX_REWIND_TICKS`] of them.
    fn keep_trail(&mut self) {
        if self.trail.len() as u64 >= MAX_REWIND_TICKS {
            self.trail.pop_front();
        }
        self.trail.push_back(Trail {
            tick: self.tick,
            robots: self.robots.iter().map(|r| r.pose.pos).collect(),
            opponents: self.opponents.iter().map(|o| o.pose.pos).collect(),
        });
    }

    /// Where the robots were at the end of tick `seen`, if it is one of the last
    /// [`MAX_REWIND_TICKS`] before this one.
    fn trail_at(&self, seen: u64) -> Option<&Trail> {
        self.trail.iter().find(|t| t.tick == seen)
    }

    /// Stage 1: this tick's motion of every agent (robots first, then opponents).
    pub fn inputs(&mut self) -> Vec<Motion> {
        if self.any_robot_outside() {
            self.drive_api_robots();
        }
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
                &self.laser,
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
        // With a person's shot, the tick its screen showed (for lag compensation).
        let mut shooters: Vec<(AgentId, Option<u64>)> = Vec::new();
        for (i, r) in self.robots.iter().enumerate() {
            if r.command.tag && !self.robot_frozen(i) && tick >= r.cooldown_until {
                // A person's robot (a pursuer slot) aims where their screen showed.
                shooters.push((AgentId::Robot(i), r.aim_tick));
            }
        }
        for (i, o) in self.opponents.iter_mut().enumerate() {
            let (wants, seen) = match &mut o.control {
                Control::Api(route) => (std::mem::take(&mut route.fire), None),
                Control::Human(input) => (input.tag, input.seen_tick),
                Control::Bot(_) => (false, None),
            };
            if wants && !o.tagged && tick >= o.cooldown_until {
                shooters.push((AgentId::Opponent(i), seen));
            }
        }
        for (shooter, seen) in shooters {
            // An opponent eliminated earlier this tick no longer fires.
            let (pose, alive) = match shooter {
                AgentId::Robot(i) => (self.robots[i].pose, !self.robot_frozen(i)),
                AgentId::Opponent(i) => (self.opponents[i].pose, !self.opponents[i].tagged),
            };
            if !alive {
                continue;
            }
            let mut others: Vec<_> = self
                .present()
                .into_iter()
                .filter(|(id, _)| *id != shooter)
                .collect();
            // A person aimed at the other side where their screen showed it: judge the
            // shot there, at most MAX_REWIND_TICKS back (an older view is judged at the
            // bound, as Source clamps to its limit). Everything else (walls, their own side,
            // who is frozen or tagged) is as it is now.
            if let Some(past) = seen
                .filter(|s| *s < tick)
                .map(|s| s.max(tick.saturating_sub(MAX_REWIND_TICKS)))
                .and_then(|s| self.trail_at(s))
            {
                for (id, at) in &mut others {
                    let then = match (shooter, *id) {
                        (AgentId::Opponent(_), AgentId::Robot(r)) => past.robots.get(r),
                        (AgentId::Robot(_), AgentId::Opponent(o)) => past.opponents.get(o),
                        _ => None,
                    };
                    if let Some(p) = then {
                        *at = *p;
                    }
                }
            }
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
            self.end(FinishReason::AllTagged);
        } else if tick >= self.config.time_limit_ticks {
            self.end(FinishReason::TimeLimit);
        }
    }

    /// Ends the match for `reason` (the one way a match ends, by the rules or from
    /// outside), its winner following from the reason; a finished match is left as it is.
    pub fn end(&mut self, reason: FinishReason) {
        if self.status == MatchStatus::Finished {
            return;
        }
        let winner = reason.winner();
        self.status = MatchStatus::Finished;
        self.winner = winner;
        self.push(EventKind::Finished { winner, reason });
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
                    outside: self.robot_outside(i),
                })
                .collect(),
        };
        mark(StepMark::Tracker);
        let tracker_events = self.team.track(&self.arena, &self.config.physics, &view);
        mark(StepMark::Planner);
        let commands = self.team.plan(&self.arena, &self.config.physics, &view);
        mark(StepMark::Planned);
        let outside: Vec<bool> = view.robots.iter().map(|r| r.outside).collect();
        // A robot driven from outside keeps the command its order gave (see `inputs`).
        for ((r, c), outside) in self.robots.iter_mut().zip(commands).zip(outside) {
            if !outside {
                r.command = c;
            }
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
        let name = AgentId::Opponent(index).to_string();
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

    pub fn log_player(&mut self, agent: AgentId, name: String, joined: bool) {
        self.push(if joined {
            EventKind::PlayerJoined { agent, name }
        } else {
            EventKind::PlayerLeft { agent, name }
        });
    }
}

crate::checkpoint::plain_struct!(Trail {
    tick,
    robots,
    opponents
});
crate::checkpoint::restore_struct!(World {
    plain: [
        tick,
        status,
        winner,
        opponents,
        events,
        trail,
        rng_sense,
        rng_bots,
        rng_odometry,
        rng_localise,
        route_budget,
        route_work,
    ],
    nested: [robots, team],
    derived: [arena, config, laser],
});

#[cfg(test)]
mod checkpoint_tests;
#[cfg(test)]
mod tests;
