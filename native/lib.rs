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
//!
//! Every check of what a caller gives (counts against their bounds before anything is
//! allocated, floats for finiteness, arrays for their lengths, world indices) is the core's
//! too (`lasertag_core::env::engine`, which says why it lives there: the fuzz target and
//! `cargo test` reach it without Python). This shell adds what only numpy arrays have, their
//! shapes, and turns a refusal into `ValueError` or `IndexError`.
//!
//! With `planner="policy:<name>"` a shipped trained policy (`lasertag_policy`) drives every
//! world's team, as the server's match task drives it: before each tick the policy's orders
//! go in as inputs (`Episode::advance_with`), and the actions are not read. The core runs
//! no model; this shell does.

mod config;

use std::sync::Arc;
use std::time::{Duration, Instant};

use numpy::{
    PyReadonlyArray2, PyReadonlyArray3, PyReadwriteArray1, PyReadwriteArray2, PyReadwriteArray3,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyIndexError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use rayon::prelude::*;

use lasertag_core::env::engine::{self, EngineArgs, Refusal, RestartFailed, Slot, check_shape};
use lasertag_core::env::{ACTION_SIZE, EnvSpec, Rewards, command_action, mm, rad};
use lasertag_core::planner::PlannerKind;
use lasertag_core::sim::arena::Arena;
use lasertag_core::sim::{AgentId, Pose};
use lasertag_core::world::{FinishReason, Side, World, WorldInput};
use lasertag_policy::team::DEFAULT_EVERY;
use lasertag_policy::{Limits, Policy, TeamPolicy};

/// The shipped maps (`maps/*.json`), as text: the package's in-process maps.
const SHIPPED_MAPS: [(&str, &str); 4] = [
    ("hallway", include_str!("../maps/hallway.json")),
    ("maze", include_str!("../maps/maze.json")),
    ("office", include_str!("../maps/office.json")),
    ("warehouse", include_str!("../maps/warehouse.json")),
];

/// A vector of lasertag worlds on one map, driven by a policy's actions: the core's
/// [`engine::Engine`], which checks every argument and array; this shell adds the numpy
/// arrays' shapes, the GIL released while worlds step, and rayon's threads.
#[pyclass(module = "lasertag_env._native")]
struct Engine {
    inner: engine::Engine,
    /// Each world's trained policy when one drives the team (`planner="policy:<name>"`),
    /// else `None` for every world: one per world, as each decision writes its buffers.
    teams: Vec<Option<TeamPolicy>>,
    /// Whether a built-in planner drives the robots, whose decisions `step_all` then keeps
    /// in `teacher` (worlds × robots × 3): behaviour cloning's labels.
    taught: bool,
    teacher: Vec<f32>,
}

/// Each robot's planned command of `world` as the action that gives it, row by row.
fn write_teacher(world: &World, out: &mut [f32]) {
    for (row, robot) in out.chunks_exact_mut(ACTION_SIZE).zip(&world.robots) {
        row.copy_from_slice(&command_action(&robot.command));
    }
}

/// The policy's orders of this tick (none between its decisions) as inputs.
fn drive(team: &mut TeamPolicy, world: &mut World) {
    for (robot, order) in team.orders(world) {
        // An action read as the environments read it (clipped) is always taken.
        let _ = world.apply(&WorldInput::Robot { robot, order });
    }
}

/// One step of a world in a vector ([`Slot::step_or_restart`]), its policy giving the
/// orders when it has one (the actions are then not read). With `teacher`, the planners'
/// commands go into it once the step has run: what they decided from the state the step's
/// vectors describe, which they carry out on the next tick (zeros for an episode's first
/// vectors, before any decision).
#[allow(clippy::too_many_arguments)]
fn step_world(
    slot: &mut Slot,
    team: &mut Option<TeamPolicy>,
    arena: &Arc<Arena>,
    spec: &EnvSpec,
    actions: &[f32],
    obs: &mut [f32],
    rewards: &mut [f64],
    teacher: Option<&mut [f32]>,
) -> Result<(bool, bool), RestartFailed> {
    let flags = match team {
        None => slot.step_or_restart(arena, spec, actions, obs, rewards),
        Some(team) => {
            slot.step_or_restart_with(arena, spec, &[], obs, rewards, &mut |w| drive(team, w))
        }
    }?;
    if let Some(out) = teacher {
        write_teacher(slot.episode.world(), out);
    }
    Ok(flags)
}

/// The policy `name` (shipped) set up for every world of `engine`, or why it cannot drive
/// its teams (a model trained for another team size).
fn policy_teams(engine: &mut engine::Engine, name: &str) -> PyResult<Vec<Option<TeamPolicy>>> {
    let refuse = |e: &dyn std::fmt::Display| {
        PyValueError::new_err(format!("planner: \"policy:{name}\": {e}"))
    };
    let bytes = lasertag_policy::shipped(name).ok_or_else(|| refuse(&"not a shipped policy"))?;
    let policy = Arc::new(Policy::from_onnx(bytes, &Limits::default()).map_err(|e| refuse(&e))?);
    let (robots, worlds) = (engine.robots(), engine.worlds());
    let physics = engine.spec().config.physics.clone();
    let (arena, ..) = engine.parts_mut();
    // A shipped model, served as the server serves it: with its guard against parking.
    let team = TeamPolicy::new(policy, arena, robots, &physics, DEFAULT_EVERY)
        .map_err(|e| refuse(&e))?
        .unparked();
    Ok(vec![Some(team); worlds])
}

/// Whether `spec`'s robots are all driven by a built-in planner (not by actions).
fn planned_by_built_in(spec: &EnvSpec) -> bool {
    spec.config.planner != PlannerKind::Api && !spec.config.outside_robots.contains(&true)
}

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// A refusal as the Python exception it stands for.
fn refused(e: Refusal) -> PyErr {
    match e {
        Refusal::NoWorld { .. } => PyIndexError::new_err(e.to_string()),
        Refusal::Value { .. } | Refusal::Setup(_) => PyValueError::new_err(e.to_string()),
        Refusal::Restart { .. } => PyRuntimeError::new_err(e.to_string()),
    }
}

#[pymethods]
impl Engine {
    /// `map`: a map object (docs/map-format.md); `settings`: fields of `POST /api/matches`
    /// (robots, opponents, opponent_bot, time_limit_s, placement, robot_starts,
    /// opponent_starts, localisation, tracker, coordination, radio, odometry, localiser,
    /// planner: a built-in planner, one per robot, or `policy:<name>`, a shipped policy);
    /// `rewards`: weights `tag`, `team_tag`, `tick`; the laser as the rules give it. Every
    /// count is checked against `BOUNDS` before anything is allocated for it.
    #[new]
    #[pyo3(signature = (map, settings, worlds, seed, max_steps, ticks_per_step, rewards, detections, beams, laser_range, fov_deg))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
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
        let args = EngineArgs {
            map: config::map_spec(map)?,
            config: config::match_config(settings)?,
            worlds,
            seed,
            max_steps,
            ticks_per_step,
            rewards: Rewards {
                tag: rewards.0,
                team_tag: rewards.1,
                tick: rewards.2,
            },
            detections,
            beams,
            laser_range,
            fov_deg,
        };
        let checked = args.check().map_err(refused)?;
        // Building thousands of worlds takes seconds: other Python threads run meanwhile.
        let policy = checked.spec().config.policy.clone();
        let mut inner = py
            .detach(|| engine::Engine::build(checked))
            .map_err(refused)?;
        let taught = policy.is_none() && planned_by_built_in(inner.spec());
        let teams = match policy {
            Some(name) => policy_teams(&mut inner, &name)?,
            None => vec![None; inner.worlds()],
        };
        let teacher = vec![0.0; inner.worlds() * inner.robots() * ACTION_SIZE];
        Ok(Engine {
            inner,
            teams,
            taught,
            teacher,
        })
    }

    /// Values in one robot's observation vector.
    #[getter]
    fn size(&self) -> usize {
        self.inner.size()
    }

    #[getter]
    fn robots(&self) -> usize {
        self.inner.robots()
    }

    #[getter]
    fn worlds(&self) -> usize {
        self.inner.worlds()
    }

    /// The vector's bounds, (low, high).
    #[getter]
    fn bounds(&self) -> (Vec<f32>, Vec<f32>) {
        let layout = &self.inner.spec().layout;
        (layout.low().to_vec(), layout.high().to_vec())
    }

    /// Each world's episode seed.
    #[getter]
    fn seeds(&self) -> Vec<u64> {
        self.inner.seeds()
    }

    /// Starts world `world` afresh with `seed` and writes its robots' vectors into `obs`
    /// (robots × size).
    fn reset(
        &mut self,
        world: usize,
        seed: u64,
        mut obs: PyReadwriteArray2<'_, f32>,
    ) -> PyResult<()> {
        let (robots, size) = (self.inner.robots(), self.inner.size());
        check_shape("obs", obs.shape(), &[robots, size]).map_err(refused)?;
        let out = obs.as_slice_mut().map_err(value_error)?;
        self.inner.reset(world, seed, out).map_err(refused)
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
        let e = &self.inner;
        check_shape("obs", obs.shape(), &[e.worlds(), e.robots(), e.size()]).map_err(refused)?;
        let out = obs.as_slice_mut().map_err(value_error)?;
        self.inner
            .reset_all(out, seed, seeds.as_deref())
            .map_err(refused)?;
        self.teacher.fill(0.0);
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
        let (robots, size) = (self.inner.robots(), self.inner.size());
        check_shape("actions", actions.shape(), &[robots, ACTION_SIZE]).map_err(refused)?;
        check_shape("obs", obs.shape(), &[robots, size]).map_err(refused)?;
        check_shape("rewards", rewards.shape(), &[robots]).map_err(refused)?;
        let actions = actions.as_slice().map_err(value_error)?;
        let obs = obs.as_slice_mut().map_err(value_error)?;
        let rewards = rewards.as_slice_mut().map_err(value_error)?;
        let inner = &mut self.inner;
        let out = match self.teams.get_mut(world) {
            Some(Some(team)) => {
                inner
                    .check_step(actions.len(), obs.len(), rewards.len())
                    .map_err(refused)?;
                let (_, spec, slots) = inner.parts_mut();
                let slot = &mut slots[world];
                let out = py.detach(|| {
                    slot.episode
                        .step_with(spec, &[], obs, rewards, &mut |w| drive(team, w))
                });
                slot.ended = out.terminated || out.truncated;
                out
            }
            _ => py
                .detach(|| inner.step(world, actions, obs, rewards))
                .map_err(refused)?,
        };
        Ok((
            out.tick,
            out.terminated,
            out.truncated,
            out.winner.map(winner_name),
            out.reason.map(FinishReason::name),
            self.inner
                .world(world)
                .map_err(refused)?
                .episode
                .tags()
                .to_vec(),
        ))
    }

    /// One step of every world (worlds × robots × 3 actions), each on whichever core is
    /// free, without the GIL. A world whose episode ended on the previous step starts its
    /// next one instead (Gymnasium's next-step auto-reset): its actions are ignored, its
    /// vectors are the new episode's first, its rewards 0 and its flags false. A next
    /// episode whose seed places no match raises `RuntimeError` naming the lowest such
    /// world and its seed (the other worlds have stepped).
    fn step_all(
        &mut self,
        py: Python<'_>,
        actions: PyReadonlyArray3<'_, f32>,
        mut obs: PyReadwriteArray3<'_, f32>,
        mut rewards: PyReadwriteArray2<'_, f64>,
        mut terminated: PyReadwriteArray1<'_, bool>,
        mut truncated: PyReadwriteArray1<'_, bool>,
    ) -> PyResult<()> {
        let (worlds, robots, size) = (self.inner.worlds(), self.inner.robots(), self.inner.size());
        for (name, shape, want) in [
            (
                "actions",
                actions.shape(),
                &[worlds, robots, ACTION_SIZE][..],
            ),
            ("obs", obs.shape(), &[worlds, robots, size][..]),
            ("rewards", rewards.shape(), &[worlds, robots][..]),
            ("terminated", terminated.shape(), &[worlds][..]),
            ("truncated", truncated.shape(), &[worlds][..]),
        ] {
            check_shape(name, shape, want).map_err(refused)?;
        }
        let actions = actions.as_slice().map_err(value_error)?;
        let obs = obs.as_slice_mut().map_err(value_error)?;
        let rewards = rewards.as_slice_mut().map_err(value_error)?;
        let terminated = terminated.as_slice_mut().map_err(value_error)?;
        let truncated = truncated.as_slice_mut().map_err(value_error)?;
        self.inner
            .check_step_all(
                actions.len(),
                obs.len(),
                rewards.len(),
                terminated.len(),
                truncated.len(),
            )
            .map_err(refused)?;
        let per_world = robots * size;
        let taught = self.taught;
        let (arena, spec, slots) = self.inner.parts_mut();
        let teams = &mut self.teams;
        let teacher = &mut self.teacher;
        // The core's `step_all` with the worlds spread over rayon's threads.
        let failed = py.detach(|| {
            slots
                .par_iter_mut()
                .zip(teams.par_iter_mut())
                .zip(actions.par_chunks_exact(robots * ACTION_SIZE))
                .zip(obs.par_chunks_exact_mut(per_world))
                .zip(rewards.par_chunks_exact_mut(robots))
                .zip(terminated.par_iter_mut())
                .zip(truncated.par_iter_mut())
                .zip(teacher.par_chunks_exact_mut(robots * ACTION_SIZE))
                .enumerate()
                .filter_map(
                    |(world, (((((((slot, team), a), o), r), term), trunc), t))| {
                        let t = taught.then_some(t);
                        match step_world(slot, team, arena, spec, a, o, r, t) {
                            Ok(flags) => {
                                (*term, *trunc) = flags;
                                None
                            }
                            Err(e) => Some(e.of(world)),
                        }
                    },
                )
                .min_by_key(|e| match e {
                    Refusal::Restart { world, .. } => *world,
                    _ => usize::MAX,
                })
        });
        failed.map_or(Ok(()), |e| Err(refused(e)))
    }

    /// Each robot's action as its built-in planner decided it at the end of the last
    /// `step_all` (worlds × robots × 3: forward, turn, tag as 1 or 0), into `out`: the
    /// decision from the state the step's vectors describe, which the robot carries out on
    /// the next tick, so behaviour cloning pairs those vectors with these actions. Zeros
    /// after a reset and for an episode's first vectors (nothing decided yet). Refused
    /// unless a built-in planner (`coordinated`, `search`, `baseline`) drives the robots.
    fn teacher_actions(&self, mut out: PyReadwriteArray3<'_, f32>) -> PyResult<()> {
        if !self.taught {
            return Err(PyValueError::new_err(
                "teacher actions: no built-in planner drives these robots (planner=\"coordinated\", \"search\" or \"baseline\" does)",
            ));
        }
        let (worlds, robots) = (self.inner.worlds(), self.inner.robots());
        check_shape("out", out.shape(), &[worlds, robots, ACTION_SIZE]).map_err(refused)?;
        out.as_slice_mut()
            .map_err(value_error)?
            .copy_from_slice(&self.teacher);
        Ok(())
    }

    /// `steps` steps of world `world`, step `k` with `actions[k % len]` (each robots × 3),
    /// timing the ticks (with the rewards) apart from the observation vectors: (ticks
    /// seconds, vectors seconds). The world goes on from where it was, and starts afresh
    /// when its episode ends. At most `MAX_TIMED_TICKS` ticks a call (`BOUNDS["timed_ticks"]`,
    /// what one step request to the server may advance), so a call returns in seconds.
    fn time_parts(
        &mut self,
        py: Python<'_>,
        world: usize,
        steps: usize,
        actions: PyReadonlyArray3<'_, f32>,
    ) -> PyResult<(f64, f64)> {
        let (robots, size) = (self.inner.robots(), self.inner.size());
        engine::check_timed(steps as u64, self.inner.spec().ticks_per_step).map_err(refused)?;
        let shape = actions.shape();
        if shape.len() != 3 || shape[0] == 0 || shape[1..] != [robots, ACTION_SIZE] {
            return Err(refused(engine::refuse(
                "actions",
                format!("shape {shape:?}, the engine needs [steps ≥ 1, {robots}, {ACTION_SIZE}]"),
            )));
        }
        let actions = actions.as_slice().map_err(value_error)?;
        let per_step = robots * ACTION_SIZE;
        let mut obs = vec![0.0; robots * size];
        let mut rewards = vec![0.0; robots];
        self.inner.world(world).map_err(refused)?;
        let (arena, spec, slots) = self.inner.parts_mut();
        let slot = &mut slots[world];
        let team = &mut self.teams[world];
        py.detach(|| {
            let (mut ticks, mut vectors) = (Duration::ZERO, Duration::ZERO);
            for a in actions.chunks_exact(per_step).cycle().take(steps) {
                let t0 = Instant::now();
                let (out, time_fraction) = match team {
                    None => slot.episode.advance(spec, a, &mut rewards),
                    // The policy's inference counts with the ticks.
                    Some(team) => slot
                        .episode
                        .advance_with(spec, &[], &mut rewards, &mut |w| drive(team, w)),
                };
                let t1 = Instant::now();
                slot.episode.observe(spec, time_fraction, &mut obs);
                vectors += t1.elapsed();
                ticks += t1 - t0;
                if out.terminated || out.truncated {
                    slot.ended = true;
                    step_world(slot, team, arena, spec, a, &mut obs, &mut rewards, None)
                        .map_err(|e| e.of(world))?;
                }
            }
            Ok((ticks.as_secs_f64(), vectors.as_secs_f64()))
        })
        .map_err(refused)
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
                e.set_item("goal", t.goal.map(|g| [mm(g.x), mm(g.y)]))?;
                Ok(e)
            })
            .collect::<PyResult<Vec<_>>>()?;
        d.set_item("teammates", teammates)?;
        let belief = PyDict::new(py);
        belief.set_item("grid", o.belief.grid.to_vec())?;
        belief.set_item("paths", o.belief.paths.to_vec())?;
        belief.set_item(
            "roles",
            o.belief
                .roles
                .iter()
                .map(|r| r.to_vec())
                .collect::<Vec<_>>(),
        )?;
        belief.set_item("untagged", o.belief.untagged)?;
        d.set_item("belief", belief)?;
        Ok(d)
    }
}

impl Engine {
    fn get(&self, world: usize) -> PyResult<&engine::Slot> {
        self.inner.world(world).map_err(refused)
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

/// The engine's bounds by argument (docs/research.md, "Bounds"): the most robots,
/// opponents and detection slots, the longest time limit in seconds, the most ticks a step,
/// and the most robots over all the worlds of one engine.
fn bounds(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("robots", engine::MAX_ROBOTS)?;
    d.set_item("opponents", engine::MAX_OPPONENTS)?;
    d.set_item("detections", engine::MAX_DETECTIONS)?;
    d.set_item("time_limit_s", engine::MAX_TIME_LIMIT_S)?;
    d.set_item("ticks_per_step", engine::MAX_TICKS_PER_STEP)?;
    d.set_item("max_steps", engine::MAX_STEPS)?;
    d.set_item("timed_ticks", engine::MAX_TIMED_TICKS)?;
    d.set_item("agents", engine::MAX_AGENTS)?;
    Ok(d)
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Engine>()?;
    m.add_function(wrap_pyfunction!(shipped_maps, m)?)?;
    m.add("BOUNDS", bounds(m.py())?)?;
    Ok(())
}
