//! Chasing a detected opponent: turn to it, close in, fire once it is inside the tag cone.
//!
//! A shot flies from the shooter's centre to the target's (`sim::rules::shot_target`), but
//! the laser sees any part of a disc: an opponent standing just past a wall's corner is seen
//! and cannot be hit from where the robot stands. [`engage`] then walks around the corner
//! rather than aiming and missing until the match ends.
//!
//! [`engage`] is the plain rule every planner uses. The coordinated planner wraps it in
//! [`engage_looking_ahead`], Fabiani & Latombe's one-step decision: of a few candidate
//! motions it takes the one most likely to keep the opponent in view ([`keeps_in_view`]),
//! given where the opponent may go and how unsure the robot is of its own position.

use nalgebra::{Point2, Vector2};

use crate::nav::{path_within, steer, turn_to};
use crate::planner::view::RobotView;
use crate::sim::arena::Arena;
use crate::sim::motion::propose;
use crate::sim::sensors::detection_point;
use crate::sim::{AGENT_RADIUS, DT, Motion, Physics, Pose, wrap_angle};

/// Range the pursuer closes to before it stops driving: well inside the 6 m tag range so a
/// target that steps away is still hittable.
const CLOSE_RANGE: f32 = 2.5;

/// The nearest detection of this robot, as a world point and its bearing.
pub fn nearest_sighting(robot: &RobotView) -> Option<(Point2<f32>, f32, f32)> {
    robot
        .detections
        .iter()
        .min_by(|a, b| a.range.total_cmp(&b.range))
        .map(|d| (detection_point(robot.pose, d), d.range, d.bearing))
}

/// Grid rings around a seen opponent searched for a cell to walk to: its own cell is
/// passable unless the estimate put it in a wall.
const TARGET_CELL_RINGS: usize = 2;

/// Where a robot at `from` walks to get a clear shot at `target`, when a wall stands on the
/// line between them: the first corner of the way there. `None` when the line is clear (or
/// there is no way).
pub(crate) fn around_the_corner(
    arena: &Arena,
    from: Point2<f32>,
    target: Point2<f32>,
) -> Option<Point2<f32>> {
    if arena.line_of_sight(from, target) {
        return None;
    }
    let grid = &arena.grid;
    let goal = grid.nearest_passable(target, TARGET_CELL_RINGS)?;
    // The target is within the laser's range: the search settles a few metres of grid,
    // and runs only while a wall hides the target's centre.
    let mut unbounded = u64::MAX;
    let path = path_within(grid, from, goal, &mut unbounded).ok()??;
    path.into_iter().skip(1).find(|p| (p - from).norm() > 0.1)
}

/// Motion and trigger for a robot that sees an opponent at `range`, `bearing`.
pub fn engage(
    arena: &Arena,
    robot: &RobotView,
    physics: &Physics,
    target: Point2<f32>,
    range: f32,
    bearing: f32,
) -> (Motion, bool) {
    if let Some(corner) = around_the_corner(arena, robot.pose.pos, target) {
        // Every shot from here would hit the wall.
        return (steer(robot.pose, corner, physics.robot_turn_rate), false);
    }
    // Fire a little inside the device's limits: detections are noisy.
    let fire = robot.can_fire
        && range <= physics.tag_range - 0.3
        && bearing.abs() <= physics.tag_half_angle * 0.7;
    let motion = if range > CLOSE_RANGE {
        steer(robot.pose, target, physics.robot_turn_rate)
    } else {
        let d = target - robot.pose.pos;
        turn_to(robot.pose, d.y.atan2(d.x), physics.robot_turn_rate)
    };
    (motion, fire)
}

/// Motions the look-ahead weighs besides [`engage`]'s own: forward at none, half and full
/// speed, each turning hard either way or not at all.
const LOOKAHEAD_FORWARD: [f32; 3] = [0.0, 0.5, 1.0];
const LOOKAHEAD_TURN: [f32; 3] = [-1.0, 0.0, 1.0];
/// How much likelier another motion must keep the target in view before it replaces
/// [`engage`]'s: closing in and facing the target is what tags it, so only a clear gain in
/// visibility is worth a detour.
const LOOKAHEAD_MARGIN: f32 = 0.1;
/// Bearings this close to the edge of the laser's field of view count as out of it: a
/// detection there is the first to be lost to noise.
const FOV_MARGIN: f32 = 0.1;

/// [`engage`] with Fabiani & Latombe's one-step look-ahead: besides `engage`'s motion the
/// robot weighs a few others, each held for `horizon` seconds, by the probability that it
/// still sees the target afterwards ([`keeps_in_view`]), and takes the best when it beats
/// `engage`'s by [`LOOKAHEAD_MARGIN`]. A robot within tag range (about to fire, or aiming
/// while its device cools down) keeps `engage`'s motion, and a `horizon` of 0 is plain
/// `engage`. Deterministic: the probability is a fixed quadrature,
/// not a sample.
pub fn engage_looking_ahead(
    arena: &Arena,
    robot: &RobotView,
    physics: &Physics,
    horizon: f32,
    (target, range, bearing): (Point2<f32>, f32, f32),
) -> (Motion, bool) {
    let (plain, fire) = engage(arena, robot, physics, target, range, bearing);
    // Within tag range the plain rule aims, and aim is what tags (also while the device
    // cools down: a detour then spoils the next shot).
    if horizon <= 0.0 || fire || range <= physics.tag_range - 0.3 {
        return (plain, fire);
    }
    let keep =
        |m: Motion| keeps_in_view(arena, physics, robot.pose, robot.spread, target, m, horizon);
    let p_plain = keep(plain);
    let mut best = (plain, p_plain);
    for forward in LOOKAHEAD_FORWARD {
        for turn in LOOKAHEAD_TURN {
            let m = Motion::Drive { forward, turn };
            let p = keep(m);
            if p > best.1 {
                best = (m, p);
            }
        }
    }
    if best.1 > p_plain + LOOKAHEAD_MARGIN {
        (best.0, fire)
    } else {
        (plain, fire)
    }
}

/// Probability that a robot at `pose`, position uncertain by `spread` (m, std-dev), still
/// sees the opponent now at `target` after holding `motion` for `horizon` seconds.
///
/// The quadrature: the robot's true position is its estimate or one `spread` off along
/// either axis (weights 1/3 and 1/6 each); the opponent stays or walks `horizon` at top speed
/// in one of 8 directions, wherever it could walk (weights equal). The detection is relative,
/// so an error in the robot's position shifts the opponent with it: what the error changes
/// is where the walls are, which may hide the opponent or stop the robot. A sample counts as
/// seen when the robot is clear of walls there and the opponent is within range, inside the
/// field of view (less [`FOV_MARGIN`]) and in line of sight. A motion whose nominal path
/// runs into a wall scores 0.
pub fn keeps_in_view(
    arena: &Arena,
    physics: &Physics,
    pose: Pose,
    spread: f32,
    target: Point2<f32>,
    motion: Motion,
    horizon: f32,
) -> f32 {
    let ticks = (horizon / DT).round().max(1.0) as usize;
    let mut next = pose;
    for _ in 0..ticks {
        next = propose(next, motion, physics.robot_speed, physics.robot_turn_rate);
        if !arena.disc_is_free(next.pos, AGENT_RADIUS) {
            return 0.0;
        }
    }
    let reach = physics.opponent_speed * ticks as f32 * DT;
    let mut moves: Vec<Vector2<f32>> = vec![Vector2::zeros()];
    for k in 0..8 {
        let a = k as f32 * std::f32::consts::FRAC_PI_4;
        let d = Vector2::new(a.cos(), a.sin()) * reach;
        let q = target + d;
        if arena.disc_is_free(q, AGENT_RADIUS) && arena.line_of_sight(target, q) {
            moves.push(d);
        }
    }
    let offsets: &[(Vector2<f32>, f32)] = if spread > 0.0 {
        &[
            (Vector2::new(0.0, 0.0), 1.0 / 3.0),
            (Vector2::new(spread, 0.0), 1.0 / 6.0),
            (Vector2::new(-spread, 0.0), 1.0 / 6.0),
            (Vector2::new(0.0, spread), 1.0 / 6.0),
            (Vector2::new(0.0, -spread), 1.0 / 6.0),
        ]
    } else {
        &[(Vector2::new(0.0, 0.0), 1.0)]
    };
    let half_fov = physics.laser_fov * 0.5 - FOV_MARGIN;
    let mut p = 0.0;
    for &(o, w) in offsets {
        let at = next.pos + o;
        if !arena.disc_is_free(at, AGENT_RADIUS) {
            continue; // it would be in a wall: stopped, and lost
        }
        let seen = moves
            .iter()
            .filter(|&&d| {
                let q = target + d + o;
                let rel = q - at;
                rel.norm() <= physics.laser_range
                    && wrap_angle(rel.y.atan2(rel.x) - next.theta).abs() <= half_fov
                    && arena.line_of_sight(at, q)
            })
            .count();
        p += w * seen as f32 / moves.len() as f32;
    }
    p
}

/// The goal shown while pursuing: the target, facing it.
pub fn pursuit_goal(from: Pose, target: Point2<f32>) -> Pose {
    let d = target - from.pos;
    Pose {
        pos: target,
        theta: d.y.atan2(d.x),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::arena::MapDef;
    use crate::sim::sensors::Detection;

    /// An open 12 m × 6 m room.
    fn room() -> Arena {
        Arena::new(MapDef {
            name: "room".into(),
            width: 12.0,
            height: 6.0,
            obstacles: vec![],
            robot_spawns: vec![[1.0, 1.0, 0.0]],
            opponent_spawns: vec![Point2::new(9.0, 1.0)],
            landmarks: vec![],
        })
    }

    fn robot<'a>(pose: Pose, spread: f32, seen: &'a [Detection]) -> RobotView<'a> {
        RobotView {
            pose,
            spread,
            frozen: false,
            can_fire: false,
            scan: &[],
            detections: seen,
            hit: false,
            outside: false,
        }
    }

    #[test]
    fn a_target_seen_past_a_corner_is_walked_around_not_shot_at() {
        // A wall from the floor to y = 3 at x = 6; the opponent stands just past its end,
        // its disc in the laser's view but its centre hidden from the robot's.
        let mut def = room().def.clone();
        def.obstacles = vec![vec![
            Point2::new(6.0, 0.0),
            Point2::new(6.2, 0.0),
            Point2::new(6.2, 3.0),
            Point2::new(6.0, 3.0),
        ]];
        let arena = Arena::new(def);
        let physics = Physics::default();
        let target = Point2::new(7.0, 3.3);
        let aimed = |from: Point2<f32>| {
            let d = target - from;
            Pose::new(from.x, from.y, d.y.atan2(d.x))
        };
        let shooter = aimed(Point2::new(5.0, 2.6));
        assert!(!arena.line_of_sight(shooter.pos, target));
        let view = RobotView {
            can_fire: true,
            ..robot(shooter, 0.0, &[])
        };
        let range = (target - shooter.pos).norm();
        let (motion, fire) = engage(&arena, &view, &physics, target, range, 0.0);
        assert!(!fire, "every shot from here hits the wall");
        let corner = around_the_corner(&arena, shooter.pos, target).expect("a way round");
        assert!(corner.y > 3.0, "round the wall's end: {corner:?}");
        assert_eq!(motion, steer(shooter, corner, physics.robot_turn_rate));
        // From past the end the line is clear: aim and fire.
        let clear = aimed(Point2::new(5.5, 3.6));
        let view = RobotView {
            can_fire: true,
            ..robot(clear, 0.0, &[])
        };
        let range = (target - clear.pos).norm();
        assert!(around_the_corner(&arena, clear.pos, target).is_none());
        assert!(engage(&arena, &view, &physics, target, range, 0.0).1);
    }

    #[test]
    fn an_uncertain_pursuer_along_a_wall_steps_off_it_and_keeps_its_target_in_view() {
        let arena = room();
        let physics = Physics::default();
        // Driving east 0.35 m from the south wall at an opponent 6 m ahead, also by the wall.
        let pose = Pose::new(2.0, 0.35, 0.0);
        let seen = [Detection {
            range: 6.0,
            bearing: 0.0,
        }];
        let (target, range, bearing) = nearest_sighting(&robot(pose, 0.0, &seen)).unwrap();
        let horizon = 0.5;
        for (spread, moves_off) in [(0.0, false), (0.3, true)] {
            let view = robot(pose, spread, &seen);
            let (plain, _) = engage(&arena, &view, &physics, target, range, bearing);
            let (chosen, _) =
                engage_looking_ahead(&arena, &view, &physics, horizon, (target, range, bearing));
            let keep = |m| keeps_in_view(&arena, &physics, pose, spread, target, m, horizon);
            if moves_off {
                // Straight on, a robot a spread further south would be in the wall: the
                // naive (plain) motion keeps the target in view less often.
                assert!(keep(plain) < 0.9, "plain {plain:?}: {}", keep(plain));
                assert!(keep(chosen) > keep(plain) + LOOKAHEAD_MARGIN, "{chosen:?}");
                let next = (0..10).fold(pose, |p, _| {
                    propose(p, chosen, physics.robot_speed, physics.robot_turn_rate)
                });
                assert!(next.pos.y > pose.pos.y, "steps off the wall: {next:?}");
            } else {
                // Sure of its position, nothing beats closing in: the plain motion.
                assert_eq!(chosen, plain);
            }
        }
    }

    #[test]
    fn a_pursuer_about_to_fire_or_with_no_horizon_engages_plainly() {
        let arena = room();
        let physics = Physics::default();
        let pose = Pose::new(2.0, 0.35, 0.0);
        let seen = [Detection {
            range: 4.0,
            bearing: 0.0,
        }];
        let (target, range, bearing) = nearest_sighting(&robot(pose, 0.0, &seen)).unwrap();
        let mut view = robot(pose, 0.3, &seen);
        let plain = engage(&arena, &view, &physics, target, range, bearing);
        let off = engage_looking_ahead(&arena, &view, &physics, 0.0, (target, range, bearing));
        assert_eq!(off, plain);
        view.can_fire = true;
        let firing = engage(&arena, &view, &physics, target, range, bearing);
        assert!(firing.1, "in the cone and in range");
        let ahead = engage_looking_ahead(&arena, &view, &physics, 0.5, (target, range, bearing));
        assert_eq!(ahead, firing, "a shot is not spoilt by a detour");
    }

    #[test]
    fn an_opponent_at_the_edge_of_the_view_is_kept_in_it() {
        let arena = room();
        let physics = Physics::default();
        let pose = Pose::new(3.0, 1.0, std::f32::consts::FRAC_PI_2);
        // Facing north; 80° to the right, 7 m away (beyond tag range): 10° inside the
        // laser's edge.
        let seen = [Detection {
            range: 7.0,
            bearing: -80f32.to_radians(),
        }];
        let view = robot(pose, 0.1, &seen);
        let (target, range, bearing) = nearest_sighting(&view).unwrap();
        let (chosen, _) =
            engage_looking_ahead(&arena, &view, &physics, 0.5, (target, range, bearing));
        let keep = |m| keeps_in_view(&arena, &physics, pose, 0.1, target, m, 0.5);
        let naive = Motion::Drive {
            forward: 1.0,
            turn: 0.0,
        };
        // Driving on, the opponent slips out of the side of the view whenever it walks
        // back; the look-ahead turns towards it and keeps it.
        assert!(keep(naive) < 0.8, "naive: {}", keep(naive));
        assert!(keep(chosen) > 0.99, "{chosen:?}: {}", keep(chosen));
    }
}
