//! Marks over a real server: a player points at a spot for their side; their teammates get
//! it with the next tick's messages, the other side never does, spectators get it as late
//! as the rest of the truth, a flood is refused, and the replay keeps it.

mod common;

use common::{TestServer, Ws};
use serde_json::{Value, json};

/// Joins `id` on `team`: the token.
async fn join(s: &TestServer, id: &str, name: &str, team: &str) -> String {
    let r = s
        .post(
            &format!("/api/matches/{id}/players"),
            &json!({"name": name, "team": team}),
        )
        .await;
    assert_eq!(r.status, 201, "{}", r.body);
    r.body["token"].as_str().unwrap().to_string()
}

/// Everything `ws` says up to its snapshot of tick `tick` (or later), that snapshot last (a
/// frame's events follow its snapshot: those of tick `tick - 1` come before it).
async fn until_tick(ws: &mut Ws, tick: u64) -> Vec<Value> {
    let mut seen = Vec::new();
    loop {
        let v = ws.json().await;
        let done = v["type"] == "snapshot" && v["tick"].as_u64().unwrap() >= tick;
        seen.push(v);
        if done {
            return seen;
        }
    }
}

fn marks(messages: &[Value]) -> Vec<&Value> {
    messages
        .iter()
        .filter(|m| m["type"] == "event" && m["kind"] == "mark")
        .collect()
}

#[tokio::test]
async fn a_mark_reaches_the_markers_side_only_and_the_replay_keeps_it() {
    let s = TestServer::start().await;
    let id = s
        .create_match(json!({"map": "office", "robots": 2, "opponents": 2,
            "opponent_control": "human", "planner": "baseline", "pursuer_slots": 1,
            "clock": "manual", "time_limit_s": 60}))
        .await;
    let alice = join(&s, &id, "alice", "opponents").await;
    let bob = join(&s, &id, "bob", "opponents").await;
    let carol = join(&s, &id, "carol", "robots").await;
    let mut alice_ws = s.ws(&id, Some(&alice)).await.unwrap();
    let mut bob_ws = s.ws(&id, Some(&bob)).await.unwrap();
    let mut carol_ws = s.ws(&id, Some(&carol)).await.unwrap();
    let mut spectator = s.ws(&id, None).await.unwrap();
    for ws in [&mut alice_ws, &mut bob_ws, &mut carol_ws, &mut spectator] {
        ws.next_of("welcome").await;
    }
    s.step(&id, 2).await;

    alice_ws
        .send_json(&json!({"type": "mark", "x": 5.0, "y": 4.5, "kind": "robot"}))
        .await
        .unwrap();
    // A mark is applied between ticks: wait until the match's log has it.
    let mut logged = Vec::new();
    for _ in 0..100 {
        logged = s.events(&id).await;
        if logged.iter().any(|e| e["kind"] == "mark") {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    let owner_view: Vec<&Value> = logged.iter().filter(|e| e["kind"] == "mark").collect();
    assert_eq!(owner_view.len(), 1, "{logged:?}");
    s.step(&id, 1).await;
    let truth = s.step(&id, 1).await;
    let tick = truth["tick"].as_u64().unwrap();

    // Bob, alice's teammate, gets it with the next frame, with her name and the spot.
    let bob_saw = until_tick(&mut bob_ws, tick).await;
    let got = marks(&bob_saw);
    assert_eq!(got.len(), 1, "{bob_saw:?}");
    assert_eq!(got[0]["by"], "alice");
    assert_eq!(got[0]["opponent"], "o0");
    assert_eq!(
        (got[0]["x"].as_f64(), got[0]["y"].as_f64()),
        (Some(5.0), Some(4.5))
    );
    assert_eq!(got[0]["mark"], "robot");
    // Carol hunts on the other side: never; nor does a live spectator (30 s behind).
    s.step(&id, 5).await;
    let carol_saw = until_tick(&mut carol_ws, tick + 5).await;
    assert!(marks(&carol_saw).is_empty(), "{carol_saw:?}");
    let spectator_saw = until_tick(&mut spectator, 0).await;
    assert!(marks(&spectator_saw).is_empty(), "{spectator_saw:?}");

    // Carol's mark is for the robots' side: alice never gets it.
    carol_ws
        .send_json(&json!({"type": "mark", "x": 6.0, "y": 5.0, "kind": "danger"}))
        .await
        .unwrap();
    tokio::time::sleep(std::time::Duration::from_millis(200)).await;
    s.step(&id, 1).await;
    let truth = s.step(&id, 1).await;
    let tick = truth["tick"].as_u64().unwrap();
    let carol_saw = until_tick(&mut carol_ws, tick).await;
    assert_eq!(marks(&carol_saw).len(), 1, "{carol_saw:?}");
    let alice_saw = until_tick(&mut alice_ws, tick).await;
    assert!(
        marks(&alice_saw).iter().all(|m| m["by"] == "alice"),
        "{alice_saw:?}"
    );

    // Three in five seconds, then a refusal that names the limit; the socket stays open.
    for _ in 0..2 {
        bob_ws
            .send_json(&json!({"type": "mark", "x": 3.0, "y": 3.0, "kind": "go"}))
            .await
            .unwrap();
    }
    bob_ws
        .send_json(&json!({"type": "mark", "x": 3.0, "y": 3.0, "kind": "go"}))
        .await
        .unwrap();
    bob_ws
        .send_json(&json!({"type": "mark", "x": 3.0, "y": 3.0, "kind": "go"}))
        .await
        .unwrap();
    let refused = bob_ws.next_of("error").await;
    assert!(
        refused["error"]
            .as_str()
            .is_some_and(|m| m.contains("at most 3")),
        "{refused}"
    );
    // A bad mark names its field; a point outside the arena is refused.
    bob_ws
        .send_json(&json!({"type": "mark", "x": 3.0, "y": 3.0, "kind": "hello"}))
        .await
        .unwrap();
    let refused = bob_ws.next_of("error").await;
    assert!(refused.to_string().contains("kind"), "{refused}");

    // Over: the replay has the marks, each side's.
    let r = s.delete(&format!("/api/matches/{id}")).await;
    assert!(r.status == 204 || r.status == 200, "{}", r.body);
    s.flush_history();
    let replay = s.get(&format!("/api/replays/{id}")).await;
    assert_eq!(replay.status, 200, "{}", replay.body);
    let kept: Vec<&Value> = replay.body["events"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|e| e["kind"] == "mark")
        .collect();
    assert_eq!(kept.len(), 5, "{:?}", replay.body["events"]);
    assert_eq!(kept[0]["by"], "alice");
    assert_eq!(kept[1]["robot"], "r1");
}
