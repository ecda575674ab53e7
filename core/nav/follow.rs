//! Walking a path: waypoint by waypoint ([`PathFollower`]), with differential-drive steering
//! ([`steer`], [`turn_to`]).

use nalgebra::Point2;

use crate::sim::{Motion, Pose, wrap_angle};

/// Walks a path of waypoints.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PathFollower {
    pub waypoints: Vec<Point2<f32>>,
    pub next: usize,
}

impl PathFollower {
    pub fn new(waypoints: Vec<Point2<f32>>) -> PathFollower {
        // waypoints[0] is where the agent stood when planning.
        PathFollower { waypoints, next: 1 }
    }

    pub fn finished(&self) -> bool {
        self.next >= self.waypoints.len()
    }

    /// The waypoint to head for now, advancing past those already reached.
    pub fn target(&mut self, pos: Point2<f32>) -> Option<Point2<f32>> {
        while self.next < self.waypoints.len() {
            let last = self.next + 1 == self.waypoints.len();
            let reach = if last { 0.1 } else { 0.3 };
            if (self.waypoints[self.next] - pos).norm() <= reach {
                self.next += 1;
            } else {
                break;
            }
        }
        self.waypoints.get(self.next).copied()
    }
}

/// Differential-drive steering towards `target`: turn first when the error is large, then drive
/// with speed falling off as the heading error grows. `turn_rate` is the top turn rate.
pub fn steer(pose: Pose, target: Point2<f32>, turn_rate: f32) -> Motion {
    let d = target - pose.pos;
    let dist = d.norm();
    if dist < 1e-3 {
        return Motion::Stop;
    }
    let err = wrap_angle(d.y.atan2(d.x) - pose.theta);
    // A proportional turn that saturates at the top rate; gain chosen to settle in ~3 ticks.
    let turn = (err * 6.0 / turn_rate).clamp(-1.0, 1.0);
    let forward = if err.abs() > 0.8 {
        0.0
    } else {
        err.cos().max(0.0) * (dist / 0.4).min(1.0)
    };
    Motion::Drive { forward, turn }
}

/// Turn in place to `theta`; `Stop` once within a small tolerance.
pub fn turn_to(pose: Pose, theta: f32, turn_rate: f32) -> Motion {
    let err = wrap_angle(theta - pose.theta);
    if err.abs() < 0.02 {
        Motion::Stop
    } else {
        Motion::Drive {
            forward: 0.0,
            turn: (err * 6.0 / turn_rate).clamp(-1.0, 1.0),
        }
    }
}

crate::checkpoint::plain_struct!(PathFollower { waypoints, next });

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steering_reaches_a_point() {
        let mut pose = Pose::new(1.0, 1.0, 3.0);
        let target = Point2::new(3.0, 2.0);
        for _ in 0..200 {
            let m = steer(pose, target, 2.0);
            pose = crate::sim::motion::propose(pose, m, 1.0, 2.0);
        }
        assert!((pose.pos - target).norm() < 0.05, "{pose:?}");
    }
}
