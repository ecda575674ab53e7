//! Unit tests of the tick pipeline on small arenas built in code: spawns, tagging,
//! freezing, the time limit, orders, placement and the bots.

use super::*;
use crate::sim::arena::MapDef;

/// A 12 m × 6 m room with one pillar.
fn duel() -> Arc<Arena> {
    Arc::new(Arena::new(MapDef {
        name: "duel".into(),
        width: 12.0,
        height: 6.0,
        obstacles: vec![vec![
            Point2::new(5.5, 4.5),
            Point2::new(6.5, 4.5),
            Point2::new(6.5, 5.5),
            Point2::new(5.5, 5.5),
        ]],
        robot_spawns: vec![[1.0, 3.0, 0.0], [1.0, 1.0, 0.0]],
        opponent_spawns: vec![Point2::new(11.0, 5.0), Point2::new(11.0, 1.0)],
        landmarks: vec![],
    }))
}

fn config(planner: PlannerKind, control: ControlKind) -> MatchConfig {
    MatchConfig {
        robots: 1,
        opponents: 1,
        opponent_control: control,
        planner,
        ..MatchConfig::default()
    }
}

#[test]
fn agents_start_at_spawns_in_order_wrapping_and_never_overlap() {
    let cfg = MatchConfig {
        robots: 3,
        opponents: 3,
        ..config(PlannerKind::Idle, ControlKind::Api)
    };
    let w = World::new(duel(), cfg).unwrap();
    assert_eq!(w.robots[0].pose.pos, Point2::new(1.0, 3.0));
    assert_eq!(w.robots[1].pose.pos, Point2::new(1.0, 1.0));
    assert_eq!(w.opponents[1].pose.pos, Point2::new(11.0, 1.0));
    let all: Vec<_> = w.present();
    for (i, a) in all.iter().enumerate() {
        for b in &all[i + 1..] {
            assert!((a.1 - b.1).norm() >= 2.0 * AGENT_RADIUS, "{a:?} {b:?}");
        }
    }
}

#[test]
fn a_robot_tags_an_opponent_that_walks_into_view() {
    let mut w = World::new(duel(), config(PlannerKind::Baseline, ControlKind::Api)).unwrap();
    w.order_opponent(0, OpponentOrder::Waypoints(vec![Point2::new(4.0, 3.0)]))
        .unwrap();
    for _ in 0..2_000 {
        w.step();
        if w.status == MatchStatus::Finished {
            break;
        }
    }
    assert_eq!(w.winner, Some(Side::Robots));
    assert!(w.events().iter().any(|e| matches!(
        e.kind,
        EventKind::Tag {
            target: AgentId::Opponent(0),
            ..
        }
    )));
}

#[test]
fn an_opponent_freezes_a_robot_in_front_of_it() {
    let mut w = World::new(duel(), config(PlannerKind::Idle, ControlKind::Api)).unwrap();
    w.opponents[0].pose = Pose::new(4.0, 3.0, std::f32::consts::PI);
    w.order_opponent(0, OpponentOrder::Tag).unwrap();
    w.step();
    assert!(w.robot_frozen(0));
    assert!(
        w.events()
            .iter()
            .any(|e| matches!(e.kind, EventKind::RobotTagged { .. }))
    );
    // Cool-down: a second order within 1 s does not fire.
    w.order_opponent(0, OpponentOrder::Tag).unwrap();
    w.step();
    assert!(
        w.robots[0].scan.ranges.is_empty(),
        "from the tick after the hit, a frozen robot does not sense"
    );
    let shots = w
        .events()
        .iter()
        .filter(|e| matches!(e.kind, EventKind::Shot { .. }))
        .count();
    assert_eq!(shots, 1);
    for _ in 0..200 {
        w.step();
    }
    assert!(!w.robot_frozen(0), "frozen for 10 s only");
}

#[test]
fn the_time_limit_ends_the_match_for_the_opponents() {
    let cfg = MatchConfig {
        time_limit_ticks: 40,
        ..config(PlannerKind::Idle, ControlKind::Bot)
    };
    let mut w = World::new(duel(), cfg).unwrap();
    // A loop on the tick ends with the match: a finished match's step does not advance.
    let stepped = std::iter::from_fn(|| (w.tick < 100 && w.step()).then_some(())).count();
    assert_eq!((stepped, w.tick), (40, 40));
    assert!(!w.step(), "a finished match stays at its last tick");
    assert_eq!((w.tick, w.winner), (40, Some(Side::Opponents)));
}

#[test]
fn orders_are_checked() {
    let mut w = World::new(duel(), config(PlannerKind::Idle, ControlKind::Api)).unwrap();
    assert!(matches!(
        w.order_opponent(0, OpponentOrder::Waypoints(vec![Point2::new(13.0, 1.0)])),
        Err(OrderError::OutsideArena { .. })
    ));
    assert!(matches!(
        w.order_opponent(3, OpponentOrder::Stop),
        Err(OrderError::UnknownOpponent(_))
    ));
    let mut b = World::new(duel(), config(PlannerKind::Idle, ControlKind::Bot)).unwrap();
    assert!(matches!(
        b.order_opponent(0, OpponentOrder::Stop),
        Err(OrderError::NotApiControlled(_))
    ));
}

#[test]
fn random_placement_is_seeded_and_free() {
    let cfg = |seed| MatchConfig {
        placement: Placement::Random,
        seed,
        robots: 2,
        opponents: 2,
        ..config(PlannerKind::Idle, ControlKind::Bot)
    };
    let a = World::new(duel(), cfg(5)).unwrap();
    let b = World::new(duel(), cfg(5)).unwrap();
    let c = World::new(duel(), cfg(6)).unwrap();
    assert_eq!(a.digest(), b.digest());
    assert_ne!(a.digest(), c.digest());
    for r in &a.robots {
        assert!(a.arena.disc_is_free(r.pose.pos, AGENT_RADIUS));
    }
}

#[test]
fn an_evading_bot_runs_from_a_robot_it_sees() {
    let cfg = MatchConfig {
        opponent_bot: BotKind::Evade,
        opponent_control: ControlKind::Bot,
        placement: Placement::Given {
            robots: vec![[3.0, 2.0, 0.0]],
            opponents: vec![[5.0, 2.0]],
        },
        ..config(PlannerKind::Idle, ControlKind::Bot)
    };
    let mut w = World::new(duel(), cfg).unwrap();
    for _ in 0..200 {
        w.step();
    }
    let robot = w.robots[0].pose.pos;
    let bot = w.opponents[0].pose.pos;
    let hidden = !w.arena.line_of_sight(robot, bot);
    assert!(
        (bot - robot).norm() > 5.0 || hidden,
        "the bot fled: {bot:?}"
    );
}

#[test]
fn a_wandering_bot_keeps_moving_and_stays_in_free_space() {
    let cfg = MatchConfig {
        time_limit_ticks: 100_000,
        ..config(PlannerKind::Idle, ControlKind::Bot)
    };
    let mut w = World::new(duel(), cfg).unwrap();
    let mut visited = Vec::new();
    for t in 0..2_000 {
        w.step();
        let p = w.opponents[0].pose.pos;
        assert!(
            w.arena.disc_is_free(p, AGENT_RADIUS - 1e-3),
            "tick {t}: {p:?}"
        );
        if t % 200 == 0 {
            visited.push(p);
        }
    }
    let spread = visited
        .iter()
        .map(|p| (p - visited[0]).norm())
        .fold(0.0, f32::max);
    assert!(spread > 3.0, "wandered about: {visited:?}");
}

/// Regression (review of the tracker): a robot that tags an opponent in the same tick as
/// it is itself frozen still reports the hit, so the role counts keep adding up.
#[test]
fn a_hit_by_a_robot_frozen_in_the_same_tick_still_counts() {
    let cfg = MatchConfig {
        opponents: 2,
        placement: Placement::Given {
            robots: vec![[3.0, 3.0, 0.0]],
            opponents: vec![[6.0, 3.0], [1.0, 3.0]],
        },
        ..config(PlannerKind::Baseline, ControlKind::Api)
    };
    let mut w = World::new(duel(), cfg).unwrap();
    // o1 stands behind the robot; turn it to face the robot.
    w.opponents[1].pose.theta = 0.0;
    assert!(
        w.robots[0].command.tag,
        "the robot sees o0 dead ahead and fires"
    );
    w.order_opponent(1, OpponentOrder::Tag).unwrap();
    w.step();
    assert!(w.opponents[0].tagged, "o0 was hit");
    assert!(
        w.robot_frozen(0),
        "and the robot was frozen in the same tick"
    );
    assert_eq!(w.team.trackers[0].untagged_count(), 1);
}

#[test]
fn a_persons_shot_is_judged_where_its_screen_showed_the_robots() {
    let mut w = World::new(duel(), config(PlannerKind::Idle, ControlKind::Human)).unwrap();
    // The opponent faces east along y = 3; the robot stands in its line of fire...
    w.opponents[0].pose = Pose::new(3.0, 3.0, 0.0);
    w.robots[0].pose = Pose::new(5.0, 3.0, 0.0);
    w.step();
    w.step();
    let seen = w.tick;
    // ...then is somewhere else, well outside the ±5° cone.
    w.robots[0].pose = Pose::new(5.0, 1.0, 0.0);
    w.step();
    let tagged = |w: &World| {
        w.events()
            .iter()
            .any(|e| matches!(e.kind, EventKind::RobotTagged { .. }))
    };
    let fire = |seen_tick: Option<u64>| {
        let mut w = w.clone();
        w.set_human_input(
            0,
            HumanInput {
                tag: true,
                seen_tick,
                ..HumanInput::default()
            },
        );
        w.step();
        w
    };
    // Fired at what the screen showed two ticks ago: a hit, where the robot was.
    assert!(tagged(&fire(Some(seen))));
    // On the present (no tick said, or one from the future): a miss.
    assert!(!tagged(&fire(None)));
    assert!(!tagged(&fire(Some(w.tick + 1))));
    // Beyond the bound: judged where the robot was at the bound, already gone: a miss.
    let mut old = w.clone();
    for _ in 0..MAX_REWIND_TICKS {
        old.step();
    }
    old.set_human_input(
        0,
        HumanInput {
            tag: true,
            seen_tick: Some(seen),
            ..HumanInput::default()
        },
    );
    old.step();
    assert!(!tagged(&old));
}

fn api_duel() -> World {
    World::new(duel(), config(PlannerKind::Api, ControlKind::Api)).unwrap()
}

#[test]
fn an_api_robot_holds_its_velocities_until_told_otherwise_and_stands_still_before() {
    let mut w = api_duel();
    let start = w.robots[0].pose;
    for _ in 0..10 {
        w.step();
    }
    assert_eq!(w.robots[0].pose, start, "no order, no motion");
    w.order_robot(
        0,
        RobotOrder::Drive {
            forward: 1.0,
            turn: 0.0,
            tag: false,
        },
    )
    .unwrap();
    for _ in 0..20 {
        w.step();
    }
    let moved = w.robots[0].pose.pos.x - start.pos.x;
    let top = w.config.physics.robot_speed;
    assert!(
        (moved - top).abs() < 0.05,
        "moved {moved} m in 1 s at {top} m/s"
    );
    w.order_robot(0, RobotOrder::Stop).unwrap();
    let here = w.robots[0].pose;
    w.step();
    assert_eq!(w.robots[0].pose, here);
}

#[test]
fn an_api_robot_drives_its_waypoints_around_a_pillar() {
    let mut w = api_duel();
    // Behind the pillar (5.5..6.5 × 4.5..5.5) from (1, 3): the straight line crosses it.
    let goal = Point2::new(8.0, 5.0);
    w.order_robot(0, RobotOrder::Waypoints(vec![Point2::new(4.0, 2.0), goal]))
        .unwrap();
    let mut closest = f32::MAX;
    for _ in 0..600 {
        w.step();
        closest = closest.min((w.robots[0].pose.pos - goal).norm());
    }
    assert!(closest < 0.3, "got within {closest} m of the last waypoint");
    assert_eq!(w.robots[0].command.motion, Motion::Stop, "it stops there");
    let err = w
        .order_robot(0, RobotOrder::Waypoints(vec![Point2::new(6.0, 5.0)]))
        .unwrap_err();
    assert!(
        matches!(err, RobotOrderError::BadWaypoint { index: 0, .. }),
        "{err}"
    );
    let err = w
        .order_robot(0, RobotOrder::Waypoints(vec![Point2::new(13.0, 1.0)]))
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "waypoints[0]: [13, 1] lies outside the arena"
    );
}

#[test]
fn an_api_robot_fires_once_per_order_and_orders_are_checked() {
    let mut w = api_duel();
    w.order_robot(
        0,
        RobotOrder::Drive {
            forward: 0.0,
            turn: 0.0,
            tag: true,
        },
    )
    .unwrap();
    for _ in 0..40 {
        w.step();
    }
    let shots = w
        .events()
        .iter()
        .filter(|e| {
            matches!(
                e.kind,
                EventKind::Shot {
                    by: AgentId::Robot(0),
                    ..
                }
            )
        })
        .count();
    assert_eq!(shots, 1);
    assert_eq!(
        w.order_robot(
            0,
            RobotOrder::Drive {
                forward: 2.0,
                turn: 0.0,
                tag: false
            }
        ),
        Err(RobotOrderError::OutOfRange {
            field: "forward",
            value: 2.0
        })
    );
    assert!(matches!(
        w.order_robot(3, RobotOrder::Stop),
        Err(RobotOrderError::UnknownRobot(_))
    ));
    let mut planned = World::new(duel(), config(PlannerKind::Idle, ControlKind::Api)).unwrap();
    assert_eq!(
        planned.order_robot(0, RobotOrder::Stop),
        Err(RobotOrderError::NotApiDriven)
    );
}

#[test]
fn an_observation_is_what_the_robot_knows() {
    let mut w = World::new(
        duel(),
        MatchConfig {
            robots: 2,
            ..config(PlannerKind::Api, ControlKind::Api)
        },
    )
    .unwrap();
    w.order_robot(
        0,
        RobotOrder::Drive {
            forward: 0.5,
            turn: 0.2,
            tag: false,
        },
    )
    .unwrap();
    for _ in 0..30 {
        w.step();
    }
    let o = w.observation(0).unwrap();
    assert_eq!(o.tick, 30);
    assert_eq!(o.scan.len(), w.config.physics.laser_beams);
    assert_eq!(o.estimate, w.robots[0].estimate);
    assert_eq!(o.odometry, w.robots[0].odometry);
    assert!(o.tag_ready && !o.frozen);
    // A perfect radio: the teammate's own estimate, as of now.
    assert_eq!(o.teammates.len(), 1);
    assert_eq!(o.teammates[0].robot, 1);
    assert_eq!(o.teammates[0].pose, w.robots[1].estimate);
    assert_eq!(o.teammates[0].age_ticks, 0);
    assert!(w.observation(2).is_none());
}

#[test]
fn a_persons_robot_seat_feeds_the_team_and_tags_like_a_robot() {
    // r1 is the seat (1, 1) facing east; o1 stands ahead of it, o0 far behind the pillar.
    let config = MatchConfig {
        robots: 2,
        opponents: 2,
        pursuer_slots: 1,
        planner: PlannerKind::Coordinated,
        opponent_control: ControlKind::Api,
        placement: Placement::Given {
            robots: vec![[1.0, 4.5, std::f32::consts::PI], [1.0, 1.0, 0.0]],
            opponents: vec![[11.0, 5.0], [4.0, 1.0]],
        },
        ..MatchConfig::default()
    };
    let mut w = World::new(duel(), config).unwrap();
    assert!(!w.robot_seat(0) && w.robot_seat(1));
    assert!(!w.robot_outside(1), "a free seat is the planner's");
    assert_eq!(
        w.apply(&WorldInput::SeatRobot {
            robot: 0,
            name: "ada".into()
        }),
        Err(InputError::NoRobotSeat(0))
    );
    w.apply(&WorldInput::SeatRobot {
        robot: 1,
        name: "ada".into(),
    })
    .unwrap();
    assert!(w.robot_outside(1));
    let seat_start = w.robots[1].pose;
    w.step();
    // Its laser saw o1, and the team's tracker split a role off for it.
    assert!(!w.robots[1].scan.detections.is_empty());
    assert!(
        w.events()
            .iter()
            .any(|e| matches!(e.kind, EventKind::RoleSplit { .. })),
        "{:?}",
        w.events()
    );
    // Nobody but the person moves it; their trigger tags o1.
    assert_eq!(w.robots[1].pose, seat_start);
    w.apply(&WorldInput::Robot {
        robot: 1,
        order: RobotOrder::Drive {
            forward: 0.0,
            turn: 0.0,
            tag: true,
        },
    })
    .unwrap();
    w.step();
    assert!(w.events().iter().any(|e| e.kind
        == EventKind::Tag {
            by: AgentId::Robot(1),
            target: AgentId::Opponent(1)
        }));
    assert!(w.events().iter().any(|e| e.kind
        == EventKind::PlayerJoined {
            agent: AgentId::Robot(1),
            name: "ada".into()
        }));
}

#[test]
fn a_hunters_shot_is_judged_where_their_screen_showed_the_opponents() {
    // r1, a person's robot, faces east at (1, 1); o0 walks north from 4 m ahead of it.
    let config = MatchConfig {
        robots: 2,
        opponents: 1,
        pursuer_slots: 1,
        planner: PlannerKind::Idle,
        opponent_control: ControlKind::Api,
        placement: Placement::Given {
            robots: vec![[11.0, 5.0, std::f32::consts::PI], [1.0, 1.0, 0.0]],
            opponents: vec![[4.0, 1.0]],
        },
        ..MatchConfig::default()
    };
    let mut w = World::new(duel(), config).unwrap();
    w.apply(&WorldInput::SeatRobot {
        robot: 1,
        name: "ada".into(),
    })
    .unwrap();
    w.order_opponent(0, OpponentOrder::Waypoints(vec![Point2::new(4.0, 5.0)]))
        .unwrap();
    w.step();
    let drawn = w.tick; // o0 a few centimetres north: in the tag cone
    for _ in 0..9 {
        w.step(); // half a metre north now: 9.5° off r1's heading, out of the 5° cone
    }
    let fire = |seen_tick: Option<u64>| {
        let mut w = w.clone();
        w.apply(&WorldInput::RobotKeys {
            robot: 1,
            input: HumanInput {
                forward: 0.0,
                turn: 0.0,
                tag: true,
                seen_tick,
            },
        })
        .unwrap();
        w.step();
        w.opponents[0].tagged
    };
    assert!(!fire(None), "judged on the present, the shot misses");
    assert!(
        fire(Some(drawn)),
        "judged where the screen showed o0, it hits"
    );
    // Only a pursuer slot takes a person's keys.
    assert_eq!(
        w.apply(&WorldInput::RobotKeys {
            robot: 0,
            input: HumanInput::default()
        }),
        Err(InputError::NoRobotSeat(0))
    );
}

#[test]
fn a_free_pursuer_slot_is_the_planners_and_a_person_takes_it_over() {
    let config = MatchConfig {
        robots: 2,
        opponents: 1,
        pursuer_slots: 1,
        planner: PlannerKind::Baseline,
        opponent_control: ControlKind::Api,
        ..MatchConfig::default()
    };
    let mut w = World::new(duel(), config).unwrap();
    let moved = |w: &mut World| {
        let before = w.robots[1].pose;
        for _ in 0..40 {
            w.step();
        }
        (w.robots[1].pose.pos - before.pos).norm() > 0.1
    };
    assert!(moved(&mut w), "free, the team's planner drives it");
    let seat = |robot| WorldInput::SeatRobot {
        robot,
        name: "ada".into(),
    };
    w.apply(&seat(1)).unwrap();
    assert!(!moved(&mut w), "taken, it waits for the person's keys");
    w.apply(&WorldInput::UnseatRobot {
        robot: 1,
        name: "ada".into(),
    })
    .unwrap();
    assert!(moved(&mut w), "left, the planner drives it again");
}
