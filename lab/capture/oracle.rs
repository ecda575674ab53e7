//! The oracle belief (`--oracle-belief`): every tracker handed the truth each tick, which
//! bounds what a better search of the belief could gain.

use lasertag_core::world::World;
use nalgebra::Point2;

/// Puts every untagged role's cloud of every tracker on the nearest untagged opponent, at
/// full confidence: the planners then choose from a belief that is the truth.
pub(super) fn reveal_opponents(world: &mut World) {
    let truth: Vec<Point2<f32>> = world
        .opponents
        .iter()
        .filter(|o| !o.tagged)
        .map(|o| o.pose.pos)
        .collect();
    for tracker in &mut world.team.trackers {
        for role in tracker.roles.iter_mut().filter(|r| !r.tagged) {
            let centre = role.particles().first().copied().unwrap_or_default();
            let Some(&at) = truth.iter().min_by(|a, b| {
                (**a - centre)
                    .norm_squared()
                    .total_cmp(&(**b - centre).norm_squared())
            }) else {
                return;
            };
            let n = role.particles().len().max(1);
            role.reset(vec![at; n]);
            role.confidence = 1.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lasertag_core::sim::arena::Arena;
    use lasertag_core::world::MatchConfig;
    use std::sync::Arc;

    #[test]
    fn an_oracle_belief_puts_every_cloud_on_the_opponent() {
        use lasertag_core::sim::arena::MapDef;
        let arena = Arc::new(Arena::new(MapDef {
            name: "room".into(),
            width: 10.0,
            height: 6.0,
            obstacles: vec![],
            robot_spawns: vec![[1.0, 1.0, 0.0], [1.0, 2.0, 0.0]],
            opponent_spawns: vec![Point2::new(8.0, 4.0)],
            landmarks: vec![],
        }));
        let config = MatchConfig {
            robots: 2,
            opponents: 1,
            ..MatchConfig::default()
        };
        let mut world = World::new(arena, config).unwrap();
        world.step();
        let truth = world.opponents[0].pose.pos;
        let on_truth = |w: &World| {
            w.team.trackers.iter().all(|t| {
                t.roles
                    .iter()
                    .all(|r| !r.particles().is_empty() && r.particles().iter().all(|p| *p == truth))
            })
        };
        assert!(!on_truth(&world), "a fresh tracker guesses over the room");
        reveal_opponents(&mut world);
        assert!(on_truth(&world));
    }
}
