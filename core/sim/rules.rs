//! The referee's rules for tag devices: cone, range, line of sight, first agent hit.

use nalgebra::Point2;

use crate::sim::arena::Arena;
use crate::sim::{AGENT_RADIUS, AgentId, Physics, Pose};

/// The agent a shot from `shooter` hits, if any: the nearest agent whose centre is within
/// `tag_range` and `tag_half_angle` of the shooter's heading, with no wall in between.
/// A nearer agent in the cone shields those behind it, teammates included.
pub fn shot_target(
    arena: &Arena,
    physics: &Physics,
    shooter: Pose,
    others: &[(AgentId, Point2<f32>)],
) -> Option<AgentId> {
    others
        .iter()
        .filter_map(|(id, c)| {
            let d = (c - shooter.pos).norm();
            let in_cone = d <= physics.tag_range
                && (d < AGENT_RADIUS || shooter.bearing_to(*c).abs() <= physics.tag_half_angle);
            (in_cone && arena.line_of_sight(shooter.pos, *c)).then_some((d, *id))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
        .map(|(_, id)| id)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::arena::MapDef;

    fn arena() -> Arena {
        Arena::new(MapDef {
            name: "t".into(),
            width: 20.0,
            height: 10.0,
            obstacles: vec![vec![
                Point2::new(10.0, 0.0),
                Point2::new(10.2, 0.0),
                Point2::new(10.2, 4.0),
                Point2::new(10.0, 4.0),
            ]],
            robot_spawns: vec![[1.0, 1.0, 0.0]],
            opponent_spawns: vec![Point2::new(19.0, 9.0)],
            landmarks: vec![],
        })
    }

    #[test]
    fn cone_range_line_of_sight_and_first_hit() {
        let a = arena();
        let p = Physics::default();
        let me = Pose::new(5.0, 2.0, 0.0);
        let o = |x, y| (AgentId::Opponent(0), Point2::new(x, y));
        assert_eq!(
            shot_target(&a, &p, me, &[o(9.0, 2.0)]),
            Some(AgentId::Opponent(0))
        );
        assert_eq!(shot_target(&a, &p, me, &[o(9.0, 2.6)]), None, "outside ±5°");
        assert_eq!(
            shot_target(&a, &p, me, &[o(11.5, 2.0)]),
            None,
            "beyond 6 m and behind a wall"
        );
        let far = (AgentId::Opponent(1), Point2::new(8.0, 6.5));
        let up = Pose::new(8.0, 1.0, std::f32::consts::FRAC_PI_2);
        assert_eq!(shot_target(&a, &p, up, &[far]), Some(AgentId::Opponent(1)));
        let shield = (AgentId::Robot(1), Point2::new(8.0, 3.0));
        assert_eq!(
            shot_target(&a, &p, up, &[far, shield]),
            Some(AgentId::Robot(1))
        );
    }
}
