//! `lasertag_env._native`: lasertag matches stepped in-process, for the Python package's
//! environments (python/lasertag_env/native.py wraps it; docs/research.md is the manual).
//!
//! An [`Engine`] holds a vector of worlds on one arena (whose derived tables, the
//! localisers' likelihood fields and the planners' views, are built once for all of them).
//! Each call reads the policy's actions from a numpy array and writes observations,
//! rewards and flags into numpy arrays the caller allocated once: no Python object per
//! value, no copy. The step itself runs with the GIL released, the worlds spread over the
//! cores by rayon. The arithmetic is the core's (`lasertag_core::env`), the same as the
//! HTTP backend's bit for bit.

mod config;

use std::sync::Arc;
use std::time::{Duration, Instant};

use numpy::{
    PyReadonlyArray2, PyReadonlyArray3, PyReadwriteArray1, PyReadwriteArray2, PyReadwriteArray3,
};
use pyo3::exceptions::{PyIndexError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;

use lasertag_core::env::{
    ACTION_SIZE, EnvSpec, Episode, EpisodeSeeds, Layout, Outcome, Rewards, mm, rad,
};
use lasertag_core::sim::arena::Arena;
use lasertag_core::sim::{AgentId, Pose};
use lasertag_core::world::{FinishReason, Side};

/// The shipped maps (`maps/*.json`), as text: the package's in-process maps.
const SHIPPED_MAPS: [(&str, &str); 4] = [
    ("hallway", include_str!("../maps/hallway.json")),
    ("maze", include_str!("../maps/maze.json")),
    ("office", include_str!("../maps/office.json")),
    ("warehouse", include_str!("../maps/warehouse.json")),
];

/// One world of the vector.
struct Slot {
    episode: Episode,
    seeds: EpisodeSeeds,
    /// Its episode's seed.
    seed: u64,
    /// Its episode ended on the last step (the next one resets it).
    ended: bool,
}

impl Slot {
    /// Its episode (just put in place) begins: `seed` noted, its robots' first vectors
    /// into `obs`.
    fn begin(&mut self, seed: u64, spec: &EnvSpec, obs: &mut [f32]) {
        self.seed = seed;
        self.ended = false;
        self.episode.observe_start(spec, obs);
    }
}

/// A vector of lasertag worlds on one map, driven by a policy's actions.
#[pyclass(module = "lasertag_env._native")]
struct Engine {
    arena: Arc<Arena>,
    spec: EnvSpec,
    slots: Vec<Slot>,
}

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

#[pymethods]
impl Engine {
    /// `map`: a map object (docs/map-format.md); `settings`: fields of `POST /api/matches`
    /// (robots, opponents, opponent_bot, time_limit_s, placement, robot_starts,
    /// opponent_starts, localisation, tracker, coordination, radio, odometry, localiser);
    /// `rewards`: weights `tag`, `team_tag`, `tick`; the laser as the rules give it.
    #[new]
    #[pyo3(signature = (map, settings, worlds, seed, max_steps, ticks_per_step, rewards, detections, beams, laser_range, fov_deg))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        map: &Bound<'_, PyDict>,
        settings: &Bound<'_, PyDict>,
        worlds: usize,
        seed: u64,
        max_steps: Option<u64>,
        ticks_per_step: u64,
        rewards: (f64, f64, f64),
        detections: usize,
        beams: usize,
        laser_range: f64,
        fov_deg: f64,
    ) -> PyResult<Engine> {
        if worlds == 0 {
            return Err(PyValueError::new_err("worlds: must be at least 1"));
        }
        if ticks_per_step == 0 {
            return Err(PyValueError::new_err("ticks_per_step: must be at least 1"));
        }
        let spec_map = config::map_spec(map)?;
        let (width, height) = (spec_map.width, spec_map.height);
        let def = lasertag_core::sim::map_rules::validate(&spec_map)
            .map_err(|e| PyValueError::new_err(format!("map.{e}")))?;
        let match_config = config::match_config(settings)?;
        let robots = match_config.robots;
        let spec = EnvSpec {
            config: match_config,
            layout: Layout::new(
                robots,
                detections,
                width,
                height,
                beams,
                laser_range,
                fov_deg,
            ),
            rewards: Rewards {
                tag: rewards.0,
                team_tag: rewards.1,
                tick: rewards.2,
            },
            max_steps,
            ticks_per_step,
        };
        let arena = Arc::new(Arena::new(def));
        let slots = (0..worlds)
            .map(|i| {
                let mut seeds = EpisodeSeeds::new(seed, i as u64);
                let seed = seeds.draw();
                let episode = Episode::new(arena.clone(), &spec, seed).map_err(value_error)?;
                Ok(Slot {
                    episode,
                    seeds,
                    seed,
                    ended: false,
                })
            })
            .collect::<PyResult<Vec<_>>>()?;
        Ok(Engine { arena, spec, slots })
    }

    /// Values in one robot's observation vector.
    #[getter]
    fn size(&self) -> usize {
        self.spec.layout.size()
    }

    #[getter]
    fn robots(&self) -> usize {
        self.spec.config.robots
    }

    #[getter]
    fn worlds(&self) -> usize {
        self.slots.len()
    }

    /// The vector's bounds, (low, high).
    #[getter]
    fn bounds(&self) -> (Vec<f32>, Vec<f32>) {
        (
            self.spec.layout.low().to_vec(),
            self.spec.layout.high().to_vec(),
        )
    }

    /// Each world's episode seed.
    #[getter]
    fn seeds(&self) -> Vec<u64> {
        self.slots.iter().map(|s| s.seed).collect()
    }

    /// Starts world `world` afresh with `seed` and writes its robots' vectors into `obs`
    /// (robots × size).
    fn reset(
        &mut self,
        world: usize,
        seed: u64,
        mut obs: PyReadwriteArray2<'_, f32>,
    ) -> PyResult<()> {
        let out = obs.as_slice_mut().map_err(value_error)?;
        check_len(
            "obs",
            out.len(),
            self.spec.config.robots * self.spec.layout.size(),
        )?;
        let episode = Episode::new(self.arena.clone(), &self.spec, seed).map_err(value_error)?;
        let slot = slot_mut(&mut self.slots, world)?;
        slot.episode = episode;
        slot.begin(seed, &self.spec, out);
        Ok(())
    }

    /// Every world's next episode, its vectors into `obs` (worlds × robots × size). The
    /// seeds come from each world's stream; `seed` starts the streams over (world `w`'s
    /// first episode then has seed `seed + w`), and `seeds` gives each world's first seed
    /// itself (its later ones come from a stream seeded by it).
    #[pyo3(signature = (obs, seed=None, seeds=None))]
    fn reset_all(
        &mut self,
        mut obs: PyReadwriteArray3<'_, f32>,
        seed: Option<u64>,
        seeds: Option<Vec<u64>>,
    ) -> PyResult<()> {
        let out = obs.as_slice_mut().map_err(value_error)?;
        let per_world = self.spec.config.robots * self.spec.layout.size();
        check_len("obs", out.len(), per_world * self.slots.len())?;
        if let Some(seeds) = &seeds {
            check_len("seeds", seeds.len(), self.slots.len())?;
        }
        for (i, slot) in self.slots.iter_mut().enumerate() {
            if let Some(seeds) = &seeds {
                slot.seeds = EpisodeSeeds::new(seeds[i], 0);
            } else if let Some(base) = seed {
                slot.seeds = EpisodeSeeds::new(base, i as u64);
            }
        }
        for (slot, rows) in self.slots.iter_mut().zip(out.chunks_exact_mut(per_world)) {
            let seed = slot.seeds.draw();
            slot.episode =
                Episode::new(self.arena.clone(), &self.spec, seed).map_err(value_error)?;
            slot.begin(seed, &self.spec, rows);
        }
        Ok(())
    }

    /// One step of world `world`: `actions` (robots × 3) in, vectors into `obs` (robots ×
    /// size) and rewards into `rewards` (robots). Returns (tick, terminated, truncated,
    /// winner, reason, tags per robot).
    #[allow(clippy::type_complexity)]
    fn step(
        &mut self,
        py: Python<'_>,
        world: usize,
        actions: PyReadonlyArray2<'_, f32>,
        mut obs: PyReadwriteArray2<'_, f32>,
        mut rewards: PyReadwriteArray1<'_, f64>,
    ) -> PyResult<(
        u64,
        bool,
        bool,
        Option<&'static str>,
        Option<&'static str>,
        Vec<u32>,
    )> {
        let robots = self.spec.config.robots;
        let size = self.spec.layout.size();
        let actions = actions.as_slice().map_err(value_error)?;
        check_len("actions", actions.len(), robots * ACTION_SIZE)?;
        let obs = obs.as_slice_mut().map_err(value_error)?;
        check_len("obs", obs.len(), robots * size)?;
        let rewards = rewards.as_slice_mut().map_err(value_error)?;
        check_len("rewards", rewards.len(), robots)?;
        let spec = &self.spec;
        let slot = slot_mut(&mut self.slots, world)?;
        let out = py.detach(|| slot.episode.step(spec, actions, obs, rewards));
        slot.ended = out.terminated || out.truncated;
        Ok((
            out.tick,
            out.terminated,
            out.truncated,
            out.winner.map(winner_name),
            out.reason.map(FinishReason::name),
            slot.episode.tags().to_vec(),
        ))
    }

    /// One step of every world (worlds × robots × 3 actions), each on whichever core is
    /// free, without the GIL. A world whose episode ended on the previous step starts its
    /// next one instead (Gymnasium's next-step auto-reset): its actions are ignored, its
    /// vectors are the new episode's first, its rewards 0 and its flags false.
    fn step_all(
        &mut self,
        py: Python<'_>,
        actions: PyReadonlyArray3<'_, f32>,
        mut obs: PyReadwriteArray3<'_, f32>,
        mut rewards: PyReadwriteArray2<'_, f64>,
        mut terminated: PyReadwriteArray1<'_, bool>,
        mut truncated: PyReadwriteArray1<'_, bool>,
    ) -> PyResult<()> {
        let worlds = self.slots.len();
        let robots = self.spec.config.robots;
        let per_world = robots * self.spec.layout.size();
        let actions = actions.as_slice().map_err(value_error)?;
        check_len("actions", actions.len(), worlds * robots * ACTION_SIZE)?;
        let obs = obs.as_slice_mut().map_err(value_error)?;
        check_len("obs", obs.len(), worlds * per_world)?;
        let rewards = rewards.as_slice_mut().map_err(value_error)?;
        check_len("rewards", rewards.len(), worlds * robots)?;
        let terminated = terminated.as_slice_mut().map_err(value_error)?;
        check_len("terminated", terminated.len(), worlds)?;
        let truncated = truncated.as_slice_mut().map_err(value_error)?;
        check_len("truncated", truncated.len(), worlds)?;
        let (arena, spec) = (&self.arena, &self.spec);
        py.detach(|| {
            self.slots
                .par_iter_mut()
                .zip(actions.par_chunks_exact(robots * ACTION_SIZE))
                .zip(obs.par_chunks_exact_mut(per_world))
                .zip(rewards.par_chunks_exact_mut(robots))
                .zip(terminated.par_iter_mut())
                .zip(truncated.par_iter_mut())
                .for_each(|(((((slot, a), o), r), term), trunc)| {
                    (*term, *trunc) = step_world(arena, spec, slot, a, o, r);
                });
        });
        Ok(())
    }

    /// `steps` steps of world `world`, step `k` with `actions[k % len]` (each robots × 3),
    /// timing the ticks (with the rewards) apart from the observation vectors: (ticks
    /// seconds, vectors seconds). The world goes on from where it was, and starts afresh
    /// when its episode ends.
    fn time_parts(
        &mut self,
        py: Python<'_>,
        world: usize,
        steps: usize,
        actions: PyReadonlyArray3<'_, f32>,
    ) -> PyResult<(f64, f64)> {
        let robots = self.spec.config.robots;
        let actions = actions.as_slice().map_err(value_error)?;
        let per_step = robots * ACTION_SIZE;
        if actions.is_empty() || actions.len() % per_step != 0 {
            return Err(PyValueError::new_err(format!(
                "actions: {} values, a multiple of {per_step} (steps × robots × 3) is needed",
                actions.len()
            )));
        }
        let mut obs = vec![0.0; robots * self.spec.layout.size()];
        let mut rewards = vec![0.0; robots];
        let (arena, spec) = (&self.arena, &self.spec);
        let slot = slot_mut(&mut self.slots, world)?;
        Ok(py.detach(|| {
            let (mut ticks, mut vectors) = (Duration::ZERO, Duration::ZERO);
            for a in actions.chunks_exact(per_step).cycle().take(steps) {
                let t0 = Instant::now();
                let (out, time_fraction) = slot.episode.advance(spec, a, &mut rewards);
                let t1 = Instant::now();
                slot.episode.observe(spec, time_fraction, &mut obs);
                vectors += t1.elapsed();
                ticks += t1 - t0;
                if out.terminated || out.truncated {
                    slot.ended = true;
                    step_world(arena, spec, slot, a, &mut obs, &mut rewards);
                }
            }
            (ticks.as_secs_f64(), vectors.as_secs_f64())
        }))
    }

    /// World `world`'s state digest (`World::digest`): two runs agree on it only if they
    /// agree on every position, belief and random draw.
    fn digest(&self, world: usize) -> PyResult<u64> {
        Ok(self.get(world)?.episode.world().digest())
    }

    /// World `world`'s ground truth, for rendering: (tick, robots as (x, y, θ, frozen,
    /// scan), opponents as (x, y, θ, tagged)).
    #[allow(clippy::type_complexity)]
    fn truth(
        &self,
        world: usize,
    ) -> PyResult<(
        u64,
        Vec<(f32, f32, f32, bool, Vec<f32>)>,
        Vec<(f32, f32, f32, bool)>,
    )> {
        let w = self.get(world)?.episode.world();
        let robots = (0..w.robots.len())
            .map(|i| {
                let r = &w.robots[i];
                let p = r.pose;
                (
                    p.pos.x,
                    p.pos.y,
                    p.theta,
                    w.robot_frozen(i),
                    r.scan.ranges.clone(),
                )
            })
            .collect();
        let opponents = w
            .opponents
            .iter()
            .map(|o| (o.pose.pos.x, o.pose.pos.y, o.pose.theta, o.tagged))
            .collect();
        Ok((w.tick, robots, opponents))
    }

    /// What robot `robot` of world `world` knows, as the HTTP API's observation object
    /// (the same rounding): for hand-written policies that read it by name.
    fn observation<'py>(
        &self,
        py: Python<'py>,
        world: usize,
        robot: usize,
    ) -> PyResult<Bound<'py, PyDict>> {
        let w = self.get(world)?.episode.world();
        let o = w
            .observation(robot)
            .ok_or_else(|| PyIndexError::new_err(format!("robot {robot}: out of range")))?;
        let pose = |p: Pose| -> PyResult<Bound<'py, PyDict>> {
            let d = PyDict::new(py);
            d.set_item("x", mm(p.pos.x))?;
            d.set_item("y", mm(p.pos.y))?;
            d.set_item("theta", rad(p.theta))?;
            Ok(d)
        };
        let d = PyDict::new(py);
        d.set_item("tick", o.tick)?;
        d.set_item("scan", o.scan.iter().map(|r| mm(*r)).collect::<Vec<_>>())?;
        let detections = o
            .detections
            .iter()
            .map(|s| {
                let e = PyDict::new(py);
                e.set_item("range", mm(s.range))?;
                e.set_item("bearing", rad(s.bearing))?;
                Ok(e)
            })
            .collect::<PyResult<Vec<_>>>()?;
        d.set_item("detections", detections)?;
        let landmarks = o
            .landmarks
            .iter()
            .map(|l| {
                let e = PyDict::new(py);
                e.set_item("id", l.id)?;
                e.set_item("range", mm(l.range))?;
                e.set_item("bearing", rad(l.bearing))?;
                Ok(e)
            })
            .collect::<PyResult<Vec<_>>>()?;
        d.set_item("landmarks", landmarks)?;
        d.set_item("odometry", pose(o.odometry)?)?;
        d.set_item("estimate", pose(o.estimate)?)?;
        d.set_item("spread", mm(o.spread))?;
        d.set_item("frozen", o.frozen)?;
        d.set_item("tag_ready", o.tag_ready)?;
        let teammates = o
            .teammates
            .iter()
            .map(|t| {
                let e = pose(t.pose)?;
                e.set_item("id", AgentId::Robot(t.robot).to_string())?;
                e.set_item("age_ticks", t.age_ticks)?;
                Ok(e)
            })
            .collect::<PyResult<Vec<_>>>()?;
        d.set_item("teammates", teammates)?;
        Ok(d)
    }
}

impl Engine {
    fn get(&self, world: usize) -> PyResult<&Slot> {
        let n = self.slots.len();
        self.slots.get(world).ok_or_else(|| no_world(world, n))
    }
}

/// World `world` of `slots`, to change.
fn slot_mut(slots: &mut [Slot], world: usize) -> PyResult<&mut Slot> {
    let n = slots.len();
    slots.get_mut(world).ok_or_else(|| no_world(world, n))
}

fn no_world(world: usize, worlds: usize) -> PyErr {
    PyIndexError::new_err(format!("world {world}: out of range 0..{worlds}"))
}

/// One world's step in a vector: its episode's, or its next episode's start when the last
/// step ended it. Returns (terminated, truncated).
fn step_world(
    arena: &Arc<Arena>,
    spec: &EnvSpec,
    slot: &mut Slot,
    actions: &[f32],
    obs: &mut [f32],
    rewards: &mut [f64],
) -> (bool, bool) {
    if slot.ended {
        let seed = slot.seeds.draw();
        // The settings built a world once already: the same ones on the same arena build
        // every later one.
        if let Ok(episode) = Episode::new(arena.clone(), spec, seed) {
            slot.episode = episode;
        }
        slot.begin(seed, spec, obs);
        rewards.fill(0.0);
        return (false, false);
    }
    let out: Outcome = slot.episode.step(spec, actions, obs, rewards);
    slot.ended = out.terminated || out.truncated;
    (out.terminated, out.truncated)
}

fn check_len(name: &str, got: usize, want: usize) -> PyResult<()> {
    if got == want {
        Ok(())
    } else {
        Err(PyValueError::new_err(format!(
            "{name}: {got} values, the engine needs {want} (a C-contiguous array of the right shape)"
        )))
    }
}

fn winner_name(side: Side) -> &'static str {
    match side {
        Side::Robots => "robots",
        Side::Opponents => "opponents",
    }
}

/// The shipped maps as JSON text, by name.
#[pyfunction]
fn shipped_maps() -> Vec<(&'static str, &'static str)> {
    SHIPPED_MAPS.to_vec()
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Engine>()?;
    m.add_function(wrap_pyfunction!(shipped_maps, m)?)?;
    Ok(())
}
