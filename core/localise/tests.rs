//! Unit tests of the localiser: the likelihood field, the KLD sample bound, convergence with
//! the laser and with landmarks, drift on odometry alone, and updates with nothing to weigh.

use super::*;
use crate::sim::arena::MapDef;
use crate::sim::{Physics, sensors};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// A 10 m × 6 m room with an off-centre box, so that no two poses look alike.
fn room(landmarks: Vec<Point2<f32>>) -> Arena {
    Arena::new(MapDef {
        name: "room".into(),
        width: 10.0,
        height: 6.0,
        obstacles: vec![vec![
            Point2::new(6.0, 1.0),
            Point2::new(7.5, 1.0),
            Point2::new(7.5, 2.0),
            Point2::new(6.0, 2.0),
        ]],
        robot_spawns: vec![[2.0, 3.0, 0.0]],
        opponent_spawns: vec![Point2::new(8.0, 5.0)],
        landmarks,
    })
}

fn localiser(arena: &Arena, start: Pose, rng: &mut ChaCha8Rng) -> Localiser {
    let settings = Settings::default();
    let field = Arc::new(LikelihoodField::new(arena, &settings, 8.0));
    Localiser::new(field, arena, settings, start, start, rng)
}

/// Drives a robot round a loop for `ticks`, returning the mean position error of the
/// localiser and of raw odometry. `laser` false skips measurement updates.
fn drive(arena: &Arena, laser: bool, ticks: usize, seed: u64) -> (f32, f32) {
    let physics = Physics::default();
    let shape = sensors::Laser::new(&physics);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut truth = Pose::new(2.0, 3.0, 0.0);
    let mut odom = truth;
    let mut loc = localiser(arena, truth, &mut rng);
    let (mut err, mut odo_err) = (0.0, 0.0);
    for t in 0..ticks {
        // A loop: forward along x, turning at the ends.
        let turn = if (t / 60) % 2 == 1 { 1.5 } else { 0.0 };
        let next = Pose::new(
            truth.pos.x + 0.05 * truth.theta.cos(),
            truth.pos.y + 0.05 * truth.theta.sin(),
            wrap_angle(truth.theta + turn * 0.05),
        );
        let next = if arena.disc_is_free(next.pos, 0.3) {
            next
        } else {
            Pose::new(truth.pos.x, truth.pos.y, wrap_angle(truth.theta + 0.1))
        };
        odom = sensors::odometry_step(&physics, odom, truth, next, &mut rng);
        truth = next;
        loc.predict(odom);
        if laser {
            let scan = sensors::scan(arena, &physics, &shape, truth, &[], &mut rng);
            let marks = sensors::sight_landmarks(arena, &physics, truth, &mut rng);
            let obs = Observation {
                ranges: &scan.ranges,
                laser_fov: physics.laser_fov,
                laser_range: physics.laser_range,
                landmarks: &marks,
                movers: &[],
            };
            loc.correct(&obs, &mut rng);
        }
        err += (loc.estimate().pos - truth.pos).norm();
        odo_err += (odom.pos - truth.pos).norm();
    }
    (err / ticks as f32, odo_err / ticks as f32)
}

#[test]
fn the_likelihood_field_peaks_on_walls() {
    let a = room(vec![]);
    let f = LikelihoodField::new(&a, &Settings::default(), 8.0);
    let on_wall = f.log_likelihood(0.05, 3.0);
    let open = f.log_likelihood(3.0, 3.0);
    let inside_box = f.log_likelihood(6.75, 1.5);
    assert!(on_wall > open + 2.0, "{on_wall} vs {open}");
    assert!(
        inside_box < on_wall - 2.0,
        "deep inside an obstacle is not a wall: {inside_box}"
    );
    assert_eq!(f.log_likelihood(-1.0, 3.0), f.log_outside);
    assert!(!f.open(6.75, 1.5) && f.open(3.0, 3.0));
}

#[test]
fn kld_bound_grows_with_bins() {
    assert_eq!(kld_bound(1, 0.05, 2.33), 1);
    let small = kld_bound(10, 0.05, 2.33);
    let big = kld_bound(100, 0.05, 2.33);
    assert!(small < big && big > 1000, "{small} {big}");
}

#[test]
fn a_stationary_robot_stays_put_and_converges() {
    let a = room(vec![]);
    let physics = Physics::default();
    let laser = sensors::Laser::new(&physics);
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let truth = Pose::new(3.0, 4.0, 0.7);
    // Start a little wrong: the filter must pull the cloud onto the truth.
    let mut loc = localiser(&a, Pose::new(3.1, 3.9, 0.75), &mut rng);
    for _ in 0..200 {
        loc.predict(truth);
        let scan = sensors::scan(&a, &physics, &laser, truth, &[], &mut rng);
        let obs = Observation {
            ranges: &scan.ranges,
            laser_fov: physics.laser_fov,
            laser_range: physics.laser_range,
            landmarks: &[],
            movers: &[],
        };
        loc.correct(&obs, &mut rng);
    }
    let e = loc.estimate();
    assert!((e.pos - truth.pos).norm() < 0.05, "{e:?}");
    assert!(wrap_angle(e.theta - truth.theta).abs() < 0.05, "{e:?}");
    assert!(loc.spread() < 0.1, "{}", loc.spread());
    assert!(loc.particles().len() >= 500 && loc.particles().len() <= 2000);
}

#[test]
fn odometry_alone_drifts_but_the_laser_keeps_the_error_small() {
    let a = room(vec![]);
    let (loc_err, odo_err) = drive(&a, true, 1200, 7);
    let (dead_err, _) = drive(&a, false, 1200, 7);
    eprintln!("localised {loc_err}, odometry {odo_err}, dead reckoning {dead_err}");
    assert!(loc_err < 0.1, "localised error {loc_err}");
    assert!(
        odo_err > loc_err,
        "odometry {odo_err} vs localised {loc_err}"
    );
    assert!(
        dead_err > loc_err,
        "dead reckoning {dead_err} vs localised {loc_err}"
    );
}

#[test]
fn landmark_sightings_fit_only_the_true_pose() {
    let a = room(vec![Point2::new(4.0, 3.0)]);
    let physics = Physics::default();
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let truth = Pose::new(2.0, 3.0, 0.0);
    let marks = sensors::sight_landmarks(&a, &physics, truth, &mut rng);
    assert_eq!(marks.len(), 1);
    assert!((marks[0].range - 2.0).abs() < 0.2 && marks[0].bearing.abs() < 0.1);
    let far = Pose::new(9.0, 5.0, 0.0);
    assert!(sensors::sight_landmarks(&a, &physics, far, &mut rng).is_empty());
}

/// The default motion model is the one the filter was tuned with before the odometry noise
/// became a match setting: matches with default settings replay exactly.
#[test]
fn the_default_motion_model_is_the_tuned_one() {
    assert_eq!(
        Settings::for_odometry(&Physics::default()).alpha,
        [0.05, 3f32.to_radians(), 0.08, 0.01]
    );
    assert_eq!(
        Settings::default().alpha,
        [0.05, 3f32.to_radians(), 0.08, 0.01]
    );
    let noisy = Physics {
        odometry: crate::sim::Odometry {
            distance: 0.2,
            ..Default::default()
        },
        ..Physics::default()
    };
    assert!(
        Settings::for_odometry(&noisy).alpha[2] > 0.3,
        "follows the wheels"
    );
}

/// A scan of `ranges` with no landmark and nobody in view.
fn scan_only(ranges: &[f32]) -> Observation<'_> {
    Observation {
        ranges,
        laser_fov: std::f32::consts::PI,
        laser_range: 8.0,
        landmarks: &[],
        movers: &[],
    }
}

/// `beams: 0` is a robot that localises from landmarks and odometry alone (the uncertainty
/// experiment's weak robot): no beam is weighed, not beam 0 alone.
#[test]
fn zero_beams_weighs_no_beam() {
    let ranges = vec![2.0; 181];
    let obs = scan_only(&ranges);
    assert_eq!(used_beams(&obs, 0).count(), 0);
    assert_eq!(used_beams(&obs, 30).count(), 31);
}

/// A robot localising from landmarks alone, with none in view, has nothing to weigh: its
/// cloud moves and spreads, and the update is not taken for a perfect fit (which made the
/// next real sighting look like a kidnapping and inject random particles).
#[test]
fn an_update_with_nothing_to_weigh_only_moves_the_cloud() {
    let arena = room(vec![]);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let start = Pose::new(2.0, 3.0, 0.0);
    let settings = Settings {
        beams: 0,
        ..Settings::default()
    };
    let field = Arc::new(LikelihoodField::new(&arena, &settings, 8.0));
    let mut loc = Localiser::new(field, &arena, settings, start, start, &mut rng);
    let ranges = vec![2.0; 181];
    let obs = scan_only(&ranges);
    let spread0 = loc.spread();
    for k in 1..=40 {
        loc.predict(Pose::new(2.0 + 0.05 * k as f32, 3.0, 0.0));
        loc.correct(&obs, &mut rng);
    }
    assert_eq!(
        (loc.w_slow, loc.w_fast),
        (0.0, 0.0),
        "no likelihood was averaged"
    );
    assert!(loc.spread() > spread0, "{} → {}", spread0, loc.spread());
    assert!(
        (loc.estimate().pos.x - 4.0).abs() < 0.2,
        "{:?}",
        loc.estimate()
    );
}

#[test]
fn the_vectorised_beam_sums_are_the_scalar_ones_bit_for_bit() {
    use rand::RngExt;
    let arena = room(vec![]);
    let field = LikelihoodField::new(&arena, &Settings::default(), 8.0);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    // Poses inside, on the edges and far outside (beam ends off the table), 1,003 of them so
    // that the last few take the scalar path; beam ends at every range up to the reach.
    let poses: Vec<[f32; 4]> = (0..1003)
        .map(|_| {
            let theta = rng.random_range(-4.0..4.0f32);
            let (s, c) = theta.sin_cos();
            [
                rng.random_range(-3.0..13.0),
                rng.random_range(-3.0..9.0),
                s,
                c,
            ]
        })
        .collect();
    let local: Vec<(f32, f32)> = (0..30)
        .map(|i| {
            let b = -1.5 + 0.1 * i as f32;
            let r = rng.random_range(0.0..8.0f32);
            (r * b.cos(), r * b.sin())
        })
        .collect();
    let mut fast = vec![0.0; poses.len()];
    field.beam_sums(&poses, &local, &mut fast);
    let mut slow = vec![0.0; poses.len()];
    field.beam_sums_scalar(&poses, &local, &mut slow);
    for (k, (a, b)) in fast.iter().zip(&slow).enumerate() {
        assert_eq!(a.to_bits(), b.to_bits(), "pose {k}: {a} against {b}");
    }
    // And a pose's sum is its beams' log-likelihoods added in order.
    let [px, py, s, c] = poses[0];
    let by_hand = local.iter().fold(0.0f32, |sum, &(lx, ly)| {
        sum + field.log_likelihood(px + c * lx - s * ly, py + s * lx + c * ly)
    });
    assert_eq!(slow[0].to_bits(), by_hand.to_bits());
}

#[test]
fn the_guide_table_finds_what_bisection_finds() {
    use rand::RngExt;
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for case in 0..200 {
        let n = rng.random_range(1..600);
        // Weights as a filter has them: mostly tiny, a few heavy, some exactly zero.
        let weights: Vec<f64> = (0..n)
            .map(|_| match rng.random_range(0..10) {
                0 => 0.0,
                1 => rng.random_range(0.0..1.0),
                _ => rng.random_range(0.0..1e-6),
            })
            .collect();
        let mut acc = 0.0;
        let cumulative: Vec<f64> = weights
            .iter()
            .map(|w| {
                acc += w;
                acc
            })
            .collect();
        let search = CumulativeSearch::new(&cumulative);
        let mut probes: Vec<f64> = (0..300).map(|_| rng.random::<f64>() * acc).collect();
        probes.extend(cumulative.iter().copied());
        probes.extend([0.0, acc, acc * 1.5, -1.0, f64::NAN]);
        for u in probes {
            assert_eq!(
                search.first_reaching(u),
                cumulative.partition_point(|c| *c < u),
                "case {case}, u = {u}"
            );
        }
    }
}
