//! One tracker update (motion, negative and positive information, resampling) on `office`,
//! at the reference size (4 robots × 8 roles × 1,000 particles) and around it, so the
//! growth with particles, roles and robots can be read off. And one merge check of 8 roles,
//! which runs every `merge_interval` ticks.
//!
//! `cargo bench --bench tracker`

use std::hint::black_box;
use std::path::Path;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use lasertag::maps::MapStore;
use lasertag_core::sim::arena::Arena;
use lasertag_core::sim::sensors::{self, Scan};
use lasertag_core::sim::{Physics, Pose};
use lasertag_core::tracker::{LaserModel, Settings, Sighting, Tracker};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn office() -> std::sync::Arc<Arena> {
    let store = MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps")).unwrap();
    store.get("office").unwrap().arena.clone()
}

/// Robots spread along the office's corridors, facing different ways, with real scans.
fn scans(arena: &Arena, robots: usize) -> Vec<(Pose, Scan)> {
    let poses = [
        Pose::new(2.0, 8.0, 0.0),
        Pose::new(14.0, 8.0, 1.57),
        Pose::new(20.0, 8.0, 3.0),
        Pose::new(14.0, 12.0, -1.57),
        Pose::new(8.0, 8.0, 0.0),
        Pose::new(17.0, 8.0, 3.0),
        Pose::new(14.0, 14.0, -1.57),
        Pose::new(5.0, 8.0, 0.0),
    ];
    let physics = Physics::default();
    let laser = sensors::Laser::new(&physics);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    poses
        .iter()
        .cycle()
        .take(robots)
        .map(|p| {
            (
                *p,
                sensors::scan(arena, &physics, &laser, *p, &[], &mut rng),
            )
        })
        .collect()
}

fn update(
    c: &mut Criterion,
    arena: &Arena,
    name: &str,
    robots: usize,
    roles: usize,
    particles: usize,
) {
    let settings = Settings {
        particles_per_role: particles,
        merge: false,
        ..Settings::default()
    };
    let mut tracker = Tracker::with_roles(
        arena,
        settings,
        &vec![1; roles],
        ChaCha8Rng::seed_from_u64(1),
    );
    let scans = scans(arena, robots);
    let sightings: Vec<Sighting> = scans
        .iter()
        .map(|(pose, scan)| Sighting {
            pose: *pose,
            scan: &scan.ranges,
            detections: &[],
            tagged: false,
            age_ticks: 0,
        })
        .collect();
    let laser = LaserModel {
        fov: std::f32::consts::PI,
        range: 8.0,
    };
    c.bench_with_input(
        BenchmarkId::new(name, format!("{robots}r_{roles}x{particles}")),
        &(),
        |b, _| b.iter(|| black_box(tracker.update(arena, laser, &sightings))),
    );
}

fn tracker(c: &mut Criterion) {
    let arena = office();
    update(c, &arena, "update", 4, 8, 1000);
    for particles in [250, 4000] {
        update(c, &arena, "update_particles", 4, 8, particles);
    }
    for roles in [2, 16] {
        update(c, &arena, "update_roles", 4, roles, 1000);
    }
    for robots in [1, 8] {
        update(c, &arena, "update_robots", robots, 8, 1000);
    }
    let settings = Settings {
        merge_interval: 1,
        kl_cutoff: 0.0, // never merges: measures the check alone
        ..Settings::default()
    };
    let mut tracker = Tracker::with_roles(&arena, settings, &[1; 8], ChaCha8Rng::seed_from_u64(2));
    let laser = LaserModel {
        fov: 0.0,
        range: 0.0,
    };
    c.bench_function("update_with_merge_check/0r_8x1000", |b| {
        b.iter(|| black_box(tracker.update(&arena, laser, &[])))
    });
}

criterion_group!(benches, tracker);
criterion_main!(benches);
