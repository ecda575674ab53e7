//! How sure a robot without a localiser can be of its pose: the covariance of dead reckoning.
//!
//! With localisation off a robot's estimate is its odometry alone, which drifts. Its spread
//! is not 0: every tick's noise (the sim's odometry model, `sensors::odometry_step`) adds to
//! the uncertainty, and a heading error turns into a growing cross-track error. This is the
//! prediction step of an EKF over (x, y, θ) with the odometry motion model (Thrun, Burgard &
//! Fox, *Probabilistic Robotics*, table 5.6 and §7.4): no measurement ever shrinks it.

use nalgebra::{Matrix3, Vector3};

use crate::sim::sensors::OdometryStep;
use crate::sim::{Physics, Pose};

/// Below this much motion a tick adds no uncertainty (as the sim's odometry).
const STILL: f32 = 1e-6;

#[derive(Debug, Clone)]
pub struct DeadReckoning {
    /// Covariance of (x, y, θ).
    cov: Matrix3<f32>,
    /// The odometry pose last taken in.
    last: Pose,
}

impl DeadReckoning {
    /// Certain of `start` (robots are placed where they believe they are).
    pub fn new(start: Pose) -> Self {
        DeadReckoning {
            cov: Matrix3::zeros(),
            last: start,
        }
    }

    /// Takes in this tick's odometry pose: the uncertainty grows by the step's noise.
    pub fn update(&mut self, physics: &Physics, odom: Pose) {
        let prev = std::mem::replace(&mut self.last, odom);
        let Some(step) = OdometryStep::between(prev, odom, STILL) else {
            return;
        };
        let OdometryStep { rot1, trans, .. } = step;
        // The same noise as the sim draws on the turn, drive and turn.
        let noise = Vector3::from(step.wheel_noise(physics)).map(|s| s * s);
        let heading = prev.theta + rot1;
        let (s, c) = heading.sin_cos();
        // x' = x + trans cos(θ + rot1), y' = y + trans sin(θ + rot1), θ' = θ + rot1 + rot2.
        let g = Matrix3::new(
            1.0,
            0.0,
            -trans * s, //
            0.0,
            1.0,
            trans * c, //
            0.0,
            0.0,
            1.0,
        );
        // Derivatives by (rot1, trans, rot2).
        let v = Matrix3::new(
            -trans * s,
            c,
            0.0, //
            trans * c,
            s,
            0.0, //
            1.0,
            0.0,
            1.0,
        );
        self.cov =
            g * self.cov * g.transpose() + v * Matrix3::from_diagonal(&noise) * v.transpose();
    }

    /// Standard deviation of the position (m), as a localiser's spread: √(σx² + σy²).
    pub fn spread(&self) -> f32 {
        (self.cov[(0, 0)] + self.cov[(1, 1)]).max(0.0).sqrt()
    }
}

crate::checkpoint::plain_struct!(DeadReckoning { cov, last });

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::sensors::odometry_step;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// A route of ticks: 10 m straight, a quarter turn on the spot, 5 m straight.
    fn route() -> Vec<Pose> {
        let mut poses = vec![Pose::new(0.0, 0.0, 0.0)];
        let mut p = poses[0];
        for _ in 0..200 {
            p = Pose::new(p.pos.x + 0.05, p.pos.y, p.theta);
            poses.push(p);
        }
        for _ in 0..16 {
            p = Pose::new(
                p.pos.x,
                p.pos.y,
                p.theta + std::f32::consts::FRAC_PI_2 / 16.0,
            );
            poses.push(p);
        }
        for _ in 0..100 {
            p = Pose::new(p.pos.x, p.pos.y + 0.05, p.theta);
            poses.push(p);
        }
        poses
    }

    #[test]
    fn standing_still_keeps_the_robot_certain() {
        let mut d = DeadReckoning::new(Pose::new(1.0, 2.0, 0.3));
        for _ in 0..100 {
            d.update(&Physics::default(), Pose::new(1.0, 2.0, 0.3));
        }
        assert_eq!(d.spread(), 0.0);
    }

    /// The predicted spread is the spread the sim's odometry really has: 400 noisy runs of
    /// the same route end as far from the truth as the covariance says, to within 15%.
    #[test]
    fn the_predicted_spread_matches_the_odometrys_real_drift() {
        for physics in [
            Physics::default(),
            Physics {
                odometry: crate::sim::Odometry {
                    distance: 0.2,
                    heading_deg_per_m: 8.0,
                    turn: 0.1,
                },
                ..Physics::default()
            },
        ] {
            let route = route();
            let truth = *route.last().unwrap();
            let mut rng = ChaCha8Rng::seed_from_u64(7);
            let runs = 400;
            let mut sq = 0.0f64;
            let mut predicted = 0.0;
            for _ in 0..runs {
                let mut odom = route[0];
                let mut d = DeadReckoning::new(odom);
                for w in route.windows(2) {
                    odom = odometry_step(&physics, odom, w[0], w[1], &mut rng);
                    d.update(&physics, odom);
                }
                sq += ((odom.pos - truth.pos).norm_squared()) as f64;
                predicted += d.spread() as f64 / runs as f64;
            }
            let real = (sq / runs as f64).sqrt();
            assert!(
                (predicted / real - 1.0).abs() < 0.15,
                "predicted {predicted:.3} m, real {real:.3} m"
            );
            assert!(real > 0.05, "the route drifts: {real}");
        }
    }
}
