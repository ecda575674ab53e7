//! The stored forms read back as what was stored: settings field for field, a preset's
//! physics from its name, inputs line for line.

use super::*;
use lasertag_core::bots::BotKind;
use lasertag_core::world::ControlKind;

fn round_trip(config: &MatchConfig) {
    let stored = StoredSettings::of(config, StoredClock::Manual, true, 600, None, false);
    let text = serde_json::to_string(&stored).expect("json");
    let back: StoredSettings = serde_json::from_str(&text).expect("parse");
    let again = back.config().expect("config");
    // MatchConfig has no PartialEq; Debug prints every float exactly.
    assert_eq!(format!("{config:?}"), format!("{again:?}"));
    assert_eq!(
        (back.clock, back.bots_joinable, back.spectator_delay_ticks),
        (StoredClock::Manual, true, 600)
    );
}

/// A preset's robot speed and tag cool-down are stored nowhere but in its name: the
/// replay of a recruit match runs its robots at the recruit's speed.
#[test]
fn a_presets_physics_come_back_from_its_name() {
    let mut config = MatchConfig::default();
    Difficulty::Recruit.apply(&mut config);
    let stored = StoredSettings::of(
        &config,
        StoredClock::Realtime,
        false,
        0,
        Some(Difficulty::Recruit),
        true,
    );
    let text = serde_json::to_string(&stored).expect("json");
    assert!(text.contains(r#""difficulty":"recruit""#), "{text}");
    let back: StoredSettings = serde_json::from_str(&text).expect("parse");
    assert_eq!(back.difficulty(), Some(Difficulty::Recruit));
    assert!(back.rated);
    assert_eq!(
        format!("{config:?}"),
        format!("{:?}", back.config().expect("config"))
    );
    // Rows stored without a preset read as before.
    let plain = serde_json::to_string(&StoredSettings::of(
        &MatchConfig::default(),
        StoredClock::Realtime,
        false,
        0,
        None,
        false,
    ))
    .expect("json");
    assert!(!plain.contains("difficulty"), "{plain}");
    assert!(!plain.contains("rated"), "{plain}");
}

#[test]
fn settings_come_back_field_for_field() {
    round_trip(&MatchConfig::default());
    let mut config = MatchConfig {
        robots: 3,
        opponents: 4,
        opponent_control: ControlKind::Api,
        opponent_bot: BotKind::Evade,
        planner: lasertag_core::planner::PlannerKind::Coordinated,
        outside_robots: vec![false, true, false],
        seed: u64::MAX,
        time_limit_ticks: 1234,
        placement: Placement::Given {
            robots: vec![[1.5, 2.25, 0.1]],
            opponents: vec![[3.0, 4.125]],
        },
        localisation: false,
        ..MatchConfig::default()
    };
    config.radio.loss = 0.2;
    config.radio.latency_ticks = 3;
    config.tracker.particles_per_role = 321;
    config.physics.odometry.distance = 0.1;
    config.localiser = localise::Settings {
        beams: 12,
        ..localise::Settings::for_odometry(&config.physics)
    };
    config.coordination.travel_weight = 0.0123;
    round_trip(&config);
}

#[test]
fn inputs_come_back_in_order() {
    let inputs = vec![
        (
            0,
            WorldInput::Seat {
                slot: 1,
                name: "ålice \"x\"".into(),
            },
        ),
        (
            3,
            WorldInput::Keys {
                slot: 1,
                input: HumanInput {
                    forward: 1.0,
                    turn: -0.3,
                    tag: true,
                    seen_tick: Some(2),
                },
            },
        ),
        (
            3,
            WorldInput::SeatRobot {
                robot: 1,
                name: "bo".into(),
            },
        ),
        (
            3,
            WorldInput::RobotKeys {
                robot: 1,
                input: HumanInput {
                    forward: -0.5,
                    turn: 1.0,
                    tag: true,
                    seen_tick: Some(1),
                },
            },
        ),
        (
            4,
            WorldInput::UnseatRobot {
                robot: 1,
                name: "bo".into(),
            },
        ),
        (
            4,
            WorldInput::Opponent {
                slot: 0,
                order: OpponentOrder::Waypoints(vec![Point2::new(1.0, 2.5)]),
            },
        ),
        (
            4,
            WorldInput::Robot {
                robot: 1,
                order: RobotOrder::Drive {
                    forward: 0.5,
                    turn: 0.25,
                    tag: false,
                },
            },
        ),
        (
            9,
            WorldInput::Robot {
                robot: 0,
                order: RobotOrder::Stop,
            },
        ),
        (
            12,
            WorldInput::Unseat {
                slot: 1,
                name: "ålice \"x\"".into(),
            },
        ),
        (20, WorldInput::End(FinishReason::Stopped)),
    ];
    let chunk = encode_inputs(&inputs);
    assert_eq!(decode_inputs(&chunk).expect("decode"), inputs);
    assert!(decode_inputs(b"nonsense").is_err());
    assert!(
        decode_inputs(&encode_inputs(&[]))
            .expect("empty")
            .is_empty()
    );
}
