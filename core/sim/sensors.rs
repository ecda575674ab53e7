//! The robots' sensors: a forward laser range finder and the anonymous opponent detector.
//!
//! A scan casts `laser_beams` rays evenly over the field of view (beam `i` at bearing
//! `(i - 90)°` for the default 181 beams). Each ray stops at the first wall or agent disc.
//! Beams that end on an opponent are grouped per opponent into one [`Detection`] (range and
//! bearing to its centre, with noise): the detector says *something is there*, never *who*.
//! The referee-side list of which opponents were seen is kept apart ([`Scan::seen`]) and
//! never reaches the robots' decisions.

use nalgebra::{Point2, Vector2};
use rand::RngExt;

use crate::sim::arena::Arena;
use crate::sim::segments::FanBins;
use crate::sim::{AGENT_RADIUS, AgentId, Physics, Pose, gaussian, wrap_angle};

/// A landmark seen by identity: its index in the map's `landmarks`, range and bearing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LandmarkSighting {
    pub id: usize,
    pub range: f32,
    pub bearing: f32,
}

/// An anonymous sighting of an opponent, relative to the sensing robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    pub range: f32,
    pub bearing: f32,
}

/// One robot's sensing in one tick.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scan {
    /// Measured ranges, one per beam; `laser_range` where nothing was hit.
    pub ranges: Vec<f32>,
    pub detections: Vec<Detection>,
    /// Ground truth: opponent indices behind `detections`, in the same order (referee only).
    pub seen: Vec<usize>,
}

/// Bearing of beam `i` of `n` spread evenly over `fov`.
pub fn beam_bearing(i: usize, n: usize, fov: f32) -> f32 {
    if n <= 1 {
        return 0.0;
    }
    -fov / 2.0 + fov * i as f32 / (n - 1) as f32
}

/// The unit vectors of a fan of `n` beams over `fov` around `heading`, in beam order, their
/// x and y components apart (the layout the wall and disc tests run over several beams at a
/// time): one `sin_cos` per block of [`BLOCK`](beam_fan) beams, the beams between turned
/// from the block's first by the fan's step (a complex product). Each vector is within a
/// few `f32` rounding steps of `(heading + beam_bearing(i)).sin_cos()`, at an eighth of the
/// transcendental calls (they were most of a scan's own time).
pub fn beam_fan(heading: f32, n: usize, fov: f32) -> (Vec<f32>, Vec<f32>) {
    /// Beams turned from one exact direction: the error grows by about one rounding a turn.
    const BLOCK: usize = 8;
    let step = if n <= 1 { 0.0 } else { fov / (n - 1) as f32 };
    let (s, c) = step.sin_cos();
    let (mut xs, mut ys) = (vec![0.0f32; n], vec![0.0f32; n]);
    for i in (0..n).step_by(BLOCK) {
        let (y, x) = (heading + beam_bearing(i, n, fov)).sin_cos();
        (xs[i], ys[i]) = (x, y);
    }
    // Turn every block's next beam, then the one after: the blocks' products are
    // independent, so the processor overlaps them (a block alone is one long chain).
    for j in 1..BLOCK {
        for i in (j..n).step_by(BLOCK) {
            let (px, py) = (xs[i - 1], ys[i - 1]);
            (xs[i], ys[i]) = (px * c - py * s, px * s + py * c);
        }
    }
    (xs, ys)
}

/// A laser's fan as the physics shapes it, with what every scan of it looks up (which beams
/// lie in which direction): made once a match rather than once a scan.
#[derive(Debug, Clone, PartialEq)]
pub struct Laser {
    fov: f32,
    bins: FanBins,
}

impl Laser {
    pub fn new(physics: &Physics) -> Laser {
        Laser {
            fov: physics.laser_fov,
            bins: FanBins::new(physics.laser_beams, physics.laser_fov),
        }
    }

    fn shapes(&self, physics: &Physics) -> bool {
        self.bins.beams() == physics.laser_beams && self.fov == physics.laser_fov
    }
}

/// Scans from `pose` with `laser` (made from `physics`). `others` are the centres of every
/// other agent present in the arena.
pub fn scan(
    arena: &Arena,
    physics: &Physics,
    laser: &Laser,
    pose: Pose,
    others: &[(AgentId, Point2<f32>)],
    rng: &mut impl RngExt,
) -> Scan {
    let n = physics.laser_beams;
    let max = physics.laser_range;
    let (xs, ys) = beam_fan(pose.theta, n, physics.laser_fov);
    // The walls for the whole fan at once (the same distances as a cast a beam); a fan that
    // closes the circle has no "behind" to order its beams from, so it casts beam by beam.
    let mut best = vec![max; n];
    if physics.laser_fov < std::f32::consts::TAU - 1e-3 {
        let heading = Vector2::new(pose.theta.cos(), pose.theta.sin());
        // A laser made for other physics would bound the wrong beams: make the right one.
        let own;
        let laser = if laser.shapes(physics) {
            laser
        } else {
            own = Laser::new(physics);
            &own
        };
        arena.cast_fan(pose.pos, heading, &laser.bins, (&xs, &ys), max, &mut best);
    } else {
        for ((w, x), y) in best.iter_mut().zip(&xs).zip(&ys) {
            *w = arena.cast_ray(pose.pos, Vector2::new(*x, *y), max);
        }
    }
    // Then each agent within reach, for every beam at once: `hit[i]` is the agent (an index
    // into `others`, plus one) that stops beam `i` nearer than any wall and any agent before
    // it in `others`, or 0.
    let mut hit = vec![0u32; n];
    for (k, (_, c)) in others.iter().enumerate() {
        if (c - pose.pos).norm() <= max + AGENT_RADIUS {
            discs_before(
                pose.pos,
                *c,
                AGENT_RADIUS,
                k as u32 + 1,
                (&xs, &ys),
                &mut best,
                &mut hit,
            );
        }
    }
    let mut seen: Vec<usize> = Vec::new();
    for &h in &hit {
        if let Some((AgentId::Opponent(k), _)) = h.checked_sub(1).map(|i| others[i as usize])
            && !seen.contains(&k)
        {
            seen.push(k);
        }
    }
    let ranges = best
        .iter()
        .map(|&b| {
            if b >= max {
                max
            } else {
                (b + gaussian(rng, physics.laser_noise)).clamp(0.0, max)
            }
        })
        .collect();
    // A fixed order (by opponent index) keeps noise draws, and so the match, deterministic.
    seen.sort_unstable();
    let detections = seen
        .iter()
        .filter_map(|k| others.iter().find(|(id, _)| *id == AgentId::Opponent(*k)))
        .map(|(_, c)| Detection {
            range: ((c - pose.pos).norm() + gaussian(rng, physics.detection_range_noise)).max(0.0),
            bearing: wrap_angle(
                pose.bearing_to(*c) + gaussian(rng, physics.detection_bearing_noise),
            ),
        })
        .collect();
    Scan {
        ranges,
        detections,
        seen,
    }
}

/// The distance along every beam `(xs[i], ys[i])` from `origin` to the disc at `centre`,
/// where the beam hits it: where that is nearer than `best[i]`, `best[i]` becomes it and
/// `hit[i]` becomes `mark`. Without branches, so that the compiler tests several beams in
/// one instruction.
fn discs_before(
    origin: Point2<f32>,
    centre: Point2<f32>,
    radius: f32,
    mark: u32,
    (xs, ys): (&[f32], &[f32]),
    best: &mut [f32],
    hit: &mut [u32],
) {
    let v = centre - origin;
    let v2 = v.norm_squared();
    let r2 = radius * radius;
    for (((x, y), best), hit) in xs.iter().zip(ys).zip(best).zip(hit) {
        let tc = v.dot(&Vector2::new(*x, *y));
        let d2 = v2 - tc * tc;
        // Where the beam misses (d2 > r2) the root is NaN and `t` fails every comparison.
        let t = tc - (r2 - d2).sqrt();
        let nearer = (d2 <= r2) & (t >= 0.0) & (t < *best);
        *best = if nearer { t } else { *best };
        *hit = if nearer { mark } else { *hit };
    }
}

/// The landmarks `pose` recognises: within `landmark_range` and in line of sight, all round
/// (game-rules.md), each with range and bearing noise. In map order, so the noise draws are
/// deterministic.
pub fn sight_landmarks(
    arena: &Arena,
    physics: &Physics,
    pose: Pose,
    rng: &mut impl RngExt,
) -> Vec<LandmarkSighting> {
    arena
        .def
        .landmarks
        .iter()
        .enumerate()
        .filter(|(_, m)| {
            (*m - pose.pos).norm() <= physics.landmark_range && arena.line_of_sight(pose.pos, **m)
        })
        .map(|(id, m)| LandmarkSighting {
            id,
            range: ((m - pose.pos).norm() + gaussian(rng, physics.landmark_range_noise)).max(0.0),
            bearing: wrap_angle(
                pose.bearing_to(*m) + gaussian(rng, physics.landmark_bearing_noise),
            ),
        })
        .collect()
}

/// One step of wheel odometry: the true motion from `before` to `after` as (rotate,
/// translate, rotate), each with noise, applied to the odometry pose `odom`.
pub fn odometry_step(
    physics: &Physics,
    odom: Pose,
    before: Pose,
    after: Pose,
    rng: &mut impl RngExt,
) -> Pose {
    let Some(step) = OdometryStep::between(before, after, 1e-6) else {
        return odom;
    };
    let [s_rot1, s_trans, s_rot2] = step.wheel_noise(physics);
    // Fields are evaluated in order, so the noise is drawn rotate, translate, rotate.
    OdometryStep {
        rot1: step.rot1 + gaussian(rng, s_rot1),
        trans: step.trans + gaussian(rng, s_trans),
        rot2: step.rot2 + gaussian(rng, s_rot2),
    }
    .apply(odom)
}

/// A change of pose as the odometry motion model splits it: turn, drive straight, turn. The
/// sim's odometry draws its noise on these three, and so does a localiser's motion update.
#[derive(Debug, Clone, Copy)]
pub struct OdometryStep {
    pub rot1: f32,
    pub trans: f32,
    pub rot2: f32,
}

impl OdometryStep {
    /// The change from `prev` to `next`, or `None` when both the distance and the turn are
    /// below `still`.
    pub fn between(prev: Pose, next: Pose, still: f32) -> Option<OdometryStep> {
        let d = next.pos - prev.pos;
        let mut trans = d.norm();
        let dtheta = wrap_angle(next.theta - prev.theta);
        if trans < still && dtheta.abs() < still {
            return None;
        }
        let mut rot1 = if trans < 1e-4 {
            0.0
        } else {
            wrap_angle(d.y.atan2(d.x) - prev.theta)
        };
        // Driving backwards is a small negative translation, not a half turn and back.
        if rot1.abs() > std::f32::consts::FRAC_PI_2 {
            rot1 = wrap_angle(rot1 + std::f32::consts::PI);
            trans = -trans;
        }
        Some(OdometryStep {
            rot1,
            trans,
            rot2: wrap_angle(dtheta - rot1),
        })
    }

    /// Standard deviations of the noise the robots' wheels put on each part of this step
    /// (rot1, trans, rot2): what the sim's odometry draws, and what dead reckoning predicts.
    pub fn wheel_noise(&self, physics: &Physics) -> [f32; 3] {
        let turn = |rot: f32| {
            physics.odometry.turn * rot.abs()
                + physics.odometry.heading_per_metre() * self.trans.abs()
        };
        [
            turn(self.rot1),
            physics.odometry.distance * self.trans.abs(),
            turn(self.rot2),
        ]
    }

    /// `p` moved by this step (in its own frame).
    pub fn apply(self, p: Pose) -> Pose {
        let a = p.theta + self.rot1;
        Pose::new(
            p.pos.x + self.trans * a.cos(),
            p.pos.y + self.trans * a.sin(),
            wrap_angle(a + self.rot2),
        )
    }
}

/// The world point a detection refers to, seen from `pose`.
pub fn detection_point(pose: Pose, d: &Detection) -> Point2<f32> {
    let a = pose.theta + d.bearing;
    pose.pos + Vector2::new(a.cos(), a.sin()) * d.range
}

crate::checkpoint::plain_struct!(LandmarkSighting { id, range, bearing });
crate::checkpoint::plain_struct!(Detection { range, bearing });
crate::checkpoint::plain_struct!(Scan {
    ranges,
    detections,
    seen
});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::arena::MapDef;
    use rand::SeedableRng;

    fn hall() -> Arena {
        Arena::new(MapDef {
            name: "hall".into(),
            width: 20.0,
            height: 4.0,
            obstacles: vec![],
            robot_spawns: vec![[1.0, 2.0, 0.0]],
            opponent_spawns: vec![Point2::new(4.0, 2.0)],
            landmarks: vec![],
        })
    }

    #[test]
    fn beams_span_the_field_of_view() {
        let fov = std::f32::consts::PI;
        assert!((beam_bearing(0, 181, fov) + fov / 2.0).abs() < 1e-6);
        assert!(beam_bearing(90, 181, fov).abs() < 1e-6);
        assert!((beam_bearing(180, 181, fov) - fov / 2.0).abs() < 1e-6);
    }

    #[test]
    fn beam_fans_are_the_bearings_unit_vectors() {
        for (n, fov) in [(181, std::f32::consts::PI), (1, 1.0), (7, 2.0), (360, 6.2)] {
            for k in 0..50 {
                let heading = -7.0 + 0.29 * k as f32;
                let (xs, ys) = beam_fan(heading, n, fov);
                assert_eq!((xs.len(), ys.len()), (n, n));
                for (i, d) in xs
                    .iter()
                    .zip(&ys)
                    .map(|(x, y)| Vector2::new(*x, *y))
                    .enumerate()
                {
                    let a = heading + beam_bearing(i, n, fov);
                    let exact = Vector2::new(a.cos(), a.sin());
                    assert!(
                        (d - exact).norm() < 2e-6,
                        "beam {i} of {n} at {heading}: {d:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_scan_stops_at_walls_and_agents_and_detects_opponents_anonymously() {
        let a = hall();
        let physics = Physics::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let pose = Pose::new(1.0, 2.0, 0.0);
        let others = [
            (AgentId::Opponent(0), Point2::new(4.0, 2.0)),
            (AgentId::Robot(1), Point2::new(1.0, 3.0)),
        ];
        let s = scan(&a, &physics, &Laser::new(&physics), pose, &others, &mut rng);
        assert_eq!(s.ranges.len(), 181);
        // Straight ahead: the opponent's near edge at 2.75 m.
        assert!((s.ranges[90] - 2.75).abs() < 0.1, "{}", s.ranges[90]);
        // Straight left (beam 180, +90°): the teammate's near edge at 0.75 m.
        assert!((s.ranges[180] - 0.75).abs() < 0.1, "{}", s.ranges[180]);
        // Straight right: the wall at y = 0, 2 m away.
        assert!((s.ranges[0] - 2.0).abs() < 0.1, "{}", s.ranges[0]);
        assert_eq!(s.detections.len(), 1, "only the opponent is detected");
        assert!((s.detections[0].range - 3.0).abs() < 0.25);
        assert!(s.detections[0].bearing.abs() < 0.1);
        assert_eq!(s.seen, vec![0]);
    }

    #[test]
    fn an_opponent_behind_a_wall_or_out_of_range_is_not_detected() {
        let a = hall();
        let physics = Physics::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let pose = Pose::new(1.0, 2.0, 0.0);
        let far = [(AgentId::Opponent(0), Point2::new(12.0, 2.0))];
        assert!(
            scan(&a, &physics, &Laser::new(&physics), pose, &far, &mut rng)
                .detections
                .is_empty()
        );
        let behind = [(AgentId::Opponent(0), Point2::new(0.5, 2.0))];
        let back = Pose::new(1.0, 2.0, 0.0);
        assert!(
            scan(&a, &physics, &Laser::new(&physics), back, &behind, &mut rng)
                .detections
                .is_empty()
        );
    }
}
