//! The research environment's episodes as flat arrays: a match whose robots are driven by
//! a policy's actions (`PlannerKind::Api`), each robot's observation packed into a fixed
//! vector of `f32`, the step's rewards and how the episode ends.
//!
//! This is the arithmetic of the Python package's environments (`python/lasertag_env`,
//! docs/research.md), done where the match runs so that an in-process engine steps without
//! building a Python object per value. The HTTP backend builds the same vectors in Python
//! from the server's JSON; both must agree bit for bit (a test compares whole episodes by
//! digest), so every number here goes through the same roundings the JSON does (a
//! millimetre, a ten-thousandth of a radian, `f64` arithmetic, then `f32`) and the same
//! operations in the same order.
//!
//! [`engine`] is the in-process engine itself: the checked vector of episodes the Python
//! module drives.

pub mod engine;

use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::nav::ReachCache;
use crate::planner::RobotCommand;
use crate::sim::arena::Arena;
use crate::sim::{AgentId, Motion, TICK_HZ};
use crate::tracker::features;
use crate::world::{
    EventKind, FinishReason, MatchConfig, MatchStatus, RobotObservation, RobotOrder, SetupError,
    Side, World, WorldInput,
};

/// Values of one robot's action: forward, turn, tag.
pub const ACTION_SIZE: usize = 3;
/// Ticks since a teammate's report are divided by this (and saturate at 1).
const AGE_SCALE: f64 = 100.0;
/// Values of one teammate's slot: present, x, y, cos, sin, age, goal present, goal x, goal y.
pub const TEAMMATE_VALUES: usize = 9;

/// A length rounded to the millimetre, as the API writes lengths.
pub fn mm(v: f32) -> f64 {
    ((v as f64) * 1000.0).round() / 1000.0
}

/// An angle rounded to a ten-thousandth of a radian, as the API writes angles.
pub fn rad(v: f32) -> f64 {
    ((v as f64) * 10_000.0).round() / 10_000.0
}

/// The observation vector's parts, in order: scan, pose, spread, status, time, detections,
/// teammates, belief grid, belief paths, roles, untagged share (their meaning is
/// python/lasertag_env/observation.py's table).
#[derive(Debug, Clone)]
pub struct Layout {
    beams: usize,
    /// Metres, as the rules publish it.
    laser_range: f64,
    half_fov: f64,
    /// The divisor of a scan in millimetres.
    mm_range: f32,
    robots: usize,
    detections: usize,
    /// The map's size as given (not its `f32` copy): positions are divided by these.
    width: f64,
    height: f64,
    low: Vec<f32>,
    high: Vec<f32>,
}

impl Layout {
    /// `laser_range` and `fov_deg` as the rules publish them (`GET /api/rules`).
    pub fn new(
        robots: usize,
        detections: usize,
        width: f64,
        height: f64,
        beams: usize,
        laser_range: f64,
        fov_deg: f64,
    ) -> Layout {
        let mut low = Vec::new();
        let mut high = Vec::new();
        let mut part = |n: usize, lo: f32, hi: f32| {
            low.extend(std::iter::repeat_n(lo, n));
            high.extend(std::iter::repeat_n(hi, n));
        };
        part(beams, 0.0, 1.0);
        // Position fractions are in [0, 1]; only the heading's cos and sin are signed.
        part(2, 0.0, 1.0);
        part(2, -1.0, 1.0);
        part(1, 0.0, 1.0); // spread
        part(2, 0.0, 1.0); // status
        part(1, 0.0, 1.0); // time
        for _ in 0..detections {
            part(2, 0.0, 1.0); // present, range
            part(1, -1.0, 1.0); // bearing
        }
        for _ in 1..robots {
            part(3, 0.0, 1.0); // present, x, y
            part(2, -1.0, 1.0); // cos, sin
            part(4, 0.0, 1.0); // age, goal present, goal x, goal y
        }
        part(features::GRID_CELLS, 0.0, 1.0);
        part(features::SECTORS, 0.0, 1.0); // the way to the belief
        for _ in 0..features::ROLE_SLOTS {
            part(2, 0.0, 1.0); // present, count share
            part(2, -1.0, 1.0); // ahead, left
            part(3, 0.0, 1.0); // spread, confidence, looked at in vain
        }
        part(1, 0.0, 1.0); // untagged share
        Layout {
            beams,
            laser_range,
            half_fov: fov_deg.to_radians() / 2.0,
            mm_range: (1000.0 * laser_range) as f32,
            robots,
            detections,
            width,
            height,
            low,
            high,
        }
    }

    /// Values in one robot's vector.
    pub fn size(&self) -> usize {
        self.low.len()
    }

    /// The vector's lower bounds.
    pub fn low(&self) -> &[f32] {
        &self.low
    }

    /// The vector's upper bounds.
    pub fn high(&self) -> &[f32] {
        &self.high
    }

    /// Robot `robot`'s vector from its observation into `out` (`size()` values).
    pub fn encode(&self, o: &RobotObservation, robot: usize, time_fraction: f64, out: &mut [f32]) {
        let (scan, tail) = out.split_at_mut(self.beams);
        if o.scan.len() == self.beams {
            for (v, r) in scan.iter_mut().zip(o.scan) {
                // The packed scan's millimetres (rounded half away from zero, saturating as
                // a u16 does) over the reach in millimetres, in f32: what the HTTP backend's
                // numpy division gives. An f32 times 1000 is exact in f64, so adding a half
                // and truncating is that rounding, without a call to `round`.
                let millimetres = ((*r as f64) * 1000.0 + 0.5) as u16;
                *v = millimetres as f32 / self.mm_range;
            }
        } else {
            // A frozen robot senses nothing.
            scan.fill(0.0);
        }
        let mut at = 0;
        let mut put = |v: f64| {
            tail[at] = v as f32;
            at += 1;
        };
        let theta = rad(o.estimate.theta);
        put(mm(o.estimate.pos.x) / self.width);
        put(mm(o.estimate.pos.y) / self.height);
        put(theta.cos());
        put(theta.sin());
        put(mm(o.spread));
        put(if o.tag_ready { 1.0 } else { 0.0 });
        put(if o.frozen { 1.0 } else { 0.0 });
        put(time_fraction);
        let mut sightings: Vec<(f64, f64)> = o
            .detections
            .iter()
            .map(|d| (mm(d.range), rad(d.bearing)))
            .collect();
        // Nearest first; a stable sort, as Python's `sorted`.
        sightings.sort_by(|a, b| a.0.total_cmp(&b.0));
        for k in 0..self.detections {
            match sightings.get(k) {
                Some(&(range, bearing)) => {
                    put(1.0);
                    put(range / self.laser_range);
                    put(bearing / self.half_fov);
                }
                None => (0..3).for_each(|_| put(0.0)),
            }
        }
        let mates_at = self.beams + at;
        let width = TEAMMATE_VALUES * self.robots.saturating_sub(1);
        let (mates, belief) = out[mates_at..].split_at_mut(width);
        mates.fill(0.0);
        for m in &o.teammates {
            if m.robot == robot || m.robot >= self.robots {
                continue;
            }
            let slot = if m.robot < robot {
                m.robot
            } else {
                m.robot - 1
            };
            let th = rad(m.pose.theta);
            let (has_goal, gx, gy) = match m.goal {
                Some(g) => (1.0, mm(g.x) / self.width, mm(g.y) / self.height),
                None => (0.0, 0.0, 0.0),
            };
            let values = [
                1.0,
                mm(m.pose.pos.x) / self.width,
                mm(m.pose.pos.y) / self.height,
                th.cos(),
                th.sin(),
                m.age_ticks as f64 / AGE_SCALE,
                has_goal,
                gx,
                gy,
            ];
            let at = TEAMMATE_VALUES * slot;
            for (v, x) in mates[at..at + TEAMMATE_VALUES].iter_mut().zip(values) {
                *v = x as f32;
            }
        }
        for (v, x) in belief.iter_mut().zip(o.belief.values()) {
            *v = x as f32;
        }
        // Estimates a little outside the arena, a spread past 1 m, ages past 100 ticks and
        // rounding at the edges land inside the bounds (NaN stays NaN, as numpy's).
        for ((v, lo), hi) in out.iter_mut().zip(&self.low).zip(&self.high) {
            if *v < *lo {
                *v = *lo;
            } else if *v > *hi {
                *v = *hi;
            }
        }
    }
}

/// Reward weights (python/lasertag_env/parallel.py's `DEFAULT_REWARDS`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rewards {
    /// Each tag the robot makes.
    pub tag: f64,
    /// Each tag any robot of the team makes, to every robot.
    pub team_tag: f64,
    /// Per simulated tick.
    pub tick: f64,
}

impl Default for Rewards {
    fn default() -> Self {
        Rewards {
            tag: 1.0,
            team_tag: 0.0,
            tick: -0.001,
        }
    }
}

/// What every episode of an environment shares.
#[derive(Debug, Clone)]
pub struct EnvSpec {
    /// The match's settings; its `seed` is each episode's own and its planner is `Api`.
    pub config: MatchConfig,
    pub layout: Layout,
    pub rewards: Rewards,
    /// Steps before truncation (`None`: only the match's time limit).
    pub max_steps: Option<u64>,
    pub ticks_per_step: u64,
}

/// How a step left the episode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    pub tick: u64,
    /// The robots won (every opponent tagged).
    pub terminated: bool,
    /// The episode ended otherwise: time limit, steps, or a loss.
    pub truncated: bool,
    pub winner: Option<Side>,
    pub reason: Option<FinishReason>,
}

/// One episode: a match and its step count.
#[derive(Debug)]
pub struct Episode {
    world: World,
    steps: u64,
    /// Tags each robot made in the last step.
    tags: Vec<u32>,
    /// The match's time limit in ticks, as the HTTP backend computes it from the summary.
    limit_ticks: f64,
    /// Each robot's kept searches for its belief features (asked every step).
    reach: Vec<ReachCache>,
}

impl Episode {
    /// A fresh match with `seed` on `arena`.
    pub fn new(arena: Arc<Arena>, spec: &EnvSpec, seed: u64) -> Result<Episode, SetupError> {
        let config = MatchConfig {
            seed,
            ..spec.config.clone()
        };
        let limit_s = config.time_limit_ticks as f64 / TICK_HZ as f64;
        let world = World::new(arena, config)?;
        Ok(Episode {
            tags: vec![0; world.robots.len()],
            reach: vec![ReachCache::default(); world.robots.len()],
            world,
            steps: 0,
            limit_ticks: (limit_s * TICK_HZ as f64).max(1.0),
        })
    }

    pub fn world(&self) -> &World {
        &self.world
    }

    /// Tags each robot made in the last step.
    pub fn tags(&self) -> &[u32] {
        &self.tags
    }

    /// Every robot's vector into `out` (robots × `layout.size()`), as after a reset.
    pub fn observe_start(&mut self, spec: &EnvSpec, out: &mut [f32]) {
        self.observe(spec, 0.0, out);
    }

    /// Every robot's vector into `out` (robots × `layout.size()`).
    pub fn observe(&mut self, spec: &EnvSpec, time_fraction: f64, out: &mut [f32]) {
        let size = spec.layout.size();
        for ((i, row), reach) in out
            .chunks_exact_mut(size)
            .enumerate()
            .zip(self.reach.iter_mut())
        {
            if let Some(o) = self.world.observation_with(i, reach) {
                spec.layout.encode(&o, i, time_fraction, row);
            }
        }
    }

    /// Applies each robot's action (`ACTION_SIZE` values: forward and turn as fractions,
    /// clipped to [-1, 1] with NaN as 0, and tag above 0.5), runs the step's ticks and
    /// writes every robot's vector and reward.
    pub fn step(
        &mut self,
        spec: &EnvSpec,
        actions: &[f32],
        obs: &mut [f32],
        rewards: &mut [f64],
    ) -> Outcome {
        self.step_with(spec, actions, obs, rewards, &mut |_| {})
    }

    /// [`Episode::step`] with `before_tick` called on the world before each of the step's
    /// ticks (see [`Episode::advance_with`]).
    pub fn step_with(
        &mut self,
        spec: &EnvSpec,
        actions: &[f32],
        obs: &mut [f32],
        rewards: &mut [f64],
        before_tick: &mut dyn FnMut(&mut World),
    ) -> Outcome {
        let (outcome, time_fraction) = self.advance_with(spec, actions, rewards, before_tick);
        self.observe(spec, time_fraction, obs);
        outcome
    }

    /// The first part of [`Episode::step`] (public to time the parts apart): the actions
    /// applied, the ticks run and the rewards written. Returns the outcome and the
    /// episode's time fraction, which [`Episode::observe`] puts in the vectors.
    pub fn advance(
        &mut self,
        spec: &EnvSpec,
        actions: &[f32],
        rewards: &mut [f64],
    ) -> (Outcome, f64) {
        self.advance_with(spec, actions, rewards, &mut |_| {})
    }

    /// [`Episode::advance`] with `before_tick` called on the world before each of the
    /// step's ticks, after the actions went in: where a shell gives the robots it drives
    /// itself their orders as inputs (a trained policy's, `planner="policy:<name>"`, which
    /// the core does not run). Such a shell passes no actions (an empty slice): a row would
    /// replace the order its robot holds between two of the policy's decisions.
    pub fn advance_with(
        &mut self,
        spec: &EnvSpec,
        actions: &[f32],
        rewards: &mut [f64],
        before_tick: &mut dyn FnMut(&mut World),
    ) -> (Outcome, f64) {
        let inputs: Vec<WorldInput> = actions
            .chunks_exact(ACTION_SIZE)
            .take(self.world.robots.len())
            .enumerate()
            // A team's planned robots (a mixed team, or a built-in planner measured in the
            // harness) ignore their rows: only robots driven from outside take orders.
            .filter(|(robot, _)| self.world.robot_outside(*robot))
            .map(|(robot, a)| WorldInput::Robot {
                robot,
                order: drive_order(a),
            })
            .collect();
        // Drive orders within [-1, 1] to robots the match has are always taken.
        let _ = self.world.apply_all(&inputs);
        let since = self.world.events().len() as u64;
        let start = self.world.tick;
        for _ in 0..spec.ticks_per_step {
            before_tick(&mut self.world);
            if !self.world.step() || self.world.status == MatchStatus::Finished {
                break;
            }
        }
        self.steps += 1;
        let ticks = self.world.tick - start;
        let base = spec.rewards.tick * ticks as f64;
        rewards.fill(base);
        self.tags.fill(0);
        let mut reason = None;
        for e in self.world.events_since(since) {
            match e.kind {
                EventKind::Tag { by, .. } => {
                    if let AgentId::Robot(r) = by
                        && r < rewards.len()
                    {
                        self.tags[r] += 1;
                        rewards[r] += spec.rewards.tag;
                    }
                    if spec.rewards.team_tag != 0.0 {
                        rewards.iter_mut().for_each(|v| *v += spec.rewards.team_tag);
                    }
                }
                EventKind::Finished { reason: r, .. } => reason = Some(r),
                _ => {}
            }
        }
        let finished = self.world.status == MatchStatus::Finished;
        let won = finished && self.world.winner == Some(Side::Robots);
        let out_of_steps = spec.max_steps.is_some_and(|m| self.steps >= m);
        let truncated = !won && (finished || out_of_steps);
        let time_fraction = match spec.max_steps {
            None => (self.world.tick as f64 / self.limit_ticks).min(1.0),
            Some(m) => (self.steps as f64 / m as f64).min(1.0),
        };
        let outcome = Outcome {
            tick: self.world.tick,
            terminated: won,
            truncated,
            winner: if finished { self.world.winner } else { None },
            reason,
        };
        (outcome, time_fraction)
    }
}

/// The order one robot's action gives (`ACTION_SIZE` values: forward and turn as fractions,
/// clipped to [-1, 1] with NaN as 0, and tag above 0.5): the environments' and a served
/// policy's one reading of an action.
pub fn drive_order(action: &[f32]) -> RobotOrder {
    let at = |i: usize| action.get(i).copied().unwrap_or(0.0);
    RobotOrder::Drive {
        forward: clip(at(0)),
        turn: clip(at(1)),
        tag: at(2) > 0.5,
    }
}

/// The action that gives what `command` did, as [`drive_order`] reads one: a planner's
/// decision in a policy's terms, the label behaviour cloning learns from. A robot's motion
/// is a differential drive; anything else (`Stop`, and `Toward`, which only bots walk)
/// stands.
pub fn command_action(command: &RobotCommand) -> [f32; ACTION_SIZE] {
    let (forward, turn) = match command.motion {
        Motion::Drive { forward, turn } => (clip(forward), clip(turn)),
        Motion::Stop | Motion::Toward(_) => (0.0, 0.0),
    };
    [forward, turn, if command.tag { 1.0 } else { 0.0 }]
}

/// An action's fraction: clipped to [-1, 1], NaN as 0 (what the HTTP backend sends).
fn clip(v: f32) -> f32 {
    if (-1.0..=1.0).contains(&v) {
        v
    } else if v > 1.0 {
        1.0
    } else if v < -1.0 {
        -1.0
    } else {
        0.0
    }
}

/// The seeds of one world's episodes in a vector of environments: the first is `base +
/// index`, later ones are drawn from a stream seeded by it, so every world's sequence is
/// reproducible and independent of the others'.
#[derive(Debug, Clone)]
pub struct EpisodeSeeds {
    next: u64,
    stream: ChaCha8Rng,
}

impl EpisodeSeeds {
    pub fn new(base: u64, index: u64) -> EpisodeSeeds {
        let first = base.wrapping_add(index) & (u64::MAX >> 1);
        EpisodeSeeds {
            next: first,
            stream: ChaCha8Rng::seed_from_u64(first),
        }
    }

    /// The next episode's seed, in 0..2^63 (the API's range for seeds people give).
    pub fn draw(&mut self) -> u64 {
        let seed = self.next;
        self.next = self.stream.next_u64() >> 1;
        seed
    }
}

#[cfg(test)]
mod tests;
