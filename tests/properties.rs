//! Property tests over random matches: the invariants that must hold at every tick.

use std::path::Path;
use std::sync::{Arc, OnceLock};

use lasertag::maps::MapStore;
use lasertag::planner::PlannerKind;
use lasertag::sim::bots::BotKind;
use lasertag::sim::world::{MatchConfig, Placement};
use lasertag::sim::{AGENT_RADIUS, World};
use proptest::prelude::*;

fn maps() -> &'static MapStore {
    static MAPS: OnceLock<MapStore> = OnceLock::new();
    MAPS.get_or_init(|| {
        MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps")).unwrap()
    })
}

fn arena(k: usize) -> Arc<lasertag::sim::arena::Arena> {
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
            tracker: lasertag::tracker::Settings { particles_per_role: 200, ..Default::default() },
            ..MatchConfig::default()
        };
        let mut world = World::new(arena(map), config).unwrap();
        for _ in 0..600 {
            world.step();
            let untagged = world.opponents.iter().filter(|o| !o.tagged).count() as u32;
            prop_assert_eq!(world.team.trackers[0].untagged_count(), untagged, "tick {}", world.tick);
            for role in world.team.trackers[0].roles.iter().filter(|r| !r.tagged) {
                let sum: f32 = role.weights.iter().sum();
                prop_assert!(role.weights.iter().all(|w| w.is_finite() && *w >= 0.0));
                prop_assert!((sum - 1.0).abs() < 1e-3, "weights sum to {}", sum);
                prop_assert_eq!(role.weights.len(), role.particles.len());
            }
            let discs: Vec<_> = world.robots.iter().map(|r| r.pose.pos)
                .chain(world.opponents.iter().filter(|o| !o.tagged).map(|o| o.pose.pos))
                .collect();
            for (i, a) in discs.iter().enumerate() {
                prop_assert!(world.arena.clearance(*a) >= AGENT_RADIUS - 1e-3, "disc {} in a wall at {:?}", i, a);
                for b in &discs[i + 1..] {
                    prop_assert!((a - b).norm() >= 2.0 * AGENT_RADIUS - 1e-3);
                }
            }
            if world.status == lasertag::sim::MatchStatus::Finished {
                break;
            }
        }
    }
}
