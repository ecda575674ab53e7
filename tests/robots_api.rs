//! Robots driven from outside over HTTP (`"planner": "api"`): commands, observations that
//! carry no truth, and the environment step, against the real server.

mod common;

use common::{TestServer, assert_error, duel_map};
use serde_json::{Value, json};

async fn api_match(s: &TestServer, extra: Value) -> String {
    let mut body = json!({"map": duel_map(), "robots": 2, "opponents": 1, "planner": "api",
        "opponent_control": "api", "clock": "manual", "seed": 7});
    if let (Some(b), Some(e)) = (body.as_object_mut(), extra.as_object()) {
        b.extend(e.clone());
    }
    s.create_match(body).await
}

async fn act(s: &TestServer, id: &str, body: Value) -> Value {
    let r = s.post(&format!("/api/matches/{id}/act"), &body).await;
    assert_eq!(r.status, 200, "{}", r.body);
    r.body
}

#[tokio::test]
async fn an_environment_step_applies_commands_and_answers_every_observation() {
    let s = TestServer::start().await;
    let id = api_match(&s, json!({})).await;
    let state = s.get(&format!("/api/matches/{id}")).await.body;
    assert_eq!(state["planner"], "api");
    let start = json!({"x": state["robots"][0]["x"], "y": state["robots"][0]["y"]});

    // Nothing commanded: the robots stand still.
    let idle = act(&s, &id, json!({"ticks": 5})).await;
    assert_eq!(idle["tick"], 5);
    let truth = s.get(&format!("/api/matches/{id}")).await.body;
    assert_eq!(truth["robots"][0]["x"], start["x"]);
    assert_eq!(truth["robots"][0]["y"], start["y"]);

    let step = act(
        &s,
        &id,
        json!({"commands": {"r0": {"forward": 1.0}, "r1": {"turn": 0.5}}, "ticks": 20}),
    )
    .await;
    assert_eq!(step["tick"], 25);
    assert_eq!(step["status"], "running");
    let o = &step["observations"]["r0"];
    assert_eq!(o["tick"], 25);
    assert_eq!(o["scan"].as_array().map(Vec::len), Some(181));
    for key in ["detections", "landmarks", "teammates"] {
        assert!(o[key].is_array(), "{key}: {o}");
    }
    assert_eq!(o["teammates"][0]["id"], "r1");
    assert!(o["tag_ready"].as_bool().unwrap());
    // What the robot knows of itself is its estimate, near (not equal to) the truth, and
    // nothing in the observation is the referee's.
    let truth = s.get(&format!("/api/matches/{id}")).await.body;
    let x = truth["robots"][0]["x"].as_f64().unwrap();
    let est = o["estimate"]["x"].as_f64().unwrap();
    assert!(x > start["x"].as_f64().unwrap() + 0.5, "moved forward: {x}");
    assert!((est - x).abs() < 0.3, "estimate {est}, truth {x}");
    for truth_key in ["pose", "seen", "goal", "cloud"] {
        assert!(o.get(truth_key).is_none(), "{truth_key} in {o}");
    }
    // The same observation from its own endpoint.
    let one = s
        .get(&format!("/api/matches/{id}/robots/r0/observation"))
        .await;
    assert_eq!(one.status, 200);
    assert_eq!(one.body, *o);
}

#[tokio::test]
async fn a_robot_fires_on_command_and_the_step_reports_the_events() {
    let s = TestServer::start().await;
    // The opponent stands right in front of r0.
    let id = api_match(
        &s,
        json!({"robot_starts": [[2.0, 4.0, 0.0], [1.0, 1.0, 0.0]], "opponent_starts": [[4.0, 4.0]]}),
    )
    .await;
    let step = act(&s, &id, json!({"commands": {"r0": {"tag": true}}})).await;
    let kinds: Vec<&str> = step["events"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|e| e["kind"].as_str())
        .collect();
    assert!(kinds.contains(&"tag"), "{kinds:?}");
    assert_eq!(step["status"], "finished");
    assert_eq!(step["winner"], "robots");
}

#[tokio::test]
async fn commands_are_checked_and_an_act_applies_all_or_none() {
    let s = TestServer::start().await;
    let id = api_match(&s, json!({})).await;
    let cmd = |rid: &str| format!("/api/matches/{id}/robots/{rid}/command");
    assert_eq!(
        s.post(&cmd("r0"), &json!({"forward": 0.5})).await.status,
        204
    );
    assert_error(
        &s.post(&cmd("r0"), &json!({"forward": 3})).await,
        400,
        "forward",
    );
    assert_error(&s.post(&cmd("r9"), &json!({"stop": true})).await, 404, "r9");
    assert_error(&s.post(&cmd("o0"), &json!({"stop": true})).await, 404, "o0");
    assert_error(
        &s.post(&cmd("r0"), &json!({"waypoints": [[60, 1]]})).await,
        400,
        "waypoints[0]",
    );
    assert_error(
        &s.post(&cmd("r0"), &json!({"stop": true, "turn": 1})).await,
        400,
        "body",
    );
    // Without the owner's token nothing is commanded.
    let r = s.post_as(&cmd("r0"), &json!({"stop": true}), None).await;
    assert_eq!(r.status, 401, "{}", r.body);
    // r1's waypoint is outside: r0's stop must not take effect either.
    let r = s
        .post(
            &format!("/api/matches/{id}/act"),
            &json!({"commands": {"r0": {"stop": true}, "r1": {"waypoints": [[99, 1]]}}}),
        )
        .await;
    assert_error(&r, 400, "waypoints[0]");
    let before = s.get(&format!("/api/matches/{id}")).await.body["robots"][0]["x"]
        .as_f64()
        .unwrap();
    let after = act(&s, &id, json!({"ticks": 10})).await;
    let x = after["observations"]["r0"]["odometry"]["x"]
        .as_f64()
        .unwrap();
    assert!(x > before + 0.1, "r0 still drives ({before} -> {x})");

    // A match whose robots plan for themselves takes no commands.
    let planned = s
        .create_match(json!({"map": "office", "robots": 1, "clock": "manual"}))
        .await;
    let r = s
        .post(
            &format!("/api/matches/{planned}/robots/r0/command"),
            &json!({"stop": true}),
        )
        .await;
    assert_error(&r, 409, "api");
    // What the robots of a match people play know shows where they are: the owner's.
    // (Without a seed: the server chooses a secret one for a match people may join.)
    let people = s
        .create_match(
            json!({"map": duel_map(), "robots": 2, "opponents": 1, "planner": "api",
            "opponent_control": "human", "clock": "realtime"}),
        )
        .await;
    let path = format!("/api/matches/{people}/robots/r0/observation");
    assert_error(&s.get_as(&path, None).await, 403, "owner");
    assert_eq!(s.get(&path).await.status, 200);
    // Nor does a real-time match step on demand.
    let realtime = api_match(&s, json!({"clock": "realtime"})).await;
    let r = s
        .post(&format!("/api/matches/{realtime}/act"), &json!({}))
        .await;
    assert_error(&r, 409, "real time");
}

#[tokio::test]
async fn two_runs_with_one_seed_observe_the_same() {
    let s = TestServer::start().await;
    let mut runs = Vec::new();
    for _ in 0..2 {
        let id = api_match(&s, json!({"opponent_control": "bot"})).await;
        let mut seen = Vec::new();
        for k in 0..20 {
            let turn = if k % 3 == 0 { -1.0 } else { 0.7 };
            let step = act(
                &s,
                &id,
                json!({"commands": {"r0": {"forward": 1.0, "turn": turn},
                    "r1": {"waypoints": [[10.0, 2.0], [12.0, 6.0]]}}, "ticks": 3}),
            )
            .await;
            seen.push(step["observations"].clone());
        }
        runs.push(seen);
    }
    assert!(
        runs[0] == runs[1],
        "the same seed and commands, other observations"
    );
}

/// A team may mix controllers: `"planner": ["coordinated", "api"]` plans r0 and leaves r1
/// to the client, which commands r1 (not r0) and steps both with `act`.
#[tokio::test]
async fn a_team_may_mix_planned_robots_and_robots_driven_from_outside() {
    let s = TestServer::start().await;
    let id = api_match(
        &s,
        json!({"planner": ["coordinated", "api"], "robots": null}),
    )
    .await;
    let summary = s.get(&format!("/api/matches/{id}")).await.body;
    assert_eq!(summary["planner"], "coordinated", "{summary}");
    assert_eq!(summary["robot_planners"], json!(["coordinated", "api"]));
    let cmd = |rid: &str| format!("/api/matches/{id}/robots/{rid}/command");
    assert_error(
        &s.post(&cmd("r0"), &json!({"forward": 1})).await,
        409,
        "not driven from outside",
    );
    assert_eq!(s.post(&cmd("r1"), &json!({"turn": 1})).await.status, 204);
    let before = s.get(&format!("/api/matches/{id}")).await.body;
    let after = act(
        &s,
        &id,
        json!({"commands": {"r1": {"turn": 1}}, "ticks": 20}),
    )
    .await;
    assert_eq!(after["tick"], 20);
    let state = s.get(&format!("/api/matches/{id}")).await.body;
    // r1 turned on the spot as told; r0 went where its planner sent it.
    let (b1, a1) = (&before["robots"][1], &state["robots"][1]);
    let moved = |a: &Value, b: &Value| {
        (a["x"].as_f64().unwrap() - b["x"].as_f64().unwrap())
            .hypot(a["y"].as_f64().unwrap() - b["y"].as_f64().unwrap())
    };
    assert!(moved(a1, b1) < 0.05, "{b1} → {a1}");
    assert_ne!(a1["theta"], b1["theta"], "{b1} → {a1}");
    assert!(
        moved(&state["robots"][0], &before["robots"][0]) > 0.1,
        "{state}"
    );
    // Every way of getting the list wrong is named.
    for (planner, robots, says) in [
        (
            json!(["coordinated", "baseline"]),
            json!(null),
            "share one planner",
        ),
        (
            json!(["coordinated", "api"]),
            json!(3),
            "2 planners for 3 robots",
        ),
        (json!([]), json!(null), "empty list"),
        (json!(7), json!(null), "one per robot"),
    ] {
        let body = json!({"map": "office", "planner": planner, "robots": robots});
        assert_error(&s.post("/api/matches", &body).await, 400, says);
    }
}
