//! What a door costs is priced before it runs, against the real server: robots' waypoints
//! (a path search each) within a per-request bound and the server's and each client's
//! rates of path search.

mod common;

use common::{TestServer, assert_error, test_config};
use lasertag::config::Config;
use serde_json::{Value, json};

/// A manual match on the shipped office (24 m × 16 m: 38,400 grid cells) whose robots take
/// orders from outside.
async fn api_match(s: &TestServer) -> String {
    s.create_match(
        json!({"map": "office", "robots": 2, "opponents": 1, "planner": "api",
        "clock": "manual", "seed": 3}),
    )
    .await
}

/// Where robot `rid` stands now.
async fn robot_at(s: &TestServer, id: &str, rid: usize) -> [f64; 2] {
    let state = s.get(&format!("/api/matches/{id}")).await.body;
    let r = &state["robots"][rid];
    [
        r["x"].as_f64().unwrap_or(0.0),
        r["y"].as_f64().unwrap_or(0.0),
    ]
}

/// Sixteen waypoints between the office's far corners.
fn far_waypoints() -> Value {
    let points: Vec<[f64; 2]> = (0..16)
        .map(|k| if k % 2 == 0 { [22.5, 14.5] } else { [1.5, 1.5] })
        .collect();
    json!({ "waypoints": points })
}

#[tokio::test]
async fn waypoints_past_the_path_search_bound_are_refused_naming_it() {
    let s = TestServer::start_with(Config {
        max_command_work: 20_000,
        ..test_config()
    })
    .await;
    let id = api_match(&s).await;
    let cmd = format!("/api/matches/{id}/robots/r0/command");
    // Far corners: each search would cover most of the grid.
    let r = s.post(&cmd, &far_waypoints()).await;
    assert_error(&r, 400, "budget of 20000 units");
    let act = s
        .post(
            &format!("/api/matches/{id}/act"),
            &json!({"commands": {"r1": far_waypoints()}}),
        )
        .await;
    assert_error(&act, 400, "budget of 20000 units");
    // A point a step away is found within the bound: the search stops at its goal.
    let [x, y] = robot_at(&s, &id, 0).await;
    let near = json!({"waypoints": [[x + 0.3, y]]});
    let r = s.post(&cmd, &near).await;
    assert_eq!(r.status, 204, "{}", r.body);
    // The match goes on as before.
    assert_eq!(s.step(&id, 5).await["tick"], 5);
}

#[tokio::test]
async fn a_client_past_its_share_of_path_search_waits_and_the_server_answers() {
    let s = TestServer::start_with(Config {
        max_command_work: 100_000,
        // A client's share refills at 250 units a second: one command, then none for minutes.
        command_work_per_s: 1_000.0,
        client_budget_share: 0.25,
        ..test_config()
    })
    .await;
    let id = api_match(&s).await;
    let cmd = format!("/api/matches/{id}/robots/r0/command");
    let [x, y] = robot_at(&s, &id, 0).await;
    let near = json!({"waypoints": [[x + 0.3, y]]});
    let first = s.post(&cmd, &near).await;
    assert_eq!(first.status, 204, "{}", first.body);
    let second = s.post(&cmd, &near).await;
    assert_error(&second, 429, "share of this server's path search");
    // Orders without waypoints search nothing and cost nothing.
    let stop = s.post(&cmd, &json!({"stop": true})).await;
    assert_eq!(stop.status, 204, "{}", stop.body);
    assert_eq!(s.get("/api/health").await.status, 200);
}

#[tokio::test]
async fn a_match_records_a_bounded_amount_of_commands_then_refuses_them() {
    let s = TestServer::start().await;
    let id = s
        .create_match(
            json!({"map": "office", "opponents": 1, "opponent_control": "api",
            "clock": "manual", "seed": 5}),
        )
        .await;
    let route: Vec<[f64; 2]> = (0..1000)
        .map(|k| [2.0 + (k % 20) as f64, 2.0 + (k / 100) as f64])
        .collect();
    let body = json!({ "waypoints": route });
    // About 8 KB recorded a command: the bound is met after a few hundred.
    let mut accepted = 0;
    let refused = loop {
        let r = s.command(&id, "o0", body.clone()).await;
        if r.status != 204 {
            break r;
        }
        accepted += 1;
        assert!(accepted < 2_000, "no bound after {accepted} commands");
    };
    assert!(accepted > 100, "{accepted}");
    assert_error(&refused, 409, "bound of 4000000 bytes");
    // The match still steps; the next big command is refused alike.
    assert_eq!(s.step(&id, 3).await["tick"], 3);
    assert_error(
        &s.command(&id, "o0", body).await,
        409,
        "takes no more commands",
    );
}
