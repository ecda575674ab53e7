//! Unit tests of the tracker: negative and positive information, splits, merges, tags,
//! late sightings from teammates and world-model confidence, on small arenas built in code.

use super::role::CONTRADICTED_TICKS;
use super::seen::fast_atan2;
use super::*;
use crate::sim::Pose;
use crate::sim::sensors::Detection;
use rand::SeedableRng;

fn open_room() -> Arena {
    crate::sim::arena::open_room([6.0, 3.0, 0.0])
}

fn laser() -> LaserModel {
    LaserModel {
        fov: std::f32::consts::PI,
        range: 8.0,
    }
}

fn tracker(arena: &Arena, opponents: u32) -> Tracker {
    Tracker::new(
        arena,
        Settings::default(),
        opponents,
        ChaCha8Rng::seed_from_u64(4),
    )
}

/// Radio gap: a teammate's scan that arrives late says where nobody
/// stood *then*; an opponent may since have walked in from the edge of what it saw. So
/// it contradicts only hypotheses deep inside the seen area, and a fresh scan all of it.
#[test]
fn a_late_scan_contradicts_only_what_nobody_could_have_entered_since() {
    let robot = Pose::new(1.0, 3.0, 0.0);
    let scan = vec![5.0; 181];
    let fresh = Sighting {
        pose: robot,
        scan: &scan,
        detections: &[],
        tagged: false,
        age_ticks: 0,
    };
    // 10 ticks late: an opponent at top speed (1 m/s) may have moved 0.5 m.
    let late = Sighting {
        age_ticks: 10,
        ..fresh
    };
    let (cos, sin) = (robot.theta.cos(), robot.theta.sin());
    let speed = Settings::default().opponent_speed;
    let seen =
        |p: Point2<f32>, s: &Sighting| would_be_seen(p, s, laser(), cos, sin, s.reach(speed));
    let deep = Point2::new(3.0, 3.0); // 2 m ahead, far from every edge of the scan
    let near_end = Point2::new(5.8, 3.0); // 0.2 m short of where the beams ended
    let near_side = Point2::new(1.3, 4.5); // just inside the field of view's edge
    for p in [deep, near_end, near_side] {
        assert!(seen(p, &fresh), "a fresh scan sees {p}");
    }
    assert!(seen(deep, &late), "deep inside is still contradicted");
    assert!(
        !seen(near_end, &late),
        "someone may have come in past the beams' ends"
    );
    assert!(
        !seen(near_side, &late),
        "someone may have come in from the side"
    );
    // And a late detection places the opponent less sharply.
    let mut sharp = tracker(&open_room(), 1);
    let mut blurred = sharp.clone();
    let det = [Detection {
        range: 3.0,
        bearing: 0.0,
    }];
    let a = open_room();
    sharp.update(
        &a,
        laser(),
        &[Sighting {
            detections: &det,
            ..fresh
        }],
    );
    blurred.update(
        &a,
        laser(),
        &[Sighting {
            detections: &det,
            ..late
        }],
    );
    let spread = |t: &Tracker| {
        let r = &t.roles[0];
        let total: f32 = r.weights.iter().sum();
        let mean = r
            .particles
            .iter()
            .zip(&r.weights)
            .fold(Vector2::zeros(), |m, (p, w)| m + p.coords * (w / total));
        r.particles
            .iter()
            .zip(&r.weights)
            .map(|(p, w)| (p.coords - mean).norm_squared() * w / total)
            .sum::<f32>()
            .sqrt()
    };
    assert!(
        spread(&blurred) > 1.5 * spread(&sharp),
        "late {} vs fresh {}",
        spread(&blurred),
        spread(&sharp)
    );
}

/// Regression (review of the tracker): a hit whose target the laser did not detect (a
/// teammate blocked the beams but not the shot) must still take one opponent off.
#[test]
fn a_hit_without_a_matching_detection_still_takes_one_count_off() {
    let a = open_room();
    let mut t = tracker(&a, 2);
    let scan = vec![8.0; 181];
    let s = Sighting {
        pose: Pose::new(1.0, 3.0, 0.0),
        scan: &scan,
        detections: &[],
        tagged: true,
        age_ticks: 0,
    };
    t.update(&a, laser(), &[s]);
    assert_eq!(t.untagged_count(), 1);
    assert_eq!(t.roles.iter().filter(|r| r.tagged).count(), 1);
}

/// Regression (capture run office/evade/36): a cloud squeezed against a wall in
/// full view of a robot was never down-weighted (a particle counted as seen only when the
/// beam reached past its far edge), so the robots stared at an empty strip for 220 s.
/// Now the strip is seen, and a role looked at in full for 10 ticks is re-seeded.
#[test]
fn a_cloud_against_a_wall_in_full_view_is_contradicted_and_re_seeded() {
    let a = open_room();
    let mut t = tracker(&a, 1);
    // Hypotheses in a strip 0.27 m from the east wall, in front of a robot facing it.
    let strip: Vec<Point2<f32>> = (0..1000)
        .map(|i| Point2::new(11.73, 1.5 + 3.0 * i as f32 / 1000.0))
        .collect();
    t.roles[0].reset(strip);
    // What the robot's laser measures: the wall, 3 m ahead, along every beam.
    let robot = Pose::new(8.5, 3.0, 0.0);
    let scan: Vec<f32> = (0..181)
        .map(|i| {
            let b = (i as f32 - 90.0).to_radians();
            a.cast_ray(robot.pos, Vector2::new(b.cos(), b.sin()), 8.0)
        })
        .collect();
    let s = Sighting {
        pose: robot,
        scan: &scan,
        detections: &[],
        tagged: false,
        age_ticks: 0,
    };
    for _ in 0..CONTRADICTED_TICKS {
        t.update(&a, laser(), &[s]);
    }
    let near_wall: f32 = t.roles[0]
        .particles
        .iter()
        .zip(&t.roles[0].weights)
        .filter(|(p, _)| p.x > 11.0)
        .map(|(_, w)| w)
        .sum();
    assert!(near_wall < 0.05, "weight still by the wall: {near_wall}");
    assert_eq!(t.untagged_count(), 1);
    assert_eq!(
        t.roles[0].confidence_state(),
        Confidence::Invalid,
        "a guess now"
    );
}

/// World-model confidence: a sighting makes a role valid; unconfirmed, it turns
/// suspicious after about 20 s and invalid after about a minute; looking where it should
/// be and seeing nothing wears it down within a second.
#[test]
fn confidence_is_set_by_sightings_and_worn_down_by_time_and_fruitless_looks() {
    let a = open_room();
    let mut t = tracker(&a, 1);
    assert_eq!(
        t.roles[0].confidence_state(),
        Confidence::Invalid,
        "a prior"
    );
    let scan = vec![8.0; 181];
    let seen = [Detection {
        range: 5.0,
        bearing: 0.0,
    }];
    let watching = Sighting {
        pose: Pose::new(1.0, 3.0, 0.0),
        scan: &scan,
        detections: &seen,
        tagged: false,
        age_ticks: 0,
    };
    t.update(&a, laser(), &[watching]);
    assert_eq!(t.roles[0].confidence, 1.0);
    assert_eq!(t.roles[0].confidence_state(), Confidence::Valid);
    // Nobody senses for 30 s: the cloud spreads, unconfirmed.
    for _ in 0..600 {
        t.update(&a, laser(), &[]);
    }
    assert_eq!(t.roles[0].confidence_state(), Confidence::Suspicious);
    for _ in 0..600 {
        t.update(&a, laser(), &[]);
    }
    assert_eq!(t.roles[0].confidence_state(), Confidence::Invalid);
    // Confirmed again, then looked for where it was and not found.
    t.update(&a, laser(), &[watching]);
    assert_eq!(t.roles[0].confidence_state(), Confidence::Valid);
    let looking = Sighting {
        detections: &[],
        ..watching
    };
    for _ in 0..8 {
        t.update(&a, laser(), &[looking]);
    }
    assert_eq!(t.roles[0].confidence_state(), Confidence::Suspicious);
}

/// Regression (reacquire experiment): a tight cloud 2 m from a detection kept its place
/// (the Bayes update only renormalised it) although the detection confirmed the role
/// every tick; without motion to carry it there, it never followed a teammate's
/// sightings. A detection 4σ from every particle now re-draws the cloud around it.
#[test]
fn a_detection_far_from_a_tight_cloud_redraws_the_cloud_there() {
    let a = open_room();
    let mut t = Tracker::new(
        &a,
        Settings {
            predict: false,
            ..Settings::default()
        },
        1,
        ChaCha8Rng::seed_from_u64(4),
    );
    let tight: Vec<Point2<f32>> = (0..1000)
        .map(|i| Point2::new(4.0 + (i % 10) as f32 * 0.01, 3.0 + (i / 100) as f32 * 0.01))
        .collect();
    t.roles[0].reset(tight);
    let seen = [Detection {
        range: 5.0,
        bearing: 0.0,
    }];
    let s = Sighting {
        pose: Pose::new(1.0, 3.0, 0.0),
        scan: &[],
        detections: &seen,
        tagged: false,
        age_ticks: 0,
    };
    t.update(&a, laser(), &[s]);
    let r = &t.roles[0];
    let mean = r
        .particles
        .iter()
        .zip(&r.weights)
        .fold(Vector2::zeros(), |m, (p, w)| m + p.coords * *w);
    assert!(
        (mean - Vector2::new(6.0, 3.0)).norm() < 0.2,
        "the cloud moved to the detection: {mean:?}"
    );
}

#[test]
fn fast_atan2_matches_atan2() {
    for k in 0..3600 {
        let a = k as f32 / 3600.0 * std::f32::consts::TAU - std::f32::consts::PI;
        let (y, x) = (a.sin() * 3.0, a.cos() * 3.0);
        assert!(
            (fast_atan2(y, x) - y.atan2(x)).abs() < 1e-3
                || (a.abs() - std::f32::consts::PI).abs() < 1e-3
        );
    }
}

/// `n` particles, the first `near` of them at `at` and the rest at `elsewhere`.
fn two_spots(near: usize, at: Point2<f32>, elsewhere: Point2<f32>) -> Vec<Point2<f32>> {
    (0..1000)
        .map(|i| if i < near { at } else { elsewhere })
        .collect()
}

fn still() -> Settings {
    Settings {
        predict: false,
        ..Settings::default()
    }
}

/// A role standing for three opponents explains a detection three times as well as its
/// cloud alone: any of the three may have made it. Here the role of one has 30% of its
/// weight at the detection and the role of three 20% (60% for three opponents): the
/// detection belongs to the role of three, which splits one off for it.
#[test]
fn association_weighs_a_role_by_the_opponents_it_stands_for() {
    let a = open_room();
    let mut t = Tracker::with_roles(&a, still(), &[1, 3], ChaCha8Rng::seed_from_u64(4));
    let (z, far) = (Point2::new(6.0, 3.0), Point2::new(10.0, 1.0));
    t.roles[0].reset(two_spots(300, z, far));
    t.roles[1].reset(two_spots(200, z, far));
    let seen = [Detection {
        range: 5.0,
        bearing: 0.0,
    }];
    let s = Sighting {
        pose: Pose::new(1.0, 3.0, 0.0),
        scan: &[],
        detections: &seen,
        tagged: false,
        age_ticks: 0,
    };
    let events = t.update(&a, laser(), &[s]);
    assert_eq!(events, vec![TrackerEvent::Split { role: 2, from: 1 }]);
    assert_eq!(t.roles[1].count, 2);
}

/// The same for a hit whose target the laser did not detect: the opponent taken out is
/// most likely from the role with the most opponents expected in the tag cone (count ×
/// weight there), the role of three with 20% of its weight there rather than the role of
/// one with 30%.
#[test]
fn a_hit_without_a_detection_takes_the_opponent_from_the_role_most_expected_there() {
    let a = open_room();
    let mut t = Tracker::with_roles(&a, still(), &[1, 3], ChaCha8Rng::seed_from_u64(4));
    let (ahead, far) = (Point2::new(3.0, 3.0), Point2::new(10.0, 1.0));
    t.roles[0].reset(two_spots(300, ahead, far));
    t.roles[1].reset(two_spots(200, ahead, far));
    let s = Sighting {
        pose: Pose::new(1.0, 3.0, 0.0),
        scan: &[],
        detections: &[],
        tagged: true,
        age_ticks: 0,
    };
    t.update(&a, laser(), &[s]);
    let untagged: Vec<(u64, u32)> = t
        .roles
        .iter()
        .filter(|r| !r.tagged)
        .map(|r| (r.id, r.count))
        .collect();
    assert_eq!(untagged, vec![(0, 1), (1, 2)]);
}

/// Merging a role of three opponents with a role of one gives a cloud three quarters of
/// which is the first's: the merged role stands for four draws, three of them from the
/// first cloud. Either way round.
#[test]
fn a_merge_weighs_each_cloud_by_the_opponents_it_stands_for() {
    let a = open_room();
    let merging = Settings {
        merge_interval: 1,
        kl_cutoff: 1e5, // whatever the clouds, merge them
        ..still()
    };
    let (west, east) = (Point2::new(3.0, 3.0), Point2::new(9.0, 3.0));
    for (counts, west_share) in [([3, 1], 0.75), ([1, 3], 0.25)] {
        let mut t = Tracker::with_roles(&a, merging.clone(), &counts, ChaCha8Rng::seed_from_u64(4));
        t.roles[0].reset(vec![west; 1000]);
        t.roles[1].reset(vec![east; 1000]);
        let events = t.update(&a, laser(), &[]);
        assert_eq!(
            events,
            vec![TrackerEvent::Merge {
                role: 0,
                from: 1,
                count: 4
            }]
        );
        let r = &t.roles[0];
        let west_weight: f32 = r
            .particles
            .iter()
            .zip(&r.weights)
            .filter(|(p, _)| p.x < 6.0)
            .map(|(_, w)| w)
            .sum();
        assert!(
            (west_weight - west_share).abs() < 0.01,
            "counts {counts:?}: {west_weight} of the weight in the west"
        );
    }
}

#[test]
fn behind_the_robot_the_fast_arctangent_is_past_a_right_angle() {
    // would_be_seen skips the arctangent there: it must be what the test would have said.
    use std::f32::consts::FRAC_PI_2;
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for k in 0..200_000 {
        let lateral: f32 = (rng.random::<f32>() - 0.5) * 20.0;
        // From just past the threshold to far behind, on a log scale.
        let share = 10f32.powf(-5.9 + 6.0 * rng.random::<f32>());
        let forward = -(1e-6 + share) * lateral.abs().max(1e-3);
        let b = fast_atan2(lateral, forward);
        assert!(b.abs() > FRAC_PI_2, "#{k}: ({forward}, {lateral}) gave {b}");
    }
}
