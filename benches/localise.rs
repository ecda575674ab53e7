//! One robot's localisation update on `office`: the odometry motion update plus the
//! measurement update (30 beams, landmarks, KLD resampling), at the filter's minimum and
//! maximum particle counts. And the per-map likelihood-field build, paid once per match.
//!
//! `cargo bench --bench localise`

use std::hint::black_box;
use std::path::Path;
use std::sync::Arc;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use lasertag::maps::MapStore;
use lasertag_core::localise::{LikelihoodField, Localiser, Observation, Settings};
use lasertag_core::sim::arena::Arena;
use lasertag_core::sim::{Physics, Pose, sensors};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn office() -> Arc<Arena> {
    let store = MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps")).unwrap();
    store.get("office").unwrap().arena.clone()
}

fn bench(c: &mut Criterion) {
    let arena = office();
    let physics = Physics::default();
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let truth = Pose::new(2.0, 8.0, 0.0);
    let scan = sensors::scan(
        &arena,
        &physics,
        &sensors::Laser::new(&physics),
        truth,
        &[],
        &mut rng,
    );
    let marks = sensors::sight_landmarks(&arena, &physics, truth, &mut rng);
    let mut group = c.benchmark_group("localise_update");
    for particles in [500usize, 2000] {
        let settings = Settings {
            min_particles: particles,
            max_particles: particles,
            // Update on every call, as a moving robot does.
            update_every: 1,
            ..Settings::default()
        };
        let field = Arc::new(LikelihoodField::new(&arena, &settings, physics.laser_range));
        let mut loc = Localiser::new(field, &arena, settings, truth, truth, &mut rng);
        let mut odom = truth;
        group.bench_with_input(
            BenchmarkId::from_parameter(particles),
            &particles,
            |b, _| {
                b.iter(|| {
                    odom.pos.x += 0.01;
                    loc.predict(odom);
                    let obs = Observation {
                        ranges: &scan.ranges,
                        laser_fov: physics.laser_fov,
                        laser_range: physics.laser_range,
                        landmarks: &marks,
                        movers: &[],
                    };
                    loc.correct(black_box(&obs), &mut rng);
                    black_box(loc.estimate())
                })
            },
        );
    }
    group.finish();
    c.bench_function("likelihood_field_build_office", |b| {
        b.iter(|| LikelihoodField::new(black_box(&arena), &Settings::default(), 8.0))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
