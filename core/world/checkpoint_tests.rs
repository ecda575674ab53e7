//! A match restored from a checkpoint is the match that was saved: every later tick, event
//! and byte of state as the same match never interrupted.

use super::*;
use crate::sim::arena::MapDef;

/// A 16 m × 10 m hall with two pillars and a landmark: room for searching, hiding and
/// localising.
fn hall() -> Arc<Arena> {
    let square = |x: f32, y: f32| {
        vec![
            Point2::new(x, y),
            Point2::new(x + 1.5, y),
            Point2::new(x + 1.5, y + 1.5),
            Point2::new(x, y + 1.5),
        ]
    };
    Arc::new(Arena::new(MapDef {
        name: "hall".into(),
        width: 16.0,
        height: 10.0,
        obstacles: vec![square(5.0, 3.0), square(10.0, 6.0)],
        robot_spawns: vec![[1.0, 2.0, 0.0], [1.0, 8.0, 0.0], [2.0, 5.0, 0.0]],
        opponent_spawns: vec![
            Point2::new(15.0, 9.0),
            Point2::new(15.0, 1.0),
            Point2::new(13.0, 5.0),
        ],
        landmarks: vec![Point2::new(8.0, 0.5)],
    }))
}

/// What the outside does to the match at `tick`: keys, orders, seats coming and going, as
/// the settings allow (refused inputs change nothing, live or restored).
fn inputs_at(config: &MatchConfig, tick: u64) -> Vec<WorldInput> {
    let mut out = Vec::new();
    let wave = ((tick / 7) % 5) as f32 / 2.0 - 1.0;
    if config.opponent_control == ControlKind::Human && tick.is_multiple_of(3) {
        for slot in 0..config.opponents {
            out.push(WorldInput::Keys {
                slot,
                input: HumanInput {
                    forward: 1.0,
                    turn: wave,
                    tag: tick.is_multiple_of(40),
                    seen_tick: tick.checked_sub(3),
                },
            });
        }
    }
    if config.opponent_control == ControlKind::Api && tick.is_multiple_of(50) {
        let x = 3.0 + (tick % 11) as f32;
        out.push(WorldInput::Opponent {
            slot: (tick / 50) as usize % config.opponents,
            order: OpponentOrder::Waypoints(vec![Point2::new(x, 5.0), Point2::new(x, 8.5)]),
        });
    }
    if config.planner == PlannerKind::Api && tick.is_multiple_of(10) {
        for robot in 0..config.robots {
            out.push(WorldInput::Robot {
                robot,
                order: if tick.is_multiple_of(100) {
                    RobotOrder::Waypoints(vec![Point2::new(12.0, 5.0)])
                } else {
                    RobotOrder::Drive {
                        forward: 0.8,
                        turn: wave,
                        tag: tick.is_multiple_of(30),
                    }
                },
            });
        }
    }
    if config.pursuer_slots > 0 {
        let robot = config.robots - 1;
        match tick {
            20 => out.push(WorldInput::SeatRobot {
                robot,
                name: "hunter".into(),
            }),
            t if t > 20 && t < 500 && t % 4 == 0 => out.push(WorldInput::RobotKeys {
                robot,
                input: HumanInput {
                    forward: 0.7,
                    turn: wave,
                    tag: t % 25 == 0,
                    seen_tick: Some(t - 2),
                },
            }),
            500 => out.push(WorldInput::UnseatRobot {
                robot,
                name: "hunter".into(),
            }),
            _ => {}
        }
    }
    if config.opponent_control == ControlKind::Bot && config.opponents > 1 {
        match tick {
            60 => out.push(WorldInput::Seat {
                slot: 1,
                name: "guest".into(),
            }),
            400 => out.push(WorldInput::Unseat {
                slot: 1,
                name: "guest".into(),
            }),
            _ => {}
        }
    }
    out
}

fn play(world: &mut World, until: u64) {
    while world.tick < until && world.status == MatchStatus::Running {
        for input in inputs_at(&world.config.clone(), world.tick) {
            let _ = world.apply(&input);
        }
        world.step();
    }
}

/// Saves `config`'s match at each of `at`, restores it into a fresh world and plays both
/// on: they must agree in every tick's digest, every event and, at the end, every byte of
/// their state.
fn restored_matches_run_on_as_saved(name: &str, config: MatchConfig, at: &[u64], after: u64) {
    let arena = hall();
    for &tick in at {
        let mut live = World::new(arena.clone(), config.clone()).unwrap();
        play(&mut live, tick);
        let saved = live.checkpoint();
        let mut back = World::new(arena.clone(), config.clone())
            .unwrap()
            .restored(&saved)
            .unwrap_or_else(|e| panic!("{name} at {tick}: {e}"));
        assert_eq!(back.checkpoint(), saved, "{name}: restored state at {tick}");
        for _ in 0..after {
            let next = live.tick + 1;
            play(&mut live, next);
            play(&mut back, next);
            assert_eq!(back.digest(), live.digest(), "{name}: tick {}", live.tick);
        }
        assert_eq!(back.events(), live.events(), "{name}: events after {tick}");
        assert_eq!(
            back.checkpoint(),
            live.checkpoint(),
            "{name}: state after {tick}"
        );
    }
}

fn base() -> MatchConfig {
    MatchConfig {
        robots: 2,
        opponents: 2,
        opponent_bot: BotKind::Evade,
        seed: 11,
        ..MatchConfig::default()
    }
}

#[test]
fn coordinated_robots_localising_against_bots_and_a_guest() {
    restored_matches_run_on_as_saved("coordinated", base(), &[0, 1, 97, 350], 300);
}

#[test]
fn the_search_planner_over_a_lossy_radio() {
    let mut config = MatchConfig {
        planner: PlannerKind::Search,
        robots: 3,
        ..base()
    };
    config.radio.latency_ticks = 4;
    config.radio.loss = 0.3;
    restored_matches_run_on_as_saved("search+radio", config, &[45, 260], 200);
}

#[test]
fn the_baseline_planner_against_people_with_a_pursuer_seat() {
    let config = MatchConfig {
        planner: PlannerKind::Baseline,
        opponent_control: ControlKind::Human,
        pursuer_slots: 1,
        localisation: false,
        placement: Placement::Random,
        ..base()
    };
    restored_matches_run_on_as_saved("baseline+people", config, &[30, 210], 350);
}

#[test]
fn robots_and_opponents_driven_from_outside() {
    let config = MatchConfig {
        planner: PlannerKind::Api,
        opponent_control: ControlKind::Api,
        ..base()
    };
    restored_matches_run_on_as_saved("api", config, &[10, 333], 250);
}

#[test]
fn a_checkpoint_of_other_settings_or_damaged_is_refused() {
    let arena = hall();
    let mut live = World::new(arena.clone(), base()).unwrap();
    play(&mut live, 40);
    let saved = live.checkpoint();
    let baseline = MatchConfig {
        planner: PlannerKind::Baseline,
        ..base()
    };
    assert!(
        World::new(arena.clone(), baseline)
            .unwrap()
            .restored(&saved)
            .is_err()
    );
    let fresh = || World::new(arena.clone(), base()).unwrap();
    assert!(fresh().restored(&saved[..saved.len() - 3]).is_err());
    let mut longer = saved.clone();
    longer.push(0);
    assert!(matches!(
        fresh().restored(&longer),
        Err(CheckpointError::Trailing(1))
    ));
    let mut flipped = saved.clone();
    flipped[8..12].copy_from_slice(&0u32.to_le_bytes());
    assert!(matches!(
        fresh().restored(&flipped),
        Err(CheckpointError::OtherBuild(_))
    ));
}
