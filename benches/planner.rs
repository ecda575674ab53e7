//! One negotiation round of the coordinated planner on `office`: 4 robots choose one after
//! the other (one per tick) against a belief of 8 roles × 1,000 particles (the issue's
//! reference size), and one robot's turn alone; a travel field; and
//! building a map's view table (once per map and laser setting). A round is rare (every 3 s,
//! or when a robot needs a new goal) but runs inside a tick, so it must fit well within the
//! 50 ms budget. The cost of ordinary ticks is in `cargo bench --bench tick`.
//!
//! `cargo bench --bench planner`

use std::hint::black_box;
use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use lasertag::maps::MapStore;
use lasertag_core::planner::coordinated::{Coordinated, Settings};
use lasertag_core::planner::{RobotView, TeamView};
use lasertag_core::sim::arena::Arena;
use lasertag_core::sim::sensors::{self, Scan};
use lasertag_core::sim::{Physics, Pose};
use lasertag_core::tracker::{self, LaserModel, Sighting, Tracker};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn office() -> std::sync::Arc<Arena> {
    let store = MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps")).unwrap();
    store.get("office").unwrap().arena.clone()
}

fn planner(c: &mut Criterion) {
    let arena = office();
    let physics = Physics::default();
    let poses = [
        Pose::new(2.0, 8.0, 0.0),
        Pose::new(14.0, 8.0, 1.57),
        Pose::new(20.0, 8.0, 3.0),
        Pose::new(14.0, 12.0, -1.57),
    ];
    let laser = sensors::Laser::new(&physics);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let scans: Vec<Scan> = poses
        .iter()
        .map(|p| sensors::scan(&arena, &physics, &laser, *p, &[], &mut rng))
        .collect();
    // A belief shaped by a second of looking: 8 roles, the corridors' hypotheses gone.
    let mut tracker = Tracker::with_roles(
        &arena,
        tracker::Settings {
            merge: false,
            ..tracker::Settings::default()
        },
        &[1; 8],
        ChaCha8Rng::seed_from_u64(1),
    );
    let sightings: Vec<Sighting> = poses
        .iter()
        .zip(&scans)
        .map(|(pose, scan)| Sighting {
            pose: *pose,
            scan: &scan.ranges,
            detections: &[],
            tagged: false,
            age_ticks: 0,
        })
        .collect();
    let laser = LaserModel {
        fov: physics.laser_fov,
        range: physics.laser_range,
    };
    for _ in 0..20 {
        tracker.update(&arena, laser, &sightings);
    }
    let view = TeamView {
        tick: 1,
        robots: poses
            .iter()
            .zip(&scans)
            .map(|(pose, scan)| RobotView {
                pose: *pose,
                spread: 0.0,
                frozen: false,
                can_fire: true,
                scan: &scan.ranges,
                detections: &[],
                hit: false,
                outside: false,
            })
            .collect(),
    };
    // Build the map's view table outside the measurement (it is built once per map).
    let mut team = Coordinated::new(&arena, &physics, Settings::default(), 4);
    // A round is spread over 4 ticks, one robot choosing per tick: the whole round, and the
    // one tick of it (the first robot's turn) that a match pays at once.
    c.bench_function("negotiation_round/4r_8x1000_office", |b| {
        b.iter(|| {
            team.renegotiate();
            for _ in 0..4 {
                black_box(team.decide(&arena, &physics, &tracker, &view));
            }
        })
    });
    c.bench_function("negotiation_turn/4r_8x1000_office", |b| {
        b.iter(|| {
            team.renegotiate();
            black_box(team.decide(&arena, &physics, &tracker, &view))
        })
    });
    // The same turn by the `search` planner: the coordinated turn plus the look-ahead.
    let mut search = Coordinated::searching(&arena, &physics, Settings::default(), 4);
    c.bench_function("search_turn/4r_8x1000_office", |b| {
        b.iter(|| {
            search.renegotiate();
            black_box(search.decide(&arena, &physics, &tracker, &view))
        })
    });
    c.bench_function("search_travel_table_build/office", |b| {
        b.iter(|| {
            let views = lasertag_core::sim::views::ViewTable::build(
                &arena,
                Settings::default().view_spec(&arena, &physics),
            );
            black_box(
                lasertag_core::planner::coordinated::travel::PositionTravel::build(
                    &arena,
                    &views.positions,
                ),
            )
        })
    });
    c.bench_function("distance_field/office", |b| {
        b.iter(|| {
            black_box(lasertag_core::nav::DistanceField::from_point(
                &arena.grid,
                poses[0].pos,
            ))
        })
    });
    c.bench_function("view_table_build/office", |b| {
        b.iter(|| {
            black_box(lasertag_core::sim::views::ViewTable::build(
                &arena,
                Settings::default().view_spec(&arena, &physics),
            ))
        })
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20);
    targets = planner
}
criterion_main!(benches);
