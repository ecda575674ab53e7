//! The `tracking` object of a match's state over real HTTP: the team's belief measured
//! against the truth (GOSPA, docs/tracker.md): its parts add up, it is small once a robot
//! sees the opponent, and zero once nobody is left to track.

mod common;

use common::{TestServer, duel_map};
use serde_json::{Value, json};

/// The GOSPA of `state`, after checking that its parts add up (to the millimetre rounding).
fn tracking(state: &Value) -> f64 {
    let t = &state["tracking"];
    let num = |k: &str| {
        t[k].as_f64()
            .unwrap_or_else(|| panic!("tracking.{k} in {t}"))
    };
    assert_eq!((num("c"), num("p")), (2.0, 2.0), "{t}");
    let (gospa, local) = (num("gospa"), num("localisation"));
    let (missed, false_targets) = (num("missed"), num("false"));
    let sum = local * local + 2.0 * (missed + false_targets);
    assert!(
        (gospa * gospa - sum).abs() < 0.01,
        "parts do not add up: {t}"
    );
    gospa
}

/// A robot facing an opponent 4 m ahead detects it on its first scan, and its belief lands
/// on it: well within the 2 m cut-off, nothing missed. The live state and the step's answer
/// agree.
#[tokio::test]
async fn a_seen_opponent_is_tracked_within_the_cut_off() {
    let server = TestServer::start().await;
    let id = server
        .create_match(json!({"map": duel_map(), "clock": "manual", "robots": 1,
                             "opponent_control": "api", "planner": "idle",
                             "opponent_starts": [[5.0, 4.0]]}))
        .await;
    let before = server.get(&format!("/api/matches/{id}")).await;
    assert_eq!(before.status, 200);
    tracking(&before.body);
    let stepped = server.step(&id, 2).await;
    let gospa = tracking(&stepped);
    assert!(gospa < 0.5, "{}", stepped["tracking"]);
    assert_eq!(stepped["tracking"]["missed"], 0);
    assert_eq!(stepped["tracking"]["false"], 0);
    let state = server.get(&format!("/api/matches/{id}")).await;
    assert_eq!(state.body["tracking"], stepped["tracking"]);
}

/// Once the only opponent is tagged there is nobody to track and the tagged role gives no
/// estimate: zero, not a miss.
#[tokio::test]
async fn with_every_opponent_tagged_there_is_nothing_to_miss() {
    let server = TestServer::start().await;
    let id = server
        .create_match(json!({"map": duel_map(), "clock": "manual", "robots": 1,
                             "opponent_control": "api", "planner": "baseline", "seed": 7}))
        .await;
    let r = server
        .command(&id, "o0", json!({"waypoints": [[9.0, 6.8], [5.0, 4.0]]}))
        .await;
    assert_eq!(r.status, 204, "{}", r.body);
    let state = server.step(&id, 2_000).await;
    assert_eq!(state["winner"], "robots", "{state}");
    assert_eq!(tracking(&state), 0.0, "{}", state["tracking"]);
    assert_eq!(state["tracking"]["missed"], 0);
    assert_eq!(state["tracking"]["false"], 0);
}
