//! Same seed + same inputs ⇒ the same match, tick for tick (digest of the whole state).

use std::path::Path;

use lasertag::maps::MapStore;
use lasertag_core::bots::BotKind;
use lasertag_core::planner::PlannerKind;
use lasertag_core::world::World;
use lasertag_core::world::{MatchConfig, Placement};

fn digests(seed: u64) -> Vec<u64> {
    let store = MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps")).unwrap();
    let arena = store.get("office").unwrap().arena.clone();
    let config = MatchConfig {
        robots: 3,
        opponents: 4,
        opponent_bot: BotKind::Evade,
        planner: PlannerKind::Baseline,
        placement: Placement::Random,
        time_limit_ticks: 1_000_000,
        seed,
        ..MatchConfig::default()
    };
    let mut world = World::new(arena, config).unwrap();
    (0..2_000)
        .map(|_| {
            world.step();
            world.digest()
        })
        .collect()
}

#[test]
fn the_same_seed_gives_the_same_digest_after_every_one_of_2000_ticks() {
    let a = digests(11);
    let b = digests(11);
    assert_eq!(a.len(), 2_000);
    let first_difference = a.iter().zip(&b).position(|(x, y)| x != y);
    assert_eq!(first_difference, None, "runs diverged");
    let c = digests(12);
    assert_ne!(a.last(), c.last(), "another seed plays another match");
}

/// A match on `office` with `planner` and `radio`, stepped `ticks` times: the digest after
/// every tick, and the robots' trackers at the end.
fn run_with_radio(
    planner: PlannerKind,
    radio: lasertag_core::radio::Settings,
    ticks: usize,
) -> (Vec<u64>, Vec<lasertag_core::tracker::Tracker>) {
    let store = MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps")).unwrap();
    let arena = store.get("office").unwrap().arena.clone();
    let config = MatchConfig {
        robots: 3,
        opponents: 3,
        opponent_bot: BotKind::Evade,
        planner,
        placement: Placement::Random,
        time_limit_ticks: 1_000_000,
        seed: 5,
        radio,
        tracker: lasertag_core::tracker::Settings {
            particles_per_role: 300,
            ..Default::default()
        },
        ..MatchConfig::default()
    };
    let mut world = World::new(arena, config).unwrap();
    let digests = (0..ticks)
        .map(|_| {
            world.step();
            world.digest()
        })
        .collect();
    (digests, world.team.trackers.clone())
}

/// Team radio: a perfect radio must give exactly the centralised team. Forcing
/// the per-robot machinery (one tracker per robot, every sighting sent through the channel,
/// each robot planning from its own tracker) must replay the shared tracker's match tick for
/// tick, with every robot's belief equal to the shared one.
#[test]
fn per_robot_trackers_over_a_perfect_radio_replay_the_centralised_team_exactly() {
    for planner in [PlannerKind::Coordinated, PlannerKind::Baseline] {
        let (shared, shared_trackers) =
            run_with_radio(planner, lasertag_core::radio::Settings::default(), 1_500);
        let forced = lasertag_core::radio::Settings {
            per_robot: true,
            ..Default::default()
        };
        let (per_robot, trackers) = run_with_radio(planner, forced, 1_500);
        assert_eq!(shared_trackers.len(), 1, "{planner:?}: one shared tracker");
        assert_eq!(trackers.len(), 3, "{planner:?}: one tracker per robot");
        let first_difference = shared.iter().zip(&per_robot).position(|(a, b)| a != b);
        assert_eq!(first_difference, None, "{planner:?}: runs diverged");
        for (i, t) in trackers.iter().enumerate() {
            assert_eq!(
                t.roles, shared_trackers[0].roles,
                "{planner:?}: robot {i}'s belief differs from the shared one"
            );
        }
    }
}

/// The converse, so that the test above could fail: a radio with a latency changes the match.
#[test]
fn a_radio_with_latency_and_loss_plays_another_match_and_replays_itself() {
    let lossy = lasertag_core::radio::Settings {
        latency_ticks: 5,
        loss: 0.2,
        ..Default::default()
    };
    let (a, trackers) = run_with_radio(PlannerKind::Coordinated, lossy.clone(), 1_000);
    let (b, _) = run_with_radio(PlannerKind::Coordinated, lossy, 1_000);
    assert_eq!(a, b, "the same seed replays the same lossy radio");
    let (shared, _) = run_with_radio(
        PlannerKind::Coordinated,
        lasertag_core::radio::Settings::default(),
        1_000,
    );
    assert_ne!(a.last(), shared.last(), "latency and loss change the match");
    assert!(
        trackers.windows(2).any(|w| w[0].roles != w[1].roles),
        "robots hear different things, so their beliefs differ"
    );
}
