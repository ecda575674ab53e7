//! Fair play by construction: nothing public lets a stranger rebuild a match people may join
//! (its seed is the server's secret until it ends), a player's socket hears of what it did
//! not see only as late as spectators do, and an unknown match is a 404 whatever the token.

mod common;

use std::time::Duration;

use common::{ADMIN, Got, TestServer, Ws, assert_error};
use serde_json::{Value, json};

/// The summary of match `id` in the listing, as `token` (or nobody) reads it.
async fn listed(s: &TestServer, id: &str, token: Option<&str>) -> Value {
    let r = s.get_as("/api/matches", token).await;
    assert_eq!(r.status, 200, "{}", r.body);
    r.body
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["id"] == id)
        .unwrap_or_else(|| panic!("{id} is not listed: {}", r.body))
        .clone()
}

/// Steps match `id` (as its owner) to `tick` and answers its live state.
async fn step_to(s: &TestServer, id: &str, tick: u64) -> Value {
    let now = s.get(&format!("/api/matches/{id}")).await.body["tick"]
        .as_u64()
        .unwrap();
    s.step(id, tick - now).await
}

/// Every robot's `[x, y]` in a state.
fn robots(state: &Value) -> Vec<[f64; 2]> {
    state["robots"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| [r["x"].as_f64().unwrap(), r["y"].as_f64().unwrap()])
        .collect()
}

/// How far apart two states put the robots, at most (metres).
fn off(a: &Value, b: &Value) -> f64 {
    robots(a)
        .iter()
        .zip(robots(b))
        .map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
        .fold(0.0, f64::max)
}

#[tokio::test]
async fn a_joinable_matchs_seed_is_its_owners_until_it_ends() {
    let s = TestServer::with_admin().await;
    let settings = json!({"map": "office", "robots": 2, "opponents": 1, "clock": "manual",
        "planner": "coordinated", "time_limit_s": 3});
    let mut request = settings.clone();
    request["opponent_control"] = json!("human");

    // A seed is the server's to choose when people may join.
    for people in [
        json!({"opponent_control": "human"}),
        json!({"bots_joinable": true}),
    ] {
        let mut body = settings.clone();
        body.as_object_mut()
            .unwrap()
            .extend(people.as_object().unwrap().clone());
        body["seed"] = json!(7);
        assert_error(&s.post_as("/api/matches", &body, None).await, 400, "seed");
    }

    let r = s.post("/api/matches", &request).await;
    assert_eq!(r.status, 201, "{}", r.body);
    let id = r.body["id"].as_str().unwrap().to_string();
    let owner = r.body["owner_token"].as_str().unwrap().to_string();
    let seed = r.body["seed"]
        .as_u64()
        .expect("the owner is shown the seed");

    // Everything public: the listing shows the settings but not the seed.
    let public = listed(&s, &id, None).await;
    assert!(public["seed"].is_null(), "{public}");
    assert_eq!(listed(&s, &id, Some(&owner)).await["seed"], seed);
    assert_eq!(listed(&s, &id, Some(ADMIN)).await["seed"], seed);
    // Another match's token opens nothing here (and is no error in a listing).
    let (_, other) = {
        let r = s.post("/api/matches", &json!({"map": "office"})).await;
        (
            r.body["id"].clone(),
            r.body["owner_token"].as_str().unwrap().to_string(),
        )
    };
    assert!(listed(&s, &id, Some(&other)).await["seed"].is_null());
    for path in [
        format!("/api/matches/{id}"),
        format!("/api/matches/{id}/stats"),
    ] {
        let body = s.get_as(&path, None).await.body;
        assert!(
            body.get("seed").is_none_or(Value::is_null),
            "{path}: {body}"
        );
    }

    // The attack: a headless copy from what a stranger can read (no seed there, so the
    // default) stepped to the live tick. Nobody moves the human slot in either. Any
    // difference at all shows it (the robots' noise drifts apart slowly at first): with the
    // seed the copy is exact.
    let mut copy = settings.clone();
    copy["opponent_control"] = json!("api");
    let guess = s.create_match(copy.clone()).await;
    let live = step_to(&s, &id, 40).await;
    let guessed = step_to(&s, &guess, 40).await;
    assert!(
        off(&live, &guessed) > 0.0,
        "a copy without the seed matched the live robots: {} m off",
        off(&live, &guessed)
    );
    // The seed is the whole secret: the owner, who has it, rebuilds the match exactly.
    copy["seed"] = json!(seed);
    let rebuilt = s.create_match(copy).await;
    let rebuilt = step_to(&s, &rebuilt, 40).await;
    assert_eq!(off(&live, &rebuilt), 0.0, "the owner's copy is off");

    // Once it has ended, everyone sees it: in the listing and with the replay.
    let end = s.step(&id, 1000).await;
    assert_eq!(end["status"], "finished", "{end}");
    assert_eq!(listed(&s, &id, None).await["seed"], seed);
    let mut replay = Value::Null;
    for _ in 0..50 {
        let r = s.get_as(&format!("/api/replays/{id}"), None).await;
        if r.status == 200 {
            replay = r.body;
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert_eq!(replay["settings"]["seed"], seed, "{replay}");
}

#[tokio::test]
async fn matches_without_people_keep_their_public_seeds() {
    let s = TestServer::with_admin().await;
    let id = s
        .create_match(json!({"map": "office", "opponent_control": "api", "seed": 42}))
        .await;
    assert_eq!(listed(&s, &id, None).await["seed"], 42);
}

/// Two rooms with no line of sight between them: the player (o0) alone in the west one, a
/// robot facing o1 two metres off in the east one.
fn two_rooms() -> Value {
    json!({
        "name": "two-rooms",
        "width": 14.0,
        "height": 8.0,
        "obstacles": [[[6.5, 0.0], [7.5, 0.0], [7.5, 8.0], [6.5, 8.0]]],
        "robot_spawns": [[10.0, 4.0, 0.0]],
        "opponent_spawns": [[2.0, 4.0], [12.0, 4.0]]
    })
}

/// The events a player's socket has sent up to its snapshot of `tick`.
async fn events_until(ws: &mut Ws, tick: u64) -> Vec<Value> {
    let mut events = Vec::new();
    loop {
        match ws.next().await {
            Got::Json(m) if m["type"] == "event" => events.push(m),
            Got::Json(m) if m["type"] == "snapshot" && m["tick"].as_u64() >= Some(tick) => {
                return events;
            }
            Got::Json(_) => {}
            other => panic!("the socket ended: {other:?}"),
        }
    }
}

/// The events a player's socket sends until it has been quiet for 300 ms (what the
/// spectators' frames release comes beside the live snapshots, not in step with them).
async fn events_settled(ws: &mut Ws) -> Vec<Value> {
    use futures_util::StreamExt;
    let mut events = Vec::new();
    while let Ok(Some(Ok(m))) =
        tokio::time::timeout(Duration::from_millis(300), ws.stream.next()).await
    {
        if let common::WsMessage::Text(t) = m {
            let v: Value = serde_json::from_str(t.as_str()).unwrap();
            if v["type"] == "event" {
                events.push(v);
            }
        }
    }
    events
}

#[tokio::test]
async fn a_players_socket_hears_of_a_tag_out_of_its_sight_only_late() {
    let s = TestServer::start().await;
    let id = s
        .create_match(json!({"map": two_rooms(), "robots": 1, "opponents": 2,
            "opponent_control": "human", "planner": "coordinated", "clock": "manual",
            "time_limit_s": 60, "spectator_delay_s": 1,
            "robot_starts": [[10.0, 4.0, 0.0]], "opponent_starts": [[2.0, 4.0], [12.0, 4.0]]}))
        .await;
    let (me, token) = s.join(&id, "ada").await;
    assert_eq!(me, "o0");
    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    ws.next_of("welcome").await;
    // Step until the robot tags o1 (the owner's log is live).
    let mut heard = Vec::new();
    let tagged = loop {
        let tick = s.step(&id, 1).await["tick"].as_u64().unwrap();
        assert!(tick < 400, "the robot never tagged o1");
        heard.extend(events_until(&mut ws, tick).await);
        let log = s.get(&format!("/api/matches/{id}/events")).await.body;
        if let Some(tag) = log["events"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["kind"] == "tag")
        {
            break tag.clone();
        }
    };
    assert_eq!(tagged["target"], "o1", "{tagged}");
    let at = tagged["tick"].as_u64().unwrap();
    // Nothing the robot did in the other room came live: no shot, no tag.
    assert!(
        heard
            .iter()
            .all(|e| e["kind"] != "tag" && e["kind"] != "shot"),
        "heard live: {heard:?}"
    );
    // It comes once spectators see that tick (1 s, 20 ticks, later), not before.
    step_to(&s, &id, at + 18).await;
    let early = events_settled(&mut ws).await;
    assert!(early.iter().all(|e| e["kind"] != "tag"), "{early:?}");
    step_to(&s, &id, at + 21).await;
    let events = events_settled(&mut ws).await;
    let tag = events
        .iter()
        .find(|e| e["kind"] == "tag")
        .unwrap_or_else(|| panic!("the tag never came: {events:?}"));
    assert_eq!(tag["seq"], tagged["seq"]);
    assert_eq!(tag["target"], "o1");
}

#[tokio::test]
async fn an_unknown_match_is_a_404_for_every_route_whatever_the_token() {
    let s = TestServer::with_admin().await;
    let id = "0123456789abcdef";
    let routes: Vec<(&str, String, Value)> = vec![
        (
            "POST",
            format!("/api/matches/{id}/step"),
            json!({"ticks": 1}),
        ),
        ("DELETE", format!("/api/matches/{id}"), Value::Null),
        (
            "POST",
            format!("/api/matches/{id}/opponents/o0/command"),
            json!({"stop": true}),
        ),
        (
            "POST",
            format!("/api/matches/{id}/robots/r0/command"),
            json!({"stop": true}),
        ),
        (
            "POST",
            format!("/api/matches/{id}/act"),
            json!({"commands": {"r0": {"stop": true}}, "ticks": 1}),
        ),
        (
            "POST",
            format!("/api/matches/{id}/players"),
            json!({"name": "ada"}),
        ),
        ("DELETE", "/api/maps/no-such-map".to_string(), Value::Null),
    ];
    for token in [None, Some("0123456789abcdef0123456789abcdef"), Some(ADMIN)] {
        for (method, path, body) in &routes {
            let r = match *method {
                "POST" => s.post_as(path, body, token).await,
                _ => s.delete_as(path, token).await,
            };
            assert_eq!(r.status, 404, "{method} {path} with {token:?}: {}", r.body);
        }
    }
}
