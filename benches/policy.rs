//! What a trained policy costs a match per robot (docs/performance.md, "Trained policies"):
//! one robot's observation (scan, teammates and the belief features read off its tracker's
//! particles) encoded into the research environment's vector, one inference of the shipped
//! model, and the two together as the server runs them (`TeamPolicy::orders` for a team of
//! 2 on a decision tick), on `office` after a few seconds of play.
//!
//! `cargo bench --bench policy`

use std::hint::black_box;
use std::path::Path;
use std::sync::Arc;

use criterion::{Criterion, criterion_group, criterion_main};
use lasertag::maps::MapStore;
use lasertag_core::planner::PlannerKind;
use lasertag_core::world::{MatchConfig, World};
use lasertag_policy::{Limits, Policy, TeamPolicy};

fn world() -> World {
    let store = MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps")).unwrap();
    let arena = store.get("office").unwrap().arena.clone();
    let mut w = World::new(
        arena,
        MatchConfig {
            planner: PlannerKind::Api,
            policy: Some("learned".into()),
            seed: 7,
            ..MatchConfig::default()
        },
    )
    .unwrap();
    // A few seconds in: the tracker's clouds have spread and moved.
    for _ in 0..100 {
        w.step();
    }
    w
}

fn bench(c: &mut Criterion) {
    let w = world();
    let policy = Arc::new(
        Policy::from_onnx(
            lasertag_policy::shipped("learned").unwrap(),
            &Limits::default(),
        )
        .unwrap(),
    );
    let mut team = TeamPolicy::new(policy.clone(), &w.arena, 2, &w.config.physics, 1).unwrap();
    c.bench_function("policy/observation (one robot, belief included)", |b| {
        b.iter(|| black_box(w.observation(0)))
    });
    let observation = vec![0.1f32; policy.input_len()];
    let (mut action, mut scratch) = (Vec::new(), Vec::new());
    c.bench_function("policy/inference (shipped model)", |b| {
        b.iter(|| {
            policy
                .infer(black_box(&observation), &mut action, &mut scratch)
                .unwrap();
            black_box(&action);
        })
    });
    c.bench_function("policy/orders (team of 2, a decision tick)", |b| {
        b.iter(|| black_box(team.orders(&w)))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
