//! One tick of a match on `office` — `baseline` and `coordinated` with 2 robots and 2
//! wandering opponents, and `coordinated` at the planning size (4 robots, 8
//! opponents) — averaged over ticks with and without negotiation rounds, with the robots
//! localising and with odometry alone; one robot's laser scan alone, so the share of ray
//! casting in a tick can be read off; and one step of the research environment's episode
//! (the in-process engine's unit of work), with the default and the light settings; and
//! what a checkpoint costs (clone on the match's task, encode, restore).
//!
//! `cargo bench --bench tick`

use std::hint::black_box;
use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use lasertag::maps::MapStore;
use lasertag_core::planner::PlannerKind;
use lasertag_core::sim::sensors;
use lasertag_core::sim::{AgentId, Physics};
use lasertag_core::world::{MatchConfig, Placement};
use lasertag_core::world::{MatchStatus, World};
use rand::SeedableRng;

fn office_world(
    seed: u64,
    planner: PlannerKind,
    robots: usize,
    opponents: usize,
    localisation: bool,
) -> World {
    let store = MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps")).unwrap();
    let arena = store.get("office").unwrap().arena.clone();
    let config = MatchConfig {
        robots,
        opponents,
        planner,
        placement: Placement::Random,
        time_limit_ticks: u64::MAX,
        seed,
        localisation,
        ..MatchConfig::default()
    };
    World::new(arena, config).unwrap()
}

/// A match that is mid-game after 10 s (paths planned, robots moving, opponents at large).
fn mid_game(
    planner: PlannerKind,
    robots: usize,
    opponents: usize,
    localisation: bool,
) -> (World, World) {
    (1..)
        .find_map(|seed| {
            let initial = office_world(seed, planner, robots, opponents, localisation);
            let mut start = initial.clone();
            for _ in 0..200 {
                start.step();
            }
            (start.status == MatchStatus::Running).then_some((initial, start))
        })
        .unwrap()
}

fn tick(c: &mut Criterion) {
    // Every robot localising (the default), then the same matches without the localiser
    // (each robot's estimate its odometry): the difference, divided by the robots, is what a
    // robot's localiser costs a tick on average (it updates every 0.2 m or π/6 of motion,
    // not every tick).
    use PlannerKind::{Baseline, Coordinated, Search};
    for (name, planner, robots, opponents, localisation) in [
        ("tick/baseline_office_2r_2o", Baseline, 2, 2, true),
        ("tick/coordinated_office_2r_2o", Coordinated, 2, 2, true),
        ("tick/coordinated_office_4r_8o", Coordinated, 4, 8, true),
        (
            "tick/coordinated_office_2r_2o_odometry",
            Coordinated,
            2,
            2,
            false,
        ),
        (
            "tick/coordinated_office_4r_8o_odometry",
            Coordinated,
            4,
            8,
            false,
        ),
        ("tick/search_office_2r_2o_odometry", Search, 2, 2, false),
    ] {
        let (_, start) = mid_game(planner, robots, opponents, localisation);
        let mut world = start.clone();
        c.bench_function(name, |b| {
            b.iter(|| {
                if world.status == MatchStatus::Finished {
                    world = start.clone();
                }
                world.step();
                black_box(world.tick)
            })
        });
    }

    let (initial, _) = mid_game(Baseline, 2, 2, true);
    let physics = Physics::default();
    let robot = initial.robots[0].pose;
    let others: Vec<_> = initial
        .opponents
        .iter()
        .enumerate()
        .map(|(i, o)| (AgentId::Opponent(i), o.pose.pos))
        .chain(std::iter::once((
            AgentId::Robot(1),
            initial.robots[1].pose.pos,
        )))
        .collect();
    let laser = sensors::Laser::new(&physics);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    c.bench_function("scan/one_robot_181_beams", |b| {
        b.iter(|| {
            black_box(sensors::scan(
                &initial.arena,
                &physics,
                &laser,
                robot,
                &others,
                &mut rng,
            ))
        })
    });
}

/// What a checkpoint costs a running match: its task clones the world once every 600 ticks
/// (`checkpoint/clone_*`, on the match's task); the store's writer thread turns the clone
/// into deflated bytes (`checkpoint/encode_*`); a resume restores them into a fresh world
/// (`checkpoint/restore_*`). The largest calibration-like world: coordinated, 4 robots
/// localising, 8 opponents, 10 s into play.
fn checkpoint(c: &mut Criterion) {
    let (initial, start) = mid_game(PlannerKind::Coordinated, 4, 8, true);
    c.bench_function("checkpoint/clone_office_4r_8o", |b| {
        b.iter(|| black_box(start.clone()))
    });
    c.bench_function("checkpoint/encode_office_4r_8o", |b| {
        b.iter(|| black_box(lasertag::store::codec::encode_checkpoint(&start, u64::MAX)))
    });
    let bytes = lasertag::store::codec::encode_checkpoint(&start, u64::MAX).unwrap();
    c.bench_function("checkpoint/restore_office_4r_8o", |b| {
        b.iter(|| {
            let fresh = World::new(initial.arena.clone(), initial.config.clone()).unwrap();
            black_box(lasertag::store::codec::decode_checkpoint(fresh, &bytes).unwrap())
        })
    });
}

/// One step of the research environment's episode (`core::env`, what `lasertag_env`'s
/// in-process engine runs): office, 2 robots driven by actions against a `wander` bot,
/// observations packed. `belief` is the environments' default: every robot localising and
/// the team tracker at its default size, whose belief the observation carries. The plain
/// row has the tracker at its minimum (`team_tracker=False`); `light` also turns the
/// localiser off (each robot's estimate its odometry), the settings of docs/research.md's
/// "light" rows.
fn env_step(c: &mut Criterion) {
    use lasertag_core::env::{EnvSpec, Episode, Layout, Rewards};
    let store = MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps")).unwrap();
    let arena = store.get("office").unwrap().arena.clone();
    for (name, localisation, belief) in [
        ("env/step_office_2r_1o_belief", true, true),
        ("env/step_office_2r_1o", true, false),
        ("env/step_office_2r_1o_light", false, false),
    ] {
        let mut config = MatchConfig {
            planner: PlannerKind::Api,
            localisation,
            ..MatchConfig::default()
        };
        if !belief {
            config.tracker.particles_per_role = 10;
        }
        let p = &config.physics;
        let layout = Layout::new(
            2,
            3,
            arena.def.width as f64,
            arena.def.height as f64,
            p.laser_beams,
            p.laser_range as f64,
            (p.laser_fov as f64).to_degrees(),
        );
        let spec = EnvSpec {
            config,
            layout,
            rewards: Rewards::default(),
            max_steps: None,
            ticks_per_step: 1,
        };
        let size = spec.layout.size();
        let mut obs = vec![0.0f32; 2 * size];
        let mut rewards = vec![0.0f64; 2];
        // Forward and a slow turn, tag held: the robots roam and fire as a policy's would.
        let actions = [0.8f32, 0.3, 1.0, 0.6, -0.2, 0.0];
        let mut seed = 0;
        let mut episode = Episode::new(arena.clone(), &spec, seed).unwrap();
        c.bench_function(name, |b| {
            b.iter(|| {
                let out = episode.step(&spec, &actions, &mut obs, &mut rewards);
                if out.terminated || out.truncated {
                    seed += 1;
                    episode = Episode::new(arena.clone(), &spec, seed).unwrap();
                }
                black_box(obs[0])
            })
        });
    }
}

criterion_group!(benches, tick, checkpoint, env_step);
criterion_main!(benches);
