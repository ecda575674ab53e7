//! The fuzz body of `fuzz/fuzz_targets/native_engine.rs`: bytes → the engine's constructor
//! arguments and a run of calls on it, each through [`Engine`] as the Python module makes
//! them. It lives beside the engine (not in the fuzz crate) so that `cargo test` runs it on
//! fixed inputs too (`tests.rs`).
//!
//! Besides "no panic, no abort", it checks the engine's promises: what the checks accept is
//! within every bound, a refusal names a field, and the vectors the steps write lie within
//! the layout's bounds (no NaN), their rewards finite.
//!
//! Counts are decoded mostly small and sometimes as whole 64-bit numbers, floats mostly as
//! the value the rules give and sometimes as NaN, an infinity or raw bits, so that both
//! sides of every check are reached. An engine of more than [`MOST_BUILT`] worlds, or a
//! map over 400 m², is checked but not built, and a step advances at most
//! [`MOST_TICKS`] ticks: the checks are the same at any size, and each input stays fast.

use super::*;
use crate::bots::BotKind;
use crate::planner::PlannerKind;

/// The most worlds an input builds.
pub const MOST_BUILT: usize = 3;
/// The most ticks per step of an input that is stepped.
pub const MOST_TICKS: u64 = 8;
/// The most calls an input makes after building.
const MOST_CALLS: usize = 24;

/// The input, read from the front; zeros once it runs out.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn u8(&mut self) -> u8 {
        match self.0.split_first() {
            Some((b, rest)) => {
                self.0 = rest;
                *b
            }
            None => 0,
        }
    }

    fn u64(&mut self) -> u64 {
        (0..8).fold(0, |v, i| v | (self.u8() as u64) << (8 * i))
    }

    /// Mostly in `lo..=hi`, sometimes just outside it, sometimes any 64-bit number.
    fn count(&mut self, lo: u64, hi: u64) -> u64 {
        match self.u8() {
            s @ 0..200 => lo + s as u64 % (hi - lo + 1),
            s @ 200..224 if s.is_multiple_of(2) => lo.wrapping_sub(1),
            200..224 => hi + 1,
            _ => self.u64(),
        }
    }

    /// Mostly `usual`, else a multiple of it, zero, NaN, an infinity or raw bits.
    fn float(&mut self, usual: f64) -> f64 {
        match self.u8() % 32 {
            0 => f64::NAN,
            1 => f64::INFINITY,
            2 => f64::NEG_INFINITY,
            3 => f64::from_bits(self.u64()),
            4 => 0.0,
            5 => usual * self.u8() as f64 / 64.0,
            _ => usual,
        }
    }

    /// An action's value: mostly in [-1.5, 1.5], sometimes NaN, infinite or raw bits.
    fn action(&mut self) -> f32 {
        match self.u8() % 8 {
            0 => f32::NAN,
            1 => f32::INFINITY,
            2 => f32::from_bits(self.u64() as u32),
            _ => (self.u8() as f32 - 128.0) / 85.0,
        }
    }

    fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

/// An empty rectangle of `width` × `height` with one pillar, and spawns in two corners.
fn map(b: &mut Bytes) -> MapSpec {
    let width = b.float(12.0);
    let height = b.float(8.0);
    let (w, h) = (width, height);
    MapSpec {
        name: "fuzz".into(),
        width,
        height,
        obstacles: vec![vec![
            [w / 2.0, h / 2.0],
            [w / 2.0 + 0.5, h / 2.0],
            [w / 2.0 + 0.5, h / 2.0 + 0.5],
        ]],
        robot_spawns: vec![[1.0, 1.0, 0.0], [1.0, 2.5, 0.0]],
        opponent_spawns: vec![[w - 1.0, h - 1.0]],
        landmarks: vec![],
    }
}

fn config(b: &mut Bytes) -> Result<MatchConfig, Refusal> {
    let robots = b.count(1, MAX_ROBOTS as u64) as usize;
    let opponents = b.count(1, 4) as usize;
    let time_limit_ticks = time_limit_ticks(b.float(300.0))?;
    let kinds = [
        PlannerKind::Api,
        PlannerKind::Coordinated,
        PlannerKind::Baseline,
    ];
    let planner = kinds[b.u8() as usize % kinds.len()];
    let outside_robots = match b.u8() % 4 {
        0 if planner != PlannerKind::Api => (0..b.u8() % 10).map(|i| i % 2 == 0).collect(),
        _ => Vec::new(),
    };
    let placement = match b.u8() % 4 {
        0 => Placement::Random,
        1 => Placement::Given {
            robots: (0..b.u8() % 4)
                .map(|_| {
                    [
                        b.float(2.0) as f32,
                        b.float(2.0) as f32,
                        b.float(1.0) as f32,
                    ]
                })
                .collect(),
            opponents: (0..b.u8() % 3)
                .map(|_| [b.float(9.0) as f32, b.float(6.0) as f32])
                .collect(),
        },
        _ => Placement::Spawns,
    };
    let mut config = MatchConfig {
        robots,
        opponents,
        opponent_bot: [BotKind::Wander, BotKind::Evade, BotKind::Idle][b.u8() as usize % 3],
        planner,
        outside_robots,
        time_limit_ticks,
        placement,
        localisation: b.u8().is_multiple_of(2),
        ..MatchConfig::default()
    };
    // The tracker at its minimum, as the environments run it (no observation reads it).
    config.tracker.particles_per_role = 10;
    Ok(config)
}

fn args(b: &mut Bytes) -> Result<EngineArgs, Refusal> {
    let map = map(b);
    let config = config(b)?;
    Ok(EngineArgs {
        map,
        config,
        worlds: b.count(1, MOST_BUILT as u64) as usize,
        seed: b.u64(),
        max_steps: match b.u8() % 4 {
            0 => None,
            _ => Some(b.count(1, 12)),
        },
        ticks_per_step: b.count(1, MOST_TICKS),
        rewards: Rewards {
            tag: b.float(1.0),
            team_tag: b.float(0.5),
            tick: b.float(-0.001),
        },
        detections: b.count(0, 4) as usize,
        beams: match b.u8() % 8 {
            0 => b.count(0, 400) as usize,
            _ => 181,
        },
        laser_range: b.float(8.0),
        fov_deg: b.float(180.0),
    })
}

/// A refusal names what it refuses.
fn check_refusal(e: &Refusal) {
    if let Refusal::Value { field, message } = e {
        assert!(
            !field.is_empty() && !message.is_empty(),
            "a refusal without a field: {e:?}"
        );
    }
}

/// Robots' vectors within the layout's bounds.
fn check_vectors(spec: &EnvSpec, obs: &[f32]) {
    let (low, high) = (spec.layout.low(), spec.layout.high());
    for (i, row) in obs.chunks_exact(spec.layout.size()).enumerate() {
        for (j, v) in row.iter().enumerate() {
            assert!(
                (low[j]..=high[j]).contains(v),
                "robot {i}'s value {j} is {v}, outside [{}, {}]",
                low[j],
                high[j]
            );
        }
    }
}

/// `n`, or one more or one less when the input asks for a wrong length.
fn length(b: &mut Bytes, n: usize) -> usize {
    match b.u8() % 16 {
        0 => n + 1,
        1 => n.saturating_sub(1),
        _ => n,
    }
}

/// How far an input went.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reached {
    /// Its arguments were refused.
    Refused,
    /// They passed the checks; the engine was too large to build here.
    Checked,
    /// The engine was built, and took `calls` calls without refusing them.
    Built { calls: usize },
}

/// Runs one input: the checks, and for a small engine that passes them its build and a
/// run of resets and steps. Panics only when a promise above is broken.
pub fn exercise(data: &[u8]) -> Reached {
    let mut b = Bytes(data);
    let checked = match args(&mut b).and_then(EngineArgs::check) {
        Ok(c) => c,
        Err(e) => {
            check_refusal(&e);
            return Reached::Refused;
        }
    };
    let spec = checked.spec();
    let c = &spec.config;
    assert!((1..=MAX_ROBOTS).contains(&c.robots), "robots {}", c.robots);
    assert!((1..=MAX_OPPONENTS).contains(&c.opponents));
    assert!(checked.worlds() * c.robots <= MAX_AGENTS);
    assert!((1..=MAX_TICKS_PER_STEP).contains(&spec.ticks_per_step));
    let area = checked.map().width * checked.map().height;
    if checked.worlds() > MOST_BUILT || spec.ticks_per_step > MOST_TICKS || area > 400.0 {
        return Reached::Checked;
    }
    let weights = spec.rewards;
    let mut engine = match Engine::build(checked) {
        Ok(e) => e,
        Err(e) => {
            check_refusal(&e);
            return Reached::Refused;
        }
    };
    let mut taken = 0;
    let (worlds, robots, size) = (engine.worlds(), engine.robots(), engine.size());
    for _ in 0..MOST_CALLS {
        if b.is_empty() {
            break;
        }
        let world = b.count(0, worlds as u64 - 1) as usize;
        let result = match b.u8() % 4 {
            0 => {
                let mut obs = vec![0.0; length(&mut b, robots * size)];
                let seed = b.u64();
                engine.reset(world, seed, &mut obs).map(|()| obs)
            }
            1 => {
                let mut obs = vec![0.0; length(&mut b, worlds * robots * size)];
                let seeds: Option<Vec<u64>> = match b.u8() % 3 {
                    0 => Some((0..length(&mut b, worlds)).map(|_| b.u64()).collect()),
                    _ => None,
                };
                let seed = b.u8().is_multiple_of(2).then(|| b.u64());
                engine
                    .reset_all(&mut obs, seed, seeds.as_deref())
                    .map(|()| obs)
            }
            2 => {
                let n = length(&mut b, robots * ACTION_SIZE);
                let actions: Vec<f32> = (0..n).map(|_| b.action()).collect();
                let mut obs = vec![0.0; length(&mut b, robots * size)];
                let mut rewards = vec![0.0; length(&mut b, robots)];
                engine
                    .step(world, &actions, &mut obs, &mut rewards)
                    .map(|_| {
                        check_rewards(&weights, &rewards);
                        obs
                    })
            }
            _ => {
                let n = length(&mut b, worlds * robots * ACTION_SIZE);
                let actions: Vec<f32> = (0..n).map(|_| b.action()).collect();
                let mut obs = vec![0.0; length(&mut b, worlds * robots * size)];
                let mut rewards = vec![0.0; length(&mut b, worlds * robots)];
                let mut terminated = vec![false; length(&mut b, worlds)];
                let mut truncated = vec![false; length(&mut b, worlds)];
                engine
                    .step_all(
                        &actions,
                        &mut obs,
                        &mut rewards,
                        &mut terminated,
                        &mut truncated,
                    )
                    .map(|()| {
                        check_rewards(&weights, &rewards);
                        obs
                    })
            }
        };
        match result {
            Ok(obs) => {
                check_vectors(engine.spec(), &obs);
                taken += 1;
            }
            Err(e) => check_refusal(&e),
        }
    }
    Reached::Built { calls: taken }
}

/// Finite rewards from weights of a sane size (a reward adds a few weights per step, so
/// weights near f64's limits may overflow it, as they would in any sum).
fn check_rewards(weights: &Rewards, rewards: &[f64]) {
    let sane = [weights.tag, weights.team_tag, weights.tick]
        .iter()
        .all(|w| w.abs() <= 1e12);
    if sane {
        assert!(
            rewards.iter().all(|r| r.is_finite()),
            "rewards {rewards:?} from weights {weights:?}"
        );
    }
}
