//! Unit tests of the research episodes on a small arena built in code (the Python suite
//! compares them with the HTTP backend on the shipped maps).

use super::*;
use crate::bots::BotKind;
use crate::planner::PlannerKind;
use crate::sim::arena::MapDef;
use nalgebra::Point2;

fn room() -> Arc<Arena> {
    Arc::new(Arena::new(MapDef {
        name: "room".into(),
        width: 12.0,
        height: 6.0,
        obstacles: vec![vec![
            Point2::new(5.5, 2.5),
            Point2::new(6.5, 2.5),
            Point2::new(6.5, 3.5),
            Point2::new(5.5, 3.5),
        ]],
        robot_spawns: vec![[1.0, 3.0, 0.0], [1.0, 1.0, 0.0]],
        opponent_spawns: vec![Point2::new(11.0, 5.0)],
        landmarks: vec![],
    }))
}

fn spec(robots: usize, max_steps: Option<u64>) -> EnvSpec {
    EnvSpec {
        config: MatchConfig {
            robots,
            opponents: 1,
            opponent_bot: BotKind::Wander,
            planner: PlannerKind::Api,
            ..MatchConfig::default()
        },
        layout: Layout::new(robots, 1, 12.0, 6.0, 181, 8.0, 180.0),
        rewards: Rewards::default(),
        max_steps,
        ticks_per_step: 2,
    }
}

/// Runs an episode with a fixed policy; every vector and reward, as bits.
fn trajectory(seed: u64, steps: usize) -> Vec<u64> {
    let spec = spec(2, Some(steps as u64));
    let size = spec.layout.size();
    let mut episode = Episode::new(room(), &spec, seed).unwrap();
    let mut obs = vec![0.0; 2 * size];
    let mut rewards = vec![0.0; 2];
    episode.observe_start(&spec, &mut obs);
    let mut bits: Vec<u64> = obs.iter().map(|v| v.to_bits() as u64).collect();
    for k in 0..steps {
        let turn = if k % 10 < 5 { 0.5 } else { -0.5 };
        let actions = [1.0, turn, 1.0, 0.8, -turn, 0.0];
        let out = episode.step(&spec, &actions, &mut obs, &mut rewards);
        bits.extend(obs.iter().map(|v| v.to_bits() as u64));
        bits.extend(rewards.iter().map(|v| v.to_bits()));
        if out.terminated || out.truncated {
            break;
        }
    }
    bits
}

#[test]
fn the_vector_has_every_part_and_stays_in_its_bounds() {
    let spec = spec(2, None);
    let layout = &spec.layout;
    // 181 beams, pose 4, spread, 2 status, time, 3 per detection, 9 per teammate, then the
    // belief: a grid of 16, the 8 path sectors, 2 roles of 7 and the untagged share.
    assert_eq!(layout.size(), 181 + 4 + 1 + 2 + 1 + 3 + 9 + 16 + 8 + 14 + 1);
    let mut episode = Episode::new(room(), &spec, 3).unwrap();
    let mut obs = vec![f32::NAN; 2 * layout.size()];
    episode.observe_start(&spec, &mut obs);
    for row in obs.chunks(layout.size()) {
        for ((v, lo), hi) in row.iter().zip(layout.low()).zip(layout.high()) {
            assert!(*lo <= *v && *v <= *hi, "{v} outside [{lo}, {hi}]");
        }
        // Some beam hits a wall inside the reach.
        assert!(row[..181].iter().any(|r| *r > 0.0 && *r < 1.0));
        // The time part is 0 at the start.
        assert_eq!(row[181 + 7], 0.0);
        // The belief: the grid holds the one opponent the tracker spreads over the map,
        // the first role slot is filled and the second empty, the opponent is untagged.
        let belief = &row[181 + 8 + 3 + 9..];
        let mass: f32 = belief[..16].iter().sum();
        assert!((mass - 1.0).abs() < 1e-3, "grid mass {mass}");
        // The paths hold the part of it within 6 m of travel: some, not all of it.
        let near: f32 = belief[16..24].iter().sum();
        assert!(near > 0.0 && near < mass, "path mass {near}");
        assert_eq!((belief[24], belief[31], belief[38]), (1.0, 0.0, 1.0));
    }
}

#[test]
fn an_episode_is_a_function_of_its_seed_and_actions() {
    assert_eq!(trajectory(7, 60), trajectory(7, 60));
    assert_ne!(trajectory(7, 60), trajectory(8, 60));
}

#[test]
fn each_step_costs_its_ticks_and_steps_run_out() {
    let spec = spec(1, Some(3));
    let mut episode = Episode::new(room(), &spec, 1).unwrap();
    let mut obs = vec![0.0; spec.layout.size()];
    let mut rewards = vec![0.0];
    let mut outcomes = Vec::new();
    for _ in 0..3 {
        outcomes.push(episode.step(&spec, &[0.0, 0.0, 0.0], &mut obs, &mut rewards));
        assert_eq!(rewards[0], -0.001 * 2.0);
    }
    assert_eq!(outcomes[2].tick, 6);
    assert!(!outcomes[1].truncated && outcomes[2].truncated && !outcomes[2].terminated);
    // The time part is steps / max_steps.
    assert_eq!(obs[181 + 7], 1.0);
}

#[test]
fn actions_are_clipped_and_nan_stands_still() {
    assert_eq!(clip(2.0), 1.0);
    assert_eq!(clip(-3.0), -1.0);
    assert_eq!(clip(f32::NAN), 0.0);
    assert_eq!(clip(0.25), 0.25);
}

#[test]
fn each_world_has_its_own_reproducible_seeds() {
    let draw = |base, index| {
        let mut s = EpisodeSeeds::new(base, index);
        [s.draw(), s.draw(), s.draw()]
    };
    assert_eq!(draw(5, 0), draw(5, 0));
    assert_eq!(draw(5, 1)[0], 6);
    assert_ne!(draw(5, 0)[1..], draw(5, 1)[1..]);
    assert!(draw(u64::MAX, 3).iter().all(|s| *s < 1 << 63));
}

#[test]
fn a_shells_driver_orders_the_robots_before_every_tick_of_a_step() {
    let spec = spec(2, Some(50));
    let size = spec.layout.size();
    let (mut obs, mut rewards) = (vec![0.0; 2 * size], vec![0.0; 2]);
    let drive = [1.0, 0.3, 0.0, 1.0, -0.3, 0.0];
    // Orders given before each tick (none as actions) drive as the same actions do.
    let mut by_actions = Episode::new(room(), &spec, 7).unwrap();
    let mut by_shell = Episode::new(room(), &spec, 7).unwrap();
    let mut ticks = Vec::new();
    for _ in 0..5 {
        by_actions.step(&spec, &drive, &mut obs, &mut rewards);
        by_shell.step_with(&spec, &[], &mut obs, &mut rewards, &mut |w| {
            ticks.push(w.tick);
            for (robot, a) in drive.chunks_exact(ACTION_SIZE).enumerate() {
                let order = drive_order(a);
                w.apply(&WorldInput::Robot { robot, order }).unwrap();
            }
        });
    }
    assert_eq!(
        ticks,
        (0..10).collect::<Vec<u64>>(),
        "once before each tick"
    );
    assert_eq!(by_actions.world().digest(), by_shell.world().digest());
    // `advance` is `advance_with` doing nothing between the ticks.
    let mut plain = Episode::new(room(), &spec, 7).unwrap();
    let mut hooked = Episode::new(room(), &spec, 7).unwrap();
    let a = plain.advance(&spec, &drive, &mut rewards);
    let b = hooked.advance_with(&spec, &drive, &mut rewards, &mut |_| {});
    assert_eq!((a, plain.world().digest()), (b, hooked.world().digest()));
}

#[test]
fn a_planners_command_reads_back_as_the_action_that_gives_it() {
    let drive = |forward, turn, tag| RobotCommand {
        motion: Motion::Drive { forward, turn },
        tag,
        goal: None,
    };
    for (command, action) in [
        (drive(0.75, -0.25, true), [0.75, -0.25, 1.0]),
        (drive(1.0, 1.0, false), [1.0, 1.0, 0.0]),
        (RobotCommand::default(), [0.0, 0.0, 0.0]),
    ] {
        assert_eq!(command_action(&command), action);
        let RobotOrder::Drive { forward, turn, tag } = drive_order(&action) else {
            panic!("a drive order");
        };
        let back = drive(forward, turn, tag);
        let motion = match command.motion {
            Motion::Stop => Motion::Drive {
                forward: 0.0,
                turn: 0.0,
            },
            m => m,
        };
        assert_eq!((back.motion, back.tag), (motion, command.tag));
    }
}
