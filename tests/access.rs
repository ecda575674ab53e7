//! Access and fair play: a match or an uploaded map changes only for its owner (or the
//! operator), each client has a quota of matches and maps, and manual matches nobody uses
//! go away. Each refusal is checked together with what must not have happened (the match
//! still there, still ticking).

mod common;

use std::time::Duration;

use common::{ADMIN, TestServer, assert_error, duel_map, test_config};
use lasertag::config::{Config, Secret};
use serde_json::{Value, json};

/// Creates a match from the raw API: (id, owner token).
async fn create(s: &TestServer, body: Value) -> (String, String) {
    let r = s.post_as("/api/matches", &body, None).await;
    assert_eq!(r.status, 201, "{}", r.body);
    let token = r.body["owner_token"].as_str().expect("an owner_token");
    (r.body["id"].as_str().unwrap().into(), token.into())
}

async fn tick_of(s: &TestServer, id: &str) -> u64 {
    let r = s.get(&format!("/api/matches/{id}")).await;
    assert_eq!(r.status, 200, "{}", r.body);
    r.body["tick"].as_u64().unwrap()
}

/// Waits (bounded) until the real-time match `id` has passed tick `since`.
async fn keeps_ticking(s: &TestServer, id: &str, since: u64) {
    for _ in 0..100 {
        if tick_of(s, id).await > since {
            return;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    panic!("match {id} stopped at tick {since}");
}

#[tokio::test]
async fn only_the_owner_or_the_operator_changes_a_match() {
    let s = TestServer::with_admin().await;
    let (id, owner) = create(&s, json!({"map": "office", "clock": "manual"})).await;
    assert_eq!(owner.len(), 32);
    assert!(owner.bytes().all(|b| b.is_ascii_hexdigit()));
    // The token is shown once: never in the summary or the listing.
    let listing = s.get("/api/matches").await;
    assert!(!listing.body.to_string().contains(&owner));

    let step = format!("/api/matches/{id}/step");
    let ticks = json!({"ticks": 3});
    let r = s.post_as(&step, &ticks, None).await;
    assert_error(&r, 401, "owner_token");
    let r = s.post_as(&step, &ticks, Some("not-the-token")).await;
    assert_error(&r, 403, "owner_token");
    assert_eq!(tick_of(&s, &id).await, 0, "a refused step changed nothing");
    let r = s.post_as(&step, &ticks, Some(&owner)).await;
    assert_eq!(r.status, 200, "{}", r.body);
    let r = s.post_as(&step, &ticks, Some(ADMIN)).await;
    assert_eq!(r.status, 200, "{}", r.body);
    assert_eq!(tick_of(&s, &id).await, 6);

    // Another match's token is a wrong token here.
    let (_, other) = create(&s, json!({"map": "office", "clock": "manual"})).await;
    let r = s.post_as(&step, &ticks, Some(&other)).await;
    assert_error(&r, 403, "owner_token");

    // A malformed Authorization header is named, not taken for "no token".
    let r = s
        .client
        .post(s.url(&step))
        .header("authorization", "Basic dXNlcjpwYXNz")
        .json(&ticks)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 401);
    assert!(r.headers().contains_key("www-authenticate"));
    assert!(r.text().await.unwrap().contains("Bearer"));
}

#[tokio::test]
async fn a_stranger_cannot_delete_or_command_a_match() {
    let s = TestServer::with_admin().await;
    let (live, owner) = create(
        &s,
        json!({"map": "office", "planner": "idle", "opponent_control": "api"}),
    )
    .await;
    let path = format!("/api/matches/{live}");
    assert_error(&s.delete_as(&path, None).await, 401, "owner_token");
    assert_error(&s.delete_as(&path, Some("guess")).await, 403, "owner_token");
    let command = format!("/api/matches/{live}/opponents/o0/command");
    let r = s.post_as(&command, &json!({"stop": true}), None).await;
    assert_error(&r, 401, "owner_token");
    let r = s
        .post_as(&command, &json!({"stop": true}), Some(ADMIN))
        .await;
    assert_eq!(r.status, 204, "{}", r.body);
    // Still there and still ticking after every refusal.
    let t = tick_of(&s, &live).await;
    keeps_ticking(&s, &live, t).await;
    assert_eq!(s.delete_as(&path, Some(&owner)).await.status, 204);
    assert_eq!(s.get(&path).await.status, 404);
}

#[tokio::test]
async fn the_servers_own_matches_change_only_for_the_operator() {
    let s = TestServer::with_admin().await;
    let arena = common::shipped_arena("office");
    let world = lasertag_core::world::World::new(
        arena,
        lasertag_core::world::MatchConfig {
            seed: 1,
            ..Default::default()
        },
    )
    .unwrap();
    let meta = lasertag::game::view::MatchMeta {
        id: "house".into(),
        map: "office".into(),
        clock: lasertag::game::view::Clock::Realtime,
        players: 0,
        spectators: 0,
        free_slots: 0,
        free_pursuer_slots: 0,
        bots_joinable: true,
        spectator_delay_ticks: 0,
        head_start_ticks: 0,
        rated: false,
        difficulty: None,
    };
    s.registry.start(world, meta);
    let (_, someone) = create(&s, json!({"map": "office"})).await;
    let r = s.delete_as("/api/matches/house", Some(&someone)).await;
    assert_error(&r, 403, "only the operator");
    assert_eq!(s.get("/api/matches/house").await.status, 200);
    let r = s.delete_as("/api/matches/house", Some(ADMIN)).await;
    assert_eq!(r.status, 204);
}

#[tokio::test]
async fn an_uploaded_map_is_deleted_by_its_owner_once_no_match_runs_on_it() {
    let s = TestServer::with_admin().await;
    let r = s.post_as("/api/maps", &duel_map(), None).await;
    assert_eq!(r.status, 201, "{}", r.body);
    let owner = r.body["owner_token"].as_str().unwrap().to_string();
    assert_eq!(r.body["name"], "duel");

    assert_error(
        &s.delete_as("/api/maps/duel", None).await,
        401,
        "owner_token",
    );
    let r = s.delete_as("/api/maps/duel", Some("guess")).await;
    assert_error(&r, 403, "owner_token");
    let r = s.delete_as("/api/maps/office", Some(ADMIN)).await;
    assert_error(&r, 403, "shipped");
    // That a map exists is public (`GET` says so): an unknown one is a 404 whatever the token.
    let r = s.delete_as("/api/maps/nope", Some(&owner)).await;
    assert_error(&r, 404, "nope");
    assert_error(
        &s.delete_as("/api/maps/nope", Some(ADMIN)).await,
        404,
        "nope",
    );

    let (game, game_owner) = create(&s, json!({"map": "duel", "planner": "idle"})).await;
    let r = s.delete_as("/api/maps/duel", Some(&owner)).await;
    assert_error(&r, 409, "running match");
    // The match on it is unharmed.
    let t = tick_of(&s, &game).await;
    keeps_ticking(&s, &game, t).await;

    let path = format!("/api/matches/{game}");
    assert_eq!(s.delete_as(&path, Some(&game_owner)).await.status, 204);
    // Once it has gone, it is a 404 for everybody, its owner included.
    assert_error(
        &s.delete_as(&path, Some(&game_owner)).await,
        404,
        "no match",
    );
    assert_error(&s.delete_as(&path, Some(ADMIN)).await, 404, "no match");
    assert_eq!(
        s.delete_as("/api/maps/duel", Some(&owner)).await.status,
        204
    );
    assert_eq!(s.get("/api/maps/duel").await.status, 404);
    // The name is free again.
    assert_eq!(s.post_as("/api/maps", &duel_map(), None).await.status, 201);
}

#[tokio::test]
async fn each_client_has_a_quota_of_matches_and_maps() {
    let s = TestServer::start_with(Config {
        max_matches_per_address: 2,
        max_maps_per_address: 1,
        ..test_config()
    })
    .await;
    let manual = json!({"map": "office", "clock": "manual"});
    let (first, owner) = create(&s, manual.clone()).await;
    create(&s, manual.clone()).await;
    let r = s.post_as("/api/matches", &manual, None).await;
    assert_error(&r, 429, "holds 2 matches");
    assert_eq!(s.get(&format!("/api/matches/{first}")).await.status, 200);
    // Deleting one makes room again.
    let path = format!("/api/matches/{first}");
    assert_eq!(s.delete_as(&path, Some(&owner)).await.status, 204);
    create(&s, manual).await;

    assert_eq!(s.post_as("/api/maps", &duel_map(), None).await.status, 201);
    let mut second = duel_map();
    second["name"] = json!("duel-2");
    let r = s.post_as("/api/maps", &second, None).await;
    assert_error(&r, 429, "uploaded 1 maps");
    assert_eq!(s.get("/api/maps/duel-2").await.status, 404);
}

#[tokio::test]
async fn the_server_holds_at_most_its_number_of_maps() {
    let shipped = common::shipped_map_count();
    let s = TestServer::start_with(Config {
        max_maps: shipped + 1,
        ..test_config()
    })
    .await;
    assert_eq!(s.post_as("/api/maps", &duel_map(), None).await.status, 201);
    let mut second = duel_map();
    second["name"] = json!("duel-2");
    let r = s.post_as("/api/maps", &second, None).await;
    assert_error(&r, 503, "maps, its most");
}

#[tokio::test]
async fn a_manual_match_nobody_changes_ends_and_goes() {
    let s = TestServer::start_with(Config {
        idle_manual_after: Duration::from_millis(300),
        ..test_config()
    })
    .await;
    let (id, owner) = create(&s, json!({"map": "office", "clock": "manual"})).await;
    let path = format!("/api/matches/{id}");
    // Reading does not keep it alive; stepping does (checked while it is young).
    let r = s
        .post_as(&format!("{path}/step"), &json!({"ticks": 1}), Some(&owner))
        .await;
    assert_eq!(r.status, 200);
    let mut gone = false;
    for _ in 0..100 {
        tokio::time::sleep(Duration::from_millis(50)).await;
        if s.get(&path).await.status == 404 {
            gone = true;
            break;
        }
    }
    assert!(gone, "the idle manual match is still there");
    let metrics = s.client.get(s.url("/metrics")).send().await.unwrap();
    let text = metrics.text().await.unwrap();
    assert!(
        text.contains("lasertag_matches_removed_total{reason=\"idle\"} 1"),
        "{text}"
    );
}

#[tokio::test]
async fn a_slot_nobody_plays_is_held_briefly_and_one_client_holds_few() {
    let s = TestServer::start_with(Config {
        join_hold: Duration::from_millis(300),
        max_holds_per_address: 1,
        ..test_config()
    })
    .await;
    // Bots people may take over, as in the showcase.
    let (id, _) = create(
        &s,
        json!({"map": "office", "opponents": 3, "bots_joinable": true}),
    )
    .await;
    assert_eq!(free_slots(&s, &id).await, 3);
    let players = format!("/api/matches/{id}/players");
    let r = s
        .post_as(&players, &json!({"name": "squatter"}), None)
        .await;
    assert_eq!(r.status, 201, "{}", r.body);
    // The same client cannot hold a second slot it does not play.
    let r = s
        .post_as(&players, &json!({"name": "squatter 2"}), None)
        .await;
    assert_error(&r, 429, "without playing");
    assert_eq!(free_slots(&s, &id).await, 2);
    // Nobody connects: the hold lapses and the bot is back.
    let mut lapsed = false;
    for _ in 0..100 {
        tokio::time::sleep(Duration::from_millis(50)).await;
        if free_slots(&s, &id).await == 3 {
            lapsed = true;
            break;
        }
    }
    assert!(lapsed, "the unplayed slot is still held");
    // A slot that is played (an input sent) is not a hold: its player may join another.
    let (_, token) = s.join(&id, "player").await;
    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    ws.send_json(&json!({"type": "input", "forward": 1.0, "turn": 0.0, "tag": false}))
        .await
        .unwrap();
    let mut joined = false;
    for _ in 0..100 {
        let r = s.post_as(&players, &json!({"name": "friend"}), None).await;
        if r.status == 201 {
            joined = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(joined, "a played slot counted as a hold");
}

/// The `free_slots` of match `id` as the lobby lists it.
async fn free_slots(s: &TestServer, id: &str) -> u64 {
    let all = s.get("/api/matches").await.body;
    let found = all.as_array().unwrap().iter().find(|m| m["id"] == id);
    found.expect("listed")["free_slots"].as_u64().unwrap()
}

#[tokio::test]
async fn the_operators_token_is_held_to_no_address_rate_or_quota() {
    // One match and five requests a second per address: a research client with the admin
    // token steps a match hundreds of times and runs several; an anonymous one is refused.
    let s = TestServer::start_with(Config {
        admin_token: Some(Secret(ADMIN.into())),
        max_matches_per_address: 1,
        requests_per_s: 5.0,
        request_burst: 5.0,
        ..test_config()
    })
    .await;
    let body = json!({"map": "office", "robots": 2, "planner": "api", "clock": "manual"});
    let mut ids = Vec::new();
    for _ in 0..3 {
        let r = s.post_as("/api/matches", &body, Some(ADMIN)).await;
        assert_eq!(r.status, 201, "{}", r.body);
        ids.push(r.body["id"].as_str().unwrap().to_owned());
    }
    let act = format!("/api/matches/{}/act", ids[0]);
    for k in 0..100 {
        let r = s
            .post_as(
                &act,
                &json!({"commands": {"r0": {"forward": 1}}}),
                Some(ADMIN),
            )
            .await;
        assert_eq!(r.status, 200, "step {k}: {}", r.body);
    }
    let mut refused = false;
    for _ in 0..20 {
        if s.get_as("/api/health", None).await.status == 429 {
            refused = true;
            break;
        }
    }
    assert!(refused, "an anonymous client is still rate limited");
}
