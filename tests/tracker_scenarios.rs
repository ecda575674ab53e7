//! The tracker's behaviour under occlusion, over the HTTP API on inline maps.

mod common;

use common::{TestServer, one_door_room as room_map};
use serde_json::{Value, json};

fn in_room(p: &Value) -> bool {
    p[0].as_f64().unwrap() > 10.2 && p[1].as_f64().unwrap() > 6.2
}

/// Share of a role's weight inside the room.
fn weight_in_room(role: &Value) -> f64 {
    role["particles"]
        .as_array()
        .unwrap()
        .iter()
        .zip(role["weights"].as_array().unwrap())
        .filter(|(p, _)| in_room(p))
        .map(|(_, w)| w.as_f64().unwrap())
        .sum()
}

async fn belief(server: &TestServer, id: &str) -> Value {
    let r = server.get(&format!("/api/matches/{id}/belief")).await;
    assert_eq!(r.status, 200);
    r.body
}

/// One opponent walks past the robot into the room and hides in its top-left corner; then the
/// robot, facing the door, watches for 60 s. Returns the belief's roles and the events.
async fn hide_in_room(server: &TestServer) -> (Vec<Value>, Vec<Value>) {
    let id = server
        .create_match(json!({
            "map": room_map(), "clock": "manual", "robots": 1, "opponents": 1,
            "opponent_control": "api", "planner": "idle", "seed": 1,
            "robot_starts": [[7.0, 3.0, 0.485]], "opponent_starts": [[2.0, 8.0]]
        }))
        .await;
    server
        .command(
            &id,
            "o0",
            json!({"waypoints": [[12.7, 4.8], [12.7, 7.0], [10.8, 9.3]]}),
        )
        .await;
    // About 11 m + 2.2 m + 3 m at 1 m/s.
    let state = server.step(&id, 20 * 18).await;
    let o = &state["opponents"][0];
    assert!(
        (o["x"].as_f64().unwrap() - 10.8).abs() < 0.05
            && (o["y"].as_f64().unwrap() - 9.3).abs() < 0.05,
        "{o}"
    );
    assert!(
        state["robots"][0]["detections"]
            .as_array()
            .unwrap()
            .is_empty(),
        "hidden from the robot"
    );
    let events = server.events(&id).await;
    server.step(&id, 20 * 60).await;
    let roles = belief(server, &id).await["roles"]
        .as_array()
        .unwrap()
        .clone();
    (roles, events)
}

#[tokio::test]
async fn an_opponent_seen_entering_a_one_door_room_stays_there_while_the_door_is_watched() {
    let server = TestServer::start().await;
    let (roles, events) = hide_in_room(&server).await;
    assert_eq!(roles.len(), 1, "one opponent, one role");
    let share = weight_in_room(&roles[0]);
    println!(
        "door watched: {:.1}% of the role's weight in the room after 60 s",
        share * 100.0
    );
    assert!(share >= 0.9, "only {share} in the room");
    assert!(
        events.iter().all(|e| e["kind"] != "role_split"),
        "a role for one opponent never splits"
    );
}

/// The same walk, but then the door goes unwatched: a second API opponent standing behind
/// the robot keeps it frozen, and a frozen robot senses nothing (as if it faced away).
/// With no negative information, the belief must leak back out through the door.
#[tokio::test]
async fn with_the_door_unwatched_the_belief_spreads_back_out_of_the_room() {
    let server = TestServer::start().await;
    let id = server
        .create_match(json!({
            "map": room_map(), "clock": "manual", "robots": 1, "opponents": 2,
            "opponent_control": "api", "planner": "idle", "seed": 1,
            "robot_starts": [[7.0, 3.0, 0.485]], "opponent_starts": [[2.0, 8.0], [4.0, 1.0]]
        }))
        .await;
    server
        .command(
            &id,
            "o0",
            json!({"waypoints": [[12.7, 4.8], [12.7, 7.0], [10.8, 9.3]]}),
        )
        .await;
    // o1 walks up behind the robot (outside its field of view) and ends facing it.
    server
        .command(&id, "o1", json!({"waypoints": [[5.6, 2.0], [5.74, 2.1]]}))
        .await;
    server.step(&id, 20 * 18).await;
    let roles = belief(&server, &id).await["roles"]
        .as_array()
        .unwrap()
        .clone();
    let before = roles.iter().map(weight_in_room).fold(0.0, f64::max);
    // Tag again before each freeze runs out (10 s), so the robot never senses again.
    for _ in 0..7 {
        let r = server.command(&id, "o1", json!({"tag": true})).await;
        assert_eq!(r.status, 204);
        let state = server.step(&id, 180).await;
        assert_eq!(state["robots"][0]["frozen"], true, "the robot stays blind");
    }
    let roles = belief(&server, &id).await["roles"]
        .as_array()
        .unwrap()
        .clone();
    let hider = roles
        .iter()
        .max_by(|a, b| weight_in_room(a).total_cmp(&weight_in_room(b)))
        .unwrap();
    let share = weight_in_room(hider);
    println!(
        "door unwatched: {:.1}% of the hider's role weight in the room on hiding, {:.1}% 60 s later",
        before * 100.0,
        share * 100.0
    );
    assert!(
        share < 0.85,
        "the belief should leak out of the room: {share}"
    );
}

/// Two opponents seen one after the other get a role each; once both have hidden in the same
/// room for long enough, the two clouds become indistinguishable and merge into one role for 2.
#[tokio::test]
async fn two_opponents_seen_apart_split_into_two_roles_then_merge_when_hidden_together() {
    let server = TestServer::start().await;
    let id = server
        .create_match(json!({
            "map": room_map(), "clock": "manual", "robots": 1, "opponents": 2,
            "opponent_control": "api", "planner": "idle", "seed": 4,
            "robot_starts": [[7.0, 3.0, 0.485]], "opponent_starts": [[2.0, 8.0], [1.0, 9.0]]
        }))
        .await;
    let initial = belief(&server, &id).await;
    assert_eq!(initial["roles"].as_array().unwrap().len(), 1);
    assert_eq!(initial["roles"][0]["count"], 2);
    server
        .command(
            &id,
            "o0",
            json!({"waypoints": [[12.7, 4.8], [12.7, 7.0], [10.8, 9.3]]}),
        )
        .await;
    server.step(&id, 20 * 20).await;
    server
        .command(
            &id,
            "o1",
            json!({"waypoints": [[2.0, 8.0], [12.7, 4.8], [12.7, 7.0], [15.5, 9.5]]}),
        )
        .await;
    server.step(&id, 20 * 8).await;
    // o1 is in plain view on its way to the door: two roles, one opponent each.
    let during = belief(&server, &id).await;
    let roles: Vec<&Value> = during["roles"].as_array().unwrap().iter().collect();
    assert_eq!(
        roles.len(),
        2,
        "{:?}",
        roles.iter().map(|r| &r["count"]).collect::<Vec<_>>()
    );
    assert!(roles.iter().all(|r| r["count"] == 1));
    let events = server.events(&id).await;
    assert_eq!(
        events.iter().filter(|e| e["kind"] == "role_split").count(),
        1
    );
    // Both hide in the room; the robot keeps watching the door.
    server.step(&id, 20 * 90).await;
    let after = belief(&server, &id).await;
    let roles = after["roles"].as_array().unwrap();
    assert_eq!(
        roles.len(),
        1,
        "merged back: {:?}",
        roles.iter().map(|r| &r["count"]).collect::<Vec<_>>()
    );
    assert_eq!(roles[0]["count"], 2);
    let share = weight_in_room(&roles[0]);
    assert!(share > 0.9, "and the merged belief is in the room: {share}");
    let events = server.events(&id).await;
    let merge = events
        .iter()
        .find(|e| e["kind"] == "role_merge")
        .expect("a role_merge event");
    assert_eq!(merge["count"], 2);
}
