//! The engine's refusals, one per bound and per kind of bad float, its calls' checks, and
//! the fuzz body on fixed inputs.

use super::exercise::{Reached, exercise};
use super::*;
use crate::planner::PlannerKind;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn room() -> MapSpec {
    MapSpec {
        name: "room".into(),
        width: 12.0,
        height: 6.0,
        obstacles: vec![vec![[5.5, 2.5], [6.5, 2.5], [6.5, 3.5], [5.5, 3.5]]],
        robot_spawns: vec![[1.0, 3.0, 0.0], [1.0, 1.0, 0.0]],
        opponent_spawns: vec![[11.0, 5.0]],
        landmarks: vec![],
    }
}

/// The arguments the Python package gives for the default match on `room`.
fn args() -> EngineArgs {
    let mut config = MatchConfig {
        planner: PlannerKind::Api,
        ..MatchConfig::default()
    };
    config.tracker.particles_per_role = 10;
    EngineArgs {
        map: room(),
        config,
        worlds: 2,
        seed: 7,
        max_steps: Some(50),
        ticks_per_step: 1,
        rewards: Rewards::default(),
        detections: 1,
        beams: 181,
        laser_range: 8.0,
        fov_deg: 180.0,
    }
}

/// The field `change` makes the checks refuse, and their message.
fn refused(change: impl FnOnce(&mut EngineArgs)) -> (String, String) {
    let mut a = args();
    change(&mut a);
    match a.check() {
        Err(Refusal::Value { field, message }) => (field, message),
        other => panic!("not refused by field: {other:?}"),
    }
}

#[test]
fn every_count_is_bounded_before_anything_is_allocated_for_it() {
    // Each of these would allocate for its count (and abort) unless bounded first.
    assert_eq!(refused(|a| a.config.robots = 1_000_000_000).0, "robots");
    assert_eq!(refused(|a| a.config.robots = 0).0, "robots");
    assert_eq!(refused(|a| a.config.opponents = usize::MAX).0, "opponents");
    assert_eq!(refused(|a| a.config.opponents = 0).0, "opponents");
    assert_eq!(refused(|a| a.detections = 1_000_000_000).0, "detections");
    assert_eq!(refused(|a| a.worlds = 1_000_000).0, "worlds");
    assert_eq!(refused(|a| a.worlds = 0).0, "worlds");
    let (field, message) = refused(|a| {
        a.config.robots = 8;
        a.worlds = MAX_AGENTS / 8 + 1;
    });
    assert_eq!(field, "worlds");
    assert!(message.contains("at most 16384"), "{message}");
    assert_eq!(refused(|a| a.ticks_per_step = 0).0, "ticks_per_step");
    assert_eq!(
        refused(|a| a.ticks_per_step = MAX_TICKS_PER_STEP + 1).0,
        "ticks_per_step"
    );
    assert_eq!(refused(|a| a.max_steps = Some(0)).0, "max_steps");
    let (field, message) = refused(|a| a.max_steps = Some(MAX_STEPS + 1));
    assert_eq!(field, "max_steps");
    assert!(message.contains("1..=1728000"), "{message}");
    assert_eq!(refused(|a| a.beams = 0).0, "beams");
    assert_eq!(refused(|a| a.beams = usize::MAX).0, "beams");
    assert_eq!(
        refused(|a| a.config.outside_robots = vec![true; 9]).0,
        "planner"
    );
    assert_eq!(
        refused(|a| a.config.placement = Placement::Given {
            robots: vec![[1.0, 3.0, 0.0]; 3],
            opponents: vec![],
        })
        .0,
        "robot_starts"
    );
}

#[test]
fn the_bounds_themselves_are_accepted() {
    let mut a = args();
    a.config.robots = MAX_ROBOTS;
    a.config.opponents = MAX_OPPONENTS;
    a.detections = MAX_DETECTIONS;
    a.worlds = MAX_AGENTS / MAX_ROBOTS;
    a.ticks_per_step = MAX_TICKS_PER_STEP;
    a.max_steps = Some(MAX_STEPS);
    a.config.time_limit_ticks = time_limit_ticks(MAX_TIME_LIMIT_S).unwrap();
    let checked = a.check().unwrap();
    assert_eq!(checked.worlds() * checked.spec().config.robots, MAX_AGENTS);
}

#[test]
fn no_float_argument_takes_nan_or_an_infinity() {
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        assert!(time_limit_ticks(bad).is_err(), "time limit {bad}");
        assert_eq!(refused(|a| a.laser_range = bad).0, "laser_range");
        assert_eq!(refused(|a| a.fov_deg = bad).0, "fov_deg");
        assert_eq!(refused(|a| a.rewards.tag = bad).0, "rewards.tag");
        assert_eq!(refused(|a| a.rewards.team_tag = bad).0, "rewards.team_tag");
        assert_eq!(refused(|a| a.rewards.tick = bad).0, "rewards.tick");
        assert_eq!(refused(|a| a.map.width = bad).0, "map.width");
    }
    // NaN fails both `s <= 0` and `s > max`: only a range's membership refuses it.
    let e = time_limit_ticks(f64::NAN).unwrap_err().to_string();
    assert_eq!(e, "time_limit_s: NaN must be finite and in (0, 86400]");
    assert!(time_limit_ticks(0.0).is_err() && time_limit_ticks(86_400.5).is_err());
    assert_eq!(time_limit_ticks(6.0), Ok(120));
    // A laser other than the match's would scale the vectors wrongly.
    assert_eq!(refused(|a| a.laser_range = 9.0).0, "laser_range");
    assert_eq!(refused(|a| a.fov_deg = 90.0).0, "fov_deg");
    assert_eq!(refused(|a| a.config.time_limit_ticks = 0).0, "time_limit_s");
    // A start that is finite in f64 but not in f32, or a heading past the bound.
    let (field, _) = refused(|a| {
        a.config.placement = Placement::Given {
            robots: vec![[1.0, 3.0, f32::INFINITY]],
            opponents: vec![],
        };
        a.config.robots = 1;
    });
    assert_eq!(field, "robot_starts[0]");
}

#[test]
fn the_calls_check_their_arrays_and_worlds() {
    let mut engine = Engine::new(args()).unwrap();
    let (robots, size) = (engine.robots(), engine.size());
    let mut obs = vec![0.0; robots * size];
    let mut rewards = vec![0.0; robots];
    let actions = vec![0.5; robots * 3];
    assert_eq!(
        engine.step(2, &actions, &mut obs, &mut rewards),
        Err(Refusal::NoWorld {
            world: 2,
            worlds: 2
        })
    );
    let e = engine
        .step(0, &actions[1..], &mut obs, &mut rewards)
        .unwrap_err();
    assert!(
        e.to_string()
            .starts_with("actions: 5 values, the engine needs 6"),
        "{e}"
    );
    assert!(
        engine
            .step(0, &actions, &mut obs[1..], &mut rewards)
            .is_err()
    );
    assert!(engine.reset(usize::MAX, 1, &mut obs).is_err());
    let mut all = vec![0.0; 2 * robots * size];
    assert!(engine.reset_all(&mut all, None, Some(&[1, 2, 3])).is_err());
    engine.reset_all(&mut all, Some(3), None).unwrap();
    assert_eq!(engine.seeds(), vec![3, 4]);
    let out = engine.step(1, &actions, &mut obs, &mut rewards).unwrap();
    assert_eq!(out.tick, 1);
    assert_eq!(
        check_shape("actions", &[3, robots], &[robots, 3])
            .unwrap_err()
            .to_string(),
        "actions: shape [3, 2], the engine needs [2, 3]"
    );
}

#[test]
fn step_all_is_each_worlds_step() {
    let mut engine = Engine::new(args()).unwrap();
    let mut single = Engine::new(args()).unwrap();
    let (robots, size) = (engine.robots(), engine.size());
    let actions: Vec<f32> = (0..2 * robots * 3)
        .map(|i| (i as f32 * 0.37).sin())
        .collect();
    let mut obs = vec![0.0; 2 * robots * size];
    let mut rewards = vec![0.0; 2 * robots];
    let (mut term, mut trunc) = (vec![false; 2], vec![false; 2]);
    let mut one = vec![0.0; robots * size];
    let mut one_rewards = vec![0.0; robots];
    for _ in 0..10 {
        engine
            .step_all(&actions, &mut obs, &mut rewards, &mut term, &mut trunc)
            .unwrap();
        for w in 0..2 {
            let a = &actions[w * robots * 3..(w + 1) * robots * 3];
            single.step(w, a, &mut one, &mut one_rewards).unwrap();
            assert_eq!(one, obs[w * robots * size..(w + 1) * robots * size]);
        }
    }
    assert!(
        engine
            .step_all(&actions, &mut obs, &mut rewards, &mut term, &mut [false; 3])
            .is_err()
    );
}

#[test]
fn a_timing_run_is_bounded_as_a_step_request_is() {
    assert_eq!(MAX_STEPS, 86_400 * 20);
    assert!(check_timed(MAX_TIMED_TICKS, 1).is_ok());
    assert!(check_timed(1, MAX_TICKS_PER_STEP).is_ok());
    for (steps, ticks) in [
        (0, 1),
        (MAX_TIMED_TICKS + 1, 1),
        (2, MAX_TICKS_PER_STEP),
        (u64::MAX, 3),
    ] {
        let e = check_timed(steps, ticks).unwrap_err();
        assert!(e.to_string().starts_with("steps: "), "{e}");
    }
}

/// A closet with room for two agents 1 m apart only near its ends: random starts that put
/// the first agent in its middle leave the second nowhere.
fn closet() -> EngineArgs {
    let mut a = args();
    a.map = MapSpec {
        name: "closet".into(),
        width: 2.0,
        height: 1.0,
        obstacles: vec![],
        robot_spawns: vec![[0.5, 0.5, 0.0]],
        opponent_spawns: vec![[1.5, 0.5]],
        landmarks: vec![],
    };
    a.config.robots = 1;
    a.config.placement = Placement::Random;
    a.worlds = 1;
    a.max_steps = Some(1);
    a
}

#[test]
fn a_next_episode_that_places_no_match_is_an_error_naming_its_world_and_seed() {
    // A first episode that places, then one episode a step until a seed places none.
    let mut engine = (0..200)
        .find_map(|seed| Engine::new(EngineArgs { seed, ..closet() }).ok())
        .expect("some seed places the first episode");
    let size = engine.size();
    let (mut obs, mut rewards) = (vec![0.0; size], vec![0.0; 1]);
    let (mut term, mut trunc) = ([false], [false]);
    let step =
        |e: &mut Engine,
         obs: &mut [f32],
         rewards: &mut [f64],
         term: &mut [bool],
         trunc: &mut [bool]| { e.step_all(&[0.0; 3], obs, rewards, term, trunc) };
    let e = (0..400)
        .find_map(|_| step(&mut engine, &mut obs, &mut rewards, &mut term, &mut trunc).err())
        .expect("some seed places no match");
    let Refusal::Restart { world, seed, .. } = &e else {
        panic!("{e:?}");
    };
    assert_eq!(*world, 0);
    let text = e.to_string();
    assert!(
        text.starts_with(&format!(
            "world 0: its next episode (seed {seed}) could not start: "
        )) && text.contains("no free place")
            && text.contains("placement \"spawns\""),
        "{text}"
    );
    // Not a replay of the ended episode: the world stays ended, and a later call draws
    // its next seed, which starts once one places.
    let next = (0..400)
        .find(|_| step(&mut engine, &mut obs, &mut rewards, &mut term, &mut trunc).is_ok())
        .expect("a later seed places");
    assert!(next < 400);
    assert_ne!(engine.seeds()[0], *seed);
    assert_eq!(engine.world(0).unwrap().episode.world().tick, 0);
}

#[test]
fn the_fuzz_body_runs_on_fixed_inputs() {
    let mut inputs: Vec<Vec<u8>> = vec![
        vec![],
        vec![0; 64],
        vec![0xff; 64],
        vec![7; 300],
        // Every count at its widest decoding (224 and above reads 8 raw bytes).
        [vec![230], vec![0xff; 8], vec![0; 40]].concat(),
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    for _ in 0..48 {
        let n = rng.random_range(0..400);
        inputs.push((0..n).map(|_| rng.random()).collect());
    }
    let reached: Vec<Reached> = inputs.iter().map(|d| exercise(d)).collect();
    // The inputs reach every part: refusals, checks alone, and steps of built engines.
    assert!(reached.contains(&Reached::Refused));
    assert!(reached.contains(&Reached::Checked));
    assert!(
        reached
            .iter()
            .any(|r| matches!(r, Reached::Built { calls } if *calls > 3)),
        "{reached:?}"
    );
}
