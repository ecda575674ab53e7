//! Steps of the research environment's episode, one thread, no harness: what `perf record`
//! and `valgrind --tool=callgrind` profile (docs/performance.md, "Where a research step's
//! time goes"), and a check that an optimisation kept every number.
//!
//! The match is `lasertag_env`'s default (office, 2 robots driven by actions against a
//! `wander` bot, localisation on, one tick a step), at one of three settings:
//! `belief` (the team tracker at its default size, whose belief the observation carries:
//! `vector_env`'s default), `plain` (`team_tracker=False`) and `light` (also no localiser).
//! Episodes of 1,200 steps (the environments' `max_steps`) follow each other with seeds
//! 0, 1, 2, …; the robots' actions are random, as the benchmark's (`--actions`).
//!
//! `--worlds N` steps N episodes in turn, one step each, as each of `vector_env`'s threads
//! steps its worlds: how much a step slows when many worlds' state no longer fits the
//! caches.
//!
//! It prints the wall time a step and a checksum of every observation vector, reward and
//! world digest of the run: two builds that print the same checksum stepped the same
//! episodes bit for bit.
//!
//! ```text
//! cargo build --release --example env_profile
//! target/release/examples/env_profile --setting belief --steps 20000
//! valgrind --tool=callgrind --callgrind-out-file=/tmp/cg.out \
//!     target/release/examples/env_profile --steps 2000
//! callgrind_annotate --inclusive=yes /tmp/cg.out | head -60
//! ```

use std::path::Path;
use std::time::Instant;

use clap::{Parser, ValueEnum};
use lasertag::maps::store::MapStore;
use lasertag_core::env::{ACTION_SIZE, EnvSpec, Episode, Layout, Rewards};
use lasertag_core::planner::PlannerKind;
use lasertag_core::world::MatchConfig;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Setting {
    /// The team tracker at its default size and localisation on (`vector_env`'s default).
    Belief,
    /// The team tracker at its minimum (`team_tracker=False`).
    Plain,
    /// `plain` without the localiser (docs/research.md's "light" rows).
    Light,
}

#[derive(Parser)]
struct Args {
    #[arg(long, value_enum, default_value = "belief")]
    setting: Setting,
    /// Steps of the run, over as many 1,200-step episodes as it takes.
    #[arg(long, default_value_t = 20_000)]
    steps: u64,
    /// The robots' actions: uniform random values from a table of 64 steps, as
    /// `python/benchmarks/backends.py` steps them, or `roam` (forward and a slow turn, tag
    /// held, every step: as a policy that hunts moves).
    #[arg(long, value_enum, default_value = "random")]
    actions: Actions,
    /// Episodes stepped in turn, one step each.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=4096))]
    worlds: u64,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Actions {
    Random,
    Roam,
}

/// The environments' `max_steps`.
const EPISODE_STEPS: u64 = 1200;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let maps = MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps"))?;
    let arena = maps.get("office").ok_or("no office map")?.arena.clone();
    let mut config = MatchConfig {
        planner: PlannerKind::Api,
        localisation: !matches!(args.setting, Setting::Light),
        ..MatchConfig::default()
    };
    if !matches!(args.setting, Setting::Belief) {
        config.tracker.particles_per_role = 10;
    }
    let p = &config.physics;
    let layout = Layout::new(
        config.robots,
        config.opponents,
        arena.def.width as f64,
        arena.def.height as f64,
        p.laser_beams,
        p.laser_range as f64,
        (p.laser_fov as f64).to_degrees(),
    );
    let robots = config.robots;
    let spec = EnvSpec {
        config,
        layout,
        rewards: Rewards::default(),
        max_steps: Some(EPISODE_STEPS),
        ticks_per_step: 1,
    };
    let size = spec.layout.size();
    let mut obs = vec![0.0f32; robots * size];
    let mut rewards = vec![0.0f64; robots];
    let per_step = robots * ACTION_SIZE;
    let actions: Vec<f32> = match args.actions {
        Actions::Random => {
            let mut rng = ChaCha8Rng::seed_from_u64(0);
            (0..64 * per_step)
                .map(|_| rng.random_range(-1.0f32..1.0))
                .collect()
        }
        Actions::Roam => [0.8f32, 0.3, 1.0, 0.6, -0.2, 0.0]
            .into_iter()
            .cycle()
            .take(per_step)
            .collect(),
    };
    let mut table = actions.chunks_exact(per_step).cycle();
    // Worlds start with seeds 0..N; a world whose episode ends restarts with the next seed
    // not yet used.
    let mut seed = args.worlds;
    let mut episodes = (0..args.worlds)
        .map(|s| Episode::new(arena.clone(), &spec, s))
        .collect::<Result<Vec<_>, _>>()?;
    let mut sum = Checksum::default();
    let start = Instant::now();
    for step in 0..args.steps {
        let episode = &mut episodes[(step % args.worlds) as usize];
        let step_actions = table.next().ok_or("no actions")?;
        let out = episode.step(&spec, step_actions, &mut obs, &mut rewards);
        sum.add(obs.iter().map(|v| v.to_bits() as u64));
        sum.add(rewards.iter().map(|r| r.to_bits()));
        if out.terminated || out.truncated {
            sum.add([episode.world().digest()]);
            *episode = Episode::new(arena.clone(), &spec, seed)?;
            seed += 1;
        }
    }
    let elapsed = start.elapsed();
    sum.add(episodes.iter().map(|e| e.world().digest()));
    println!(
        "{:?}, {} world(s): {} steps, {:.1} µs a step, checksum {:016x}",
        args.setting,
        args.worlds,
        args.steps,
        elapsed.as_secs_f64() * 1e6 / args.steps as f64,
        sum.0
    );
    Ok(())
}

/// FNV-1a over 64-bit words: order-sensitive, and enough to tell two runs apart.
struct Checksum(u64);

impl Default for Checksum {
    fn default() -> Self {
        Checksum(0xcbf2_9ce4_8422_2325)
    }
}

impl Checksum {
    fn add(&mut self, words: impl IntoIterator<Item = u64>) {
        for w in words {
            self.0 = (self.0 ^ w).wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
}
