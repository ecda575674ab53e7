//! Property tests over random matches: the invariants that must hold at every tick.

use std::path::Path;
use std::sync::{Arc, OnceLock};

use lasertag::maps::{self, MapFile, MapStore};
use lasertag_core::bots::BotKind;
use lasertag_core::planner::PlannerKind;
use lasertag_core::sim::AGENT_RADIUS;
use lasertag_core::world::World;
use lasertag_core::world::{MatchConfig, Placement};
use proptest::prelude::*;

fn maps() -> &'static MapStore {
    static MAPS: OnceLock<MapStore> = OnceLock::new();
    MAPS.get_or_init(|| {
        MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps")).unwrap()
    })
}

/// Checks the core's invariants (ARCHITECTURE.md, Invariants) on `world` after a tick.
fn check(world: &World) -> Result<(), TestCaseError> {
    let untagged = world.opponents.iter().filter(|o| !o.tagged).count() as u32;
    prop_assert_eq!(
        world.team.trackers[0].untagged_count(),
        untagged,
        "tick {}",
        world.tick
    );
    // Every robot's tracker (one shared tracker unless the radio is imperfect).
    for role in world
        .team
        .trackers
        .iter()
        .flat_map(|t| t.roles.iter())
        .filter(|r| !r.tagged)
    {
        let sum: f32 = role.weights().iter().sum();
        prop_assert!(role.weights().iter().all(|w| w.is_finite() && *w >= 0.0));
        prop_assert!((sum - 1.0).abs() < 1e-3, "weights sum to {}", sum);
        prop_assert_eq!(role.weights().len(), role.particles().len());
    }
    let discs: Vec<_> = world
        .robots
        .iter()
        .map(|r| r.pose.pos)
        .chain(
            world
                .opponents
                .iter()
                .filter(|o| !o.tagged)
                .map(|o| o.pose.pos),
        )
        .collect();
    for (i, a) in discs.iter().enumerate() {
        prop_assert!(
            world.arena.clearance(*a) >= AGENT_RADIUS - 1e-3,
            "disc {} in a wall at {:?}",
            i,
            a
        );
        for b in &discs[i + 1..] {
            prop_assert!((a - b).norm() >= 2.0 * AGENT_RADIUS - 1e-3);
        }
    }
    Ok(())
}

/// A random arena: a `w` × `h` room with axis-aligned boxes (which may overlap or cut the
/// room in two) and spawns at the given points that the map validator accepts.
fn random_map(
    w: f64,
    h: f64,
    boxes: &[(f64, f64, f64, f64)],
    points: &[(f64, f64)],
) -> Option<Arc<lasertag_core::sim::arena::Arena>> {
    let obstacles: Vec<Vec<[f64; 2]>> = boxes
        .iter()
        .map(|&(x, y, bw, bh)| {
            let (x0, y0) = (x * w, y * h);
            let (x1, y1) = ((x0 + bw).min(w), (y0 + bh).min(h));
            vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
        })
        .filter(|p| p[1][0] - p[0][0] > 0.05 && p[2][1] - p[1][1] > 0.05)
        .collect();
    let mut file = MapFile {
        name: "random".into(),
        width: w,
        height: h,
        obstacles,
        robot_spawns: vec![],
        opponent_spawns: vec![],
        landmarks: points.iter().map(|&(x, y)| [x * w, y * h]).collect(),
    };
    // Keep the points the validator accepts as spawns (clear of walls and boxes).
    for &(x, y) in points {
        let mut probe = file.clone();
        probe.robot_spawns = vec![[x * w, y * h, 0.0]];
        probe.opponent_spawns = vec![[x * w, y * h]];
        if maps::validate(&probe).is_ok() {
            file.robot_spawns.push([x * w, y * h, 0.0]);
            file.opponent_spawns.push([x * w, y * h]);
        }
    }
    let def = maps::validate(&file).ok()?;
    Some(Arc::new(lasertag_core::sim::arena::Arena::new(def)))
}

fn arena(k: usize) -> Arc<lasertag_core::sim::arena::Arena> {
    let all: Vec<_> = maps().iter().collect();
    all[k % all.len()].arena.clone()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    /// Role counts always sum to the untagged opponents; belief weights stay finite and
    /// normalised; no agent overlaps a wall or another agent.
    #[test]
    fn invariants_hold_at_every_tick(
        map in 0usize..4,
        robots in 1usize..=4,
        opponents in 1usize..=5,
        evade in any::<bool>(),
        seed in any::<u64>(),
    ) {
        let config = MatchConfig {
            robots,
            opponents,
            opponent_bot: if evade { BotKind::Evade } else { BotKind::Wander },
            planner: PlannerKind::Baseline,
            placement: Placement::Random,
            seed,
            tracker: lasertag_core::tracker::Settings { particles_per_role: 200, ..Default::default() },
            ..MatchConfig::default()
        };
        let mut world = World::new(arena(map), config).unwrap();
        for _ in 0..600 {
            world.step();
            check(&world)?;
            if world.status == lasertag_core::world::MatchStatus::Finished {
                break;
            }
        }
    }

    /// The same invariants on arenas nobody drew, with the coordinated planner, localisation,
    /// every bot kind, random tracker settings and random starts.
    #[test]
    fn invariants_hold_on_random_arenas(
        w in 6.0f64..25.0,
        h in 5.0f64..18.0,
        boxes in proptest::collection::vec((0.0f64..1.0, 0.0f64..1.0, 0.3f64..6.0, 0.3f64..6.0), 0..6),
        points in proptest::collection::vec((0.05f64..0.95, 0.05f64..0.95), 4..12),
        robots in 1usize..=3,
        opponents in 1usize..=4,
        bot in 0usize..3,
        coordinated in any::<bool>(),
        localisation in any::<bool>(),
        merge in any::<bool>(),
        merge_interval in 1u64..40,
        particles in 50usize..300,
        seed in any::<u64>(),
    ) {
        let Some(arena) = random_map(w, h, &boxes, &points) else {
            return Err(TestCaseError::reject("no valid spawn"));
        };
        let config = MatchConfig {
            robots,
            opponents,
            opponent_bot: [BotKind::Wander, BotKind::Evade, BotKind::Idle][bot],
            planner: if coordinated { PlannerKind::Coordinated } else { PlannerKind::Baseline },
            placement: Placement::Random,
            localisation,
            seed,
            tracker: lasertag_core::tracker::Settings {
                particles_per_role: particles,
                merge,
                merge_interval,
                ..Default::default()
            },
            ..MatchConfig::default()
        };
        // Random placement needs room for every agent in one connected space; a map that
        // has none is refused with an error, which is not what this test is about.
        let Ok(mut world) = World::new(arena, config) else {
            return Err(TestCaseError::reject("no room for the agents"));
        };
        for _ in 0..300 {
            world.step();
            check(&world)?;
            if world.status == lasertag_core::world::MatchStatus::Finished {
                break;
            }
        }
    }
}
