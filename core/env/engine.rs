//! The in-process research engine without Python: every check of its constructor's
//! arguments and of its calls' arrays, and the vector of worlds those arguments build and
//! step.
//!
//! `native/` (the Python module `lasertag_env._native`) is a shell over this module: it
//! turns Python values into these types, runs [`Engine::step_all`]'s worlds on rayon's
//! threads with the GIL released, and turns a [`Refusal`] into a Python exception. What a
//! caller can influence is checked here rather than in the shell because a pyo3 extension
//! module links against the interpreter that loads it: neither a test binary nor a fuzz
//! target can link `native/`. Here, `cargo test` and the fuzz target
//! `fuzz/fuzz_targets/native_engine.rs` (both through [`exercise`]) run the very checks and
//! steps the Python module runs, without an interpreter.
//!
//! Every count is checked against its bound (the constants below, docs/research.md's
//! "Bounds") before anything is allocated for it; every float for finiteness (a range's
//! `contains`, which NaN never passes, where `x < lo || x > hi` would let it through); and
//! every array for its length. No argument makes the engine panic or abort.

mod bounds;
pub mod exercise;

use std::sync::Arc;

use super::{ACTION_SIZE, EnvSpec, Episode, EpisodeSeeds, Layout, Outcome, Rewards};
use crate::sim::TICK_HZ;
use crate::sim::arena::{Arena, MapDef};
use crate::sim::map_rules::{self, MapSpec};
use crate::world::{MatchConfig, Placement, World};

pub use bounds::*;

/// What an engine is built from, as its caller gives it; [`EngineArgs::check`] checks it.
#[derive(Debug, Clone)]
pub struct EngineArgs {
    pub map: MapSpec,
    /// The match of every world; its seed is each episode's own.
    pub config: MatchConfig,
    pub worlds: usize,
    /// World `w`'s first episode has seed `seed + w`.
    pub seed: u64,
    pub max_steps: Option<u64>,
    pub ticks_per_step: u64,
    pub rewards: Rewards,
    /// Detection slots in a robot's vector.
    pub detections: usize,
    /// The laser as the rules publish it (`GET /api/rules`): beams, reach in metres and
    /// field of view in degrees. They must be the match's own laser's.
    pub beams: usize,
    pub laser_range: f64,
    pub fov_deg: f64,
}

/// Arguments that passed every check, with the map's definition and the episodes' spec:
/// what [`Engine::build`] allocates the worlds from.
#[derive(Debug, Clone)]
pub struct Checked {
    def: MapDef,
    spec: EnvSpec,
    worlds: usize,
    seed: u64,
}

impl Checked {
    pub fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    pub fn worlds(&self) -> usize {
        self.worlds
    }

    pub fn map(&self) -> &MapDef {
        &self.def
    }
}

/// `n` within `lo..=hi`, or the refusal naming `field`.
fn count(field: &str, n: u64, lo: u64, hi: u64) -> Result<(), Refusal> {
    if (lo..=hi).contains(&n) {
        Ok(())
    } else {
        Err(refuse(field, format!("{n} must be in {lo}..={hi}")))
    }
}

fn finite(field: &str, x: f64) -> Result<(), Refusal> {
    if x.is_finite() {
        Ok(())
    } else {
        Err(refuse(field, format!("{x} must be finite")))
    }
}

fn check_starts<const N: usize>(
    field: &str,
    starts: &[[f32; N]],
    most: usize,
) -> Result<(), Refusal> {
    if starts.len() > most {
        return Err(refuse(
            field,
            format!(
                "{} starts for {most} agents: give one per agent",
                starts.len()
            ),
        ));
    }
    for (i, p) in starts.iter().enumerate() {
        if !p
            .iter()
            .all(|v| (-MAX_COORDINATE..=MAX_COORDINATE).contains(v))
        {
            return Err(refuse(
                format!("{field}[{i}]"),
                format!("{p:?} is not a finite point within ±{MAX_COORDINATE}"),
            ));
        }
    }
    Ok(())
}

impl EngineArgs {
    /// Every check, in an order that needs no allocation for a count before its bound has
    /// been checked: the counts, then the floats, then the map's rules, and last the
    /// observation layout (whose size follows robots and detections).
    pub fn check(self) -> Result<Checked, Refusal> {
        let c = &self.config;
        count("robots", c.robots as u64, 1, MAX_ROBOTS as u64)?;
        count("opponents", c.opponents as u64, 1, MAX_OPPONENTS as u64)?;
        count(
            "detections",
            self.detections as u64,
            0,
            MAX_DETECTIONS as u64,
        )?;
        count("worlds", self.worlds as u64, 1, MAX_AGENTS as u64)?;
        if self.worlds * c.robots > MAX_AGENTS {
            return Err(refuse(
                "worlds",
                format!(
                    "{} worlds of {} robots are {} robots, at most {MAX_AGENTS} in one engine",
                    self.worlds,
                    c.robots,
                    self.worlds * c.robots
                ),
            ));
        }
        count("ticks_per_step", self.ticks_per_step, 1, MAX_TICKS_PER_STEP)?;
        if let Some(steps) = self.max_steps
            && !(1..=MAX_STEPS).contains(&steps)
        {
            return Err(refuse(
                "max_steps",
                format!(
                    "{steps} must be in 1..={MAX_STEPS} (a step is at least a tick, and a \
                     match lasts at most that many), or None"
                ),
            ));
        }
        let most_ticks = (MAX_TIME_LIMIT_S * TICK_HZ as f64) as u64;
        if !(1..=most_ticks).contains(&c.time_limit_ticks) {
            return Err(refuse(
                "time_limit_s",
                format!(
                    "{} ticks must be in 1..={most_ticks} (up to {MAX_TIME_LIMIT_S} s)",
                    c.time_limit_ticks
                ),
            ));
        }
        if c.outside_robots.len() > c.robots {
            return Err(refuse(
                "planner",
                format!(
                    "{} planners for {} robots: give one per robot",
                    c.outside_robots.len(),
                    c.robots
                ),
            ));
        }
        if c.pursuer_slots != 0 {
            return Err(refuse(
                "pursuer_slots",
                "the research engine has no seats for people",
            ));
        }
        if let Placement::Given { robots, opponents } = &c.placement {
            check_starts("robot_starts", robots, c.robots)?;
            check_starts("opponent_starts", opponents, c.opponents)?;
        }
        let r = &self.rewards;
        finite("rewards.tag", r.tag)?;
        finite("rewards.team_tag", r.team_tag)?;
        finite("rewards.tick", r.tick)?;
        let laser = &c.physics;
        if self.beams != laser.laser_beams {
            return Err(refuse(
                "beams",
                format!(
                    "{}: the match's laser has {} beams (the rules' laser.beams)",
                    self.beams, laser.laser_beams
                ),
            ));
        }
        // The rules publish the reach and the field of view rounded to a millionth; any
        // other value would scale the vector's scan, detections and bearings wrongly.
        let range = laser.laser_range as f64;
        if !(self.laser_range.is_finite() && (self.laser_range - range).abs() <= 1e-6) {
            return Err(refuse(
                "laser_range",
                format!(
                    "{}: the match's laser reaches {range} m (the rules' laser.range)",
                    self.laser_range
                ),
            ));
        }
        let fov = (laser.laser_fov as f64).to_degrees();
        if !(self.fov_deg.is_finite() && (self.fov_deg - fov).abs() <= 1e-4) {
            return Err(refuse(
                "fov_deg",
                format!(
                    "{}: the match's laser spans {fov:.6}° (the rules' laser.fov_deg)",
                    self.fov_deg
                ),
            ));
        }
        let def = map_rules::validate(&self.map)
            .map_err(|e| refuse(format!("map.{}", e.path), e.message))?;
        let layout = Layout::new(
            c.robots,
            self.detections,
            self.map.width,
            self.map.height,
            self.beams,
            self.laser_range,
            self.fov_deg,
        );
        Ok(Checked {
            def,
            spec: EnvSpec {
                config: self.config,
                layout,
                rewards: self.rewards,
                max_steps: self.max_steps,
                ticks_per_step: self.ticks_per_step,
            },
            worlds: self.worlds,
            seed: self.seed,
        })
    }
}

/// One world of the vector.
#[derive(Debug)]
pub struct Slot {
    pub episode: Episode,
    seeds: EpisodeSeeds,
    /// Its episode's seed.
    pub seed: u64,
    /// Its episode ended on the last step (the next one resets it).
    pub ended: bool,
}

impl Slot {
    /// Its episode (just put in place) begins: `seed` noted, its robots' first vectors
    /// into `obs`.
    fn begin(&mut self, seed: u64, spec: &EnvSpec, obs: &mut [f32]) {
        self.seed = seed;
        self.ended = false;
        self.episode.observe_start(spec, obs);
    }

    /// One step in a vector: its episode's, or its next episode's start when the last step
    /// ended it (its actions ignored, its vectors the new episode's first, its rewards 0).
    /// Returns (terminated, truncated). The arrays are one world's (checked by the caller).
    /// A next episode whose seed places no match is an error, and the slot stays ended: a
    /// later call draws the next seed.
    pub fn step_or_restart(
        &mut self,
        arena: &Arc<Arena>,
        spec: &EnvSpec,
        actions: &[f32],
        obs: &mut [f32],
        rewards: &mut [f64],
    ) -> Result<(bool, bool), RestartFailed> {
        self.step_or_restart_with(arena, spec, actions, obs, rewards, &mut |_| {})
    }

    /// [`Slot::step_or_restart`] with `before_tick` before each tick of an episode's step
    /// ([`Episode::advance_with`]: a shell's own driver, such as a trained policy).
    pub fn step_or_restart_with(
        &mut self,
        arena: &Arc<Arena>,
        spec: &EnvSpec,
        actions: &[f32],
        obs: &mut [f32],
        rewards: &mut [f64],
        before_tick: &mut dyn FnMut(&mut World),
    ) -> Result<(bool, bool), RestartFailed> {
        if self.ended {
            let seed = self.seeds.draw();
            self.episode = Episode::new(arena.clone(), spec, seed)
                .map_err(|error| RestartFailed { seed, error })?;
            self.begin(seed, spec, obs);
            rewards.fill(0.0);
            return Ok((false, false));
        }
        let out: Outcome = self
            .episode
            .step_with(spec, actions, obs, rewards, before_tick);
        self.ended = out.terminated || out.truncated;
        Ok((out.terminated, out.truncated))
    }
}

/// A vector of worlds on one map, driven by a policy's actions.
#[derive(Debug)]
pub struct Engine {
    arena: Arc<Arena>,
    spec: EnvSpec,
    slots: Vec<Slot>,
}

impl Engine {
    /// [`EngineArgs::check`], then [`Engine::build`].
    pub fn new(args: EngineArgs) -> Result<Engine, Refusal> {
        Engine::build(args.check()?)
    }

    /// The arena and every world's first episode.
    pub fn build(checked: Checked) -> Result<Engine, Refusal> {
        let Checked {
            def,
            spec,
            worlds,
            seed,
        } = checked;
        let arena = Arc::new(Arena::new(def));
        let mut slots = Vec::with_capacity(worlds);
        for i in 0..worlds {
            let mut seeds = EpisodeSeeds::new(seed, i as u64);
            let seed = seeds.draw();
            let episode = Episode::new(arena.clone(), &spec, seed)?;
            slots.push(Slot {
                episode,
                seeds,
                seed,
                ended: false,
            });
        }
        Ok(Engine { arena, spec, slots })
    }

    pub fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    pub fn worlds(&self) -> usize {
        self.slots.len()
    }

    pub fn robots(&self) -> usize {
        self.spec.config.robots
    }

    /// Values in one robot's vector.
    pub fn size(&self) -> usize {
        self.spec.layout.size()
    }

    /// Each world's episode seed.
    pub fn seeds(&self) -> Vec<u64> {
        self.slots.iter().map(|s| s.seed).collect()
    }

    pub fn world(&self, world: usize) -> Result<&Slot, Refusal> {
        let worlds = self.slots.len();
        self.slots
            .get(world)
            .ok_or(Refusal::NoWorld { world, worlds })
    }

    pub fn world_mut(&mut self, world: usize) -> Result<&mut Slot, Refusal> {
        let worlds = self.slots.len();
        self.slots
            .get_mut(world)
            .ok_or(Refusal::NoWorld { world, worlds })
    }

    /// The arena, the spec and the worlds, to step them in parallel.
    pub fn parts_mut(&mut self) -> (&Arc<Arena>, &EnvSpec, &mut [Slot]) {
        (&self.arena, &self.spec, &mut self.slots)
    }

    /// Starts world `world` afresh with `seed`; its robots' vectors into `obs` (robots ×
    /// size).
    pub fn reset(&mut self, world: usize, seed: u64, obs: &mut [f32]) -> Result<(), Refusal> {
        check_len("obs", obs.len(), self.robots() * self.size())?;
        self.world(world)?;
        let episode = Episode::new(self.arena.clone(), &self.spec, seed)?;
        let spec = &self.spec;
        let slot = &mut self.slots[world];
        slot.episode = episode;
        slot.begin(seed, spec, obs);
        Ok(())
    }

    /// Every world's next episode, its vectors into `obs` (worlds × robots × size). The
    /// seeds come from each world's stream; `seed` starts the streams over (world `w`'s
    /// first episode then has seed `seed + w`), and `seeds` gives each world's first seed
    /// itself (its later ones come from a stream seeded by it).
    pub fn reset_all(
        &mut self,
        obs: &mut [f32],
        seed: Option<u64>,
        seeds: Option<&[u64]>,
    ) -> Result<(), Refusal> {
        let per_world = self.robots() * self.size();
        check_len("obs", obs.len(), per_world * self.slots.len())?;
        if let Some(seeds) = seeds {
            check_len("seeds", seeds.len(), self.slots.len())?;
        }
        for (i, slot) in self.slots.iter_mut().enumerate() {
            if let Some(seeds) = seeds {
                slot.seeds = EpisodeSeeds::new(seeds[i], 0);
            } else if let Some(base) = seed {
                slot.seeds = EpisodeSeeds::new(base, i as u64);
            }
        }
        for (slot, rows) in self.slots.iter_mut().zip(obs.chunks_exact_mut(per_world)) {
            let seed = slot.seeds.draw();
            slot.episode = Episode::new(self.arena.clone(), &self.spec, seed)?;
            slot.begin(seed, &self.spec, rows);
        }
        Ok(())
    }

    /// One step of world `world`: `actions` (robots × 3) in, vectors into `obs` (robots ×
    /// size) and rewards into `rewards` (robots).
    pub fn step(
        &mut self,
        world: usize,
        actions: &[f32],
        obs: &mut [f32],
        rewards: &mut [f64],
    ) -> Result<Outcome, Refusal> {
        self.check_step(actions.len(), obs.len(), rewards.len())?;
        let spec = &self.spec;
        let worlds = self.slots.len();
        let slot = self
            .slots
            .get_mut(world)
            .ok_or(Refusal::NoWorld { world, worlds })?;
        let out = slot.episode.step(spec, actions, obs, rewards);
        slot.ended = out.terminated || out.truncated;
        Ok(out)
    }

    /// The lengths of one world's step's arrays.
    pub fn check_step(&self, actions: usize, obs: usize, rewards: usize) -> Result<(), Refusal> {
        let robots = self.robots();
        check_len("actions", actions, robots * ACTION_SIZE)?;
        check_len("obs", obs, robots * self.size())?;
        check_len("rewards", rewards, robots)
    }

    /// The lengths of [`Engine::step_all`]'s arrays.
    pub fn check_step_all(
        &self,
        actions: usize,
        obs: usize,
        rewards: usize,
        terminated: usize,
        truncated: usize,
    ) -> Result<(), Refusal> {
        let (worlds, robots) = (self.slots.len(), self.robots());
        check_len("actions", actions, worlds * robots * ACTION_SIZE)?;
        check_len("obs", obs, worlds * robots * self.size())?;
        check_len("rewards", rewards, worlds * robots)?;
        check_len("terminated", terminated, worlds)?;
        check_len("truncated", truncated, worlds)
    }

    /// One step of every world (worlds × robots × 3 actions), one after the other; the
    /// Python module runs the same [`Slot::step_or_restart`] per world on rayon's threads.
    pub fn step_all(
        &mut self,
        actions: &[f32],
        obs: &mut [f32],
        rewards: &mut [f64],
        terminated: &mut [bool],
        truncated: &mut [bool],
    ) -> Result<(), Refusal> {
        self.check_step_all(
            actions.len(),
            obs.len(),
            rewards.len(),
            terminated.len(),
            truncated.len(),
        )?;
        let robots = self.robots();
        let per_world = robots * self.size();
        let (arena, spec, slots) = self.parts_mut();
        for (world, (((((slot, a), o), r), term), trunc)) in slots
            .iter_mut()
            .zip(actions.chunks_exact(robots * ACTION_SIZE))
            .zip(obs.chunks_exact_mut(per_world))
            .zip(rewards.chunks_exact_mut(robots))
            .zip(terminated.iter_mut())
            .zip(truncated.iter_mut())
            .enumerate()
        {
            (*term, *trunc) = slot
                .step_or_restart(arena, spec, a, o, r)
                .map_err(|e| e.of(world))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
