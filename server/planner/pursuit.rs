//! Chasing a detected opponent: turn to it, close in, fire once it is inside the tag cone.

use nalgebra::Point2;

use crate::nav::{steer, turn_to};
use crate::planner::{RobotView, detection_point};
use crate::sim::{Motion, Physics, Pose};

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

/// Motion and trigger for a robot that sees an opponent at `range`, `bearing`.
pub fn engage(
    robot: &RobotView,
    physics: &Physics,
    target: Point2<f32>,
    range: f32,
    bearing: f32,
) -> (Motion, bool) {
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

/// The goal shown while pursuing: the target, facing it.
pub fn pursuit_goal(from: Pose, target: Point2<f32>) -> Pose {
    let d = target - from.pos;
    Pose {
        pos: target,
        theta: d.y.atan2(d.x),
    }
}
