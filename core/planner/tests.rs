//! Unit tests of the team: the radio between robots and what each hears.
use super::*;
use crate::radio::Settings as RadioSettings;
use crate::sim::sensors::Detection;
use rand::SeedableRng;

fn open_room() -> Arena {
    crate::sim::arena::open_room([1.0, 3.0, 0.0])
}

fn team(arena: &Arena, radio: RadioSettings) -> Team {
    let physics = Physics::default();
    let tracker = Tracker::new(
        arena,
        crate::tracker::Settings {
            particles_per_role: 200,
            ..Default::default()
        },
        2,
        ChaCha8Rng::seed_from_u64(1),
    );
    Team::new(
        PlannerKind::Idle,
        arena,
        &physics,
        coordinated::Settings::default(),
        2,
        tracker,
        ChaCha8Rng::seed_from_u64(2),
    )
    .with_radio(Radio::new(radio, ChaCha8Rng::seed_from_u64(3)), 2)
}

fn view<'a>(tick: u64, scan: &'a [f32], seen: &'a [Detection], hit: bool) -> TeamView<'a> {
    let robot = |pose: Pose, detections: &'a [Detection], hit: bool| RobotView {
        pose,
        spread: 0.0,
        frozen: false,
        can_fire: true,
        scan,
        detections,
        hit,
        outside: false,
    };
    TeamView {
        tick,
        robots: vec![
            robot(Pose::new(1.0, 3.0, 0.0), seen, hit),
            robot(Pose::new(1.0, 1.0, std::f32::consts::PI), &[], false),
        ],
    }
}

/// A hit is a fact the team must not lose: a receiver that missed the message of the
/// hit learns of it from the sender's next message (its hit count), so its roles still
/// add up to the opponents left.
#[test]
fn a_teammate_learns_of_a_hit_whose_message_was_lost_from_the_next_one() {
    let arena = open_room();
    let physics = Physics::default();
    let mut t = team(
        &arena,
        RadioSettings {
            loss: 1.0,
            ..RadioSettings::default()
        },
    );
    assert!(t.per_robot());
    let scan = vec![8.0; 181];
    let seen = [Detection {
        range: 3.0,
        bearing: 0.0,
    }];
    t.decide(&arena, &physics, &view(1, &scan, &seen, true));
    assert_eq!(
        t.trackers[0].untagged_count(),
        1,
        "the shooter knows at once"
    );
    assert_eq!(
        t.trackers[1].untagged_count(),
        2,
        "its teammate heard nothing"
    );
    // The radio recovers; the next message says nothing of the hit but its count.
    t.channel.as_mut().unwrap().radio.settings.loss = 0.0;
    t.decide(&arena, &physics, &view(2, &scan, &[], false));
    assert_eq!(
        t.trackers[1].untagged_count(),
        1,
        "learnt from the hit count"
    );
    t.decide(&arena, &physics, &view(3, &scan, &[], false));
    assert_eq!(t.trackers[1].untagged_count(), 1, "and only once");
}

/// Without shared sightings (the reacquire experiment's first condition) a robot's
/// tracker never takes in what a teammate saw.
#[test]
fn without_shared_sightings_a_robot_keeps_only_its_own() {
    let arena = open_room();
    let physics = Physics::default();
    let mut t = team(
        &arena,
        RadioSettings {
            share_sightings: false,
            ..RadioSettings::default()
        },
    );
    let scan = vec![8.0; 181];
    let seen = [Detection {
        range: 4.0,
        bearing: 0.0,
    }];
    for tick in 1..=5 {
        t.decide(&arena, &physics, &view(tick, &scan, &seen, false));
    }
    let confirmed = |tr: &Tracker| tr.roles.iter().any(|r| r.confidence > 0.9);
    assert!(confirmed(&t.trackers[0]), "robot 0 saw the opponent");
    assert!(!confirmed(&t.trackers[1]), "robot 1 was not told");
    // The merged view still accounts for both opponents.
    let merged = t.merged_belief();
    let untagged: u32 = merged.iter().filter(|r| !r.tagged).map(|r| r.count).sum();
    assert_eq!(untagged, 2);
}
