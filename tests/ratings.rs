//! Ratings over the real server: which matches are rated, that nobody in a rated match reads
//! its truth live (its owner token reads it as late as everybody and never sees its seed
//! while it runs), and a rated match played to its end by a person over a WebSocket rating
//! them in the history, shown with the player and on the leaderboard.

mod common;

use std::time::Duration;

use common::{ADMIN, TestServer};
use lasertag::config::Config;
use serde_json::{Value, json};

/// The lobby's request for a rated match: a preset, one person's seat, a shipped map.
fn rated_request() -> Value {
    json!({"map": "office", "difficulty": "recruit", "opponent_control": "human"})
}

async fn stored_server(what: &str) -> TestServer {
    let dir = common::temp_dir(what);
    let store = lasertag::store::Store::open(
        &dir,
        lasertag::store::Retention {
            max_matches: 1000,
            max_bytes: 1 << 30,
        },
    )
    .expect("the store opens");
    TestServer::start_with_history(
        Config {
            admin_token: Some(lasertag::config::Secret(ADMIN.into())),
            ..common::test_config()
        },
        lasertag::game::replay::History::with_store(store),
    )
    .await
}

#[tokio::test]
async fn only_a_preset_as_measured_is_rated_and_its_owner_reads_it_late() {
    let s = stored_server("ratings-owner").await;
    let r = s.post_as("/api/matches", &rated_request(), None).await;
    assert_eq!(r.status, 201, "{}", r.body);
    assert_eq!(r.body["rated"], true, "{}", r.body);
    assert!(
        r.body["seed"].is_null(),
        "the owner may be the player: {}",
        r.body
    );
    let id = r.body["id"].as_str().unwrap().to_string();
    let owner = r.body["owner_token"].as_str().unwrap().to_string();

    // Anything that changes the team, the clock, the seats or the map is not the preset
    // as measured: not rated, and its owner reads it live with its seed, as before.
    let mut changed = Vec::new();
    for (field, value) in [
        ("robots", json!(2)),
        ("planner", json!("coordinated")),
        ("time_limit_s", json!(600)),
        ("opponents", json!(2)),
        ("opponent_control", json!("bot")),
        ("localisation", json!(false)),
        ("map", common::duel_map()),
        // Strangers would read it live, starts the presets were not measured with, a map
        // they were not measured on.
        ("spectator_delay_s", json!(0)),
        ("spectator_delay_s", json!(29.9)),
        ("placement", json!("random")),
        ("map", json!("hallway")),
    ] {
        let mut body = rated_request();
        body[field] = value;
        let r = s.post_as("/api/matches", &body, None).await;
        assert_eq!(r.status, 201, "{field}: {}", r.body);
        assert_eq!(r.body["rated"], false, "{field}: {}", r.body);
        changed.push(r.body);
    }
    let mut no_preset = rated_request();
    no_preset.as_object_mut().unwrap().remove("difficulty");
    let r = s.post_as("/api/matches", &no_preset, None).await;
    assert_eq!(r.body["rated"], false, "{}", r.body);
    assert!(
        changed[0]["seed"].is_u64(),
        "an unrated match's owner sees its seed"
    );

    // The listing: the owner's token opens the seed of an unrated match, not of a rated one.
    let mine = listed(&s, &id, &owner).await;
    assert!(mine["seed"].is_null(), "{mine}");
    let theirs = listed(&s, &id, ADMIN).await;
    assert!(theirs["seed"].is_u64(), "the operator sees it: {theirs}");

    // Live against late: after a second the operator's view has moved on, the owner's is
    // still held back at the start (the delay is 30 s), like everybody's.
    tokio::time::sleep(Duration::from_millis(1500)).await;
    let path = format!("/api/matches/{id}");
    let live = s.get_as(&path, Some(ADMIN)).await.body["tick"]
        .as_u64()
        .unwrap();
    let owners = s.get_as(&path, Some(&owner)).await;
    assert_eq!(owners.status, 200, "{}", owners.body);
    let public = s.get_as(&path, None).await.body["tick"].as_u64().unwrap();
    let owners = owners.body["tick"].as_u64().unwrap();
    assert!(live >= 20, "the match runs: tick {live}");
    assert_eq!(owners, public, "the owner reads what everybody reads");
    assert!(owners + 20 <= live, "owner at {owners}, live {live}");
    let belief = s.get_as(&format!("{path}/belief"), Some(&owner)).await;
    assert_eq!(belief.status, 200, "{}", belief.body);
    // The owner still owns it: they may end it (an end not by the rules rates nobody).
    assert_eq!(s.delete_as(&path, Some(&owner)).await.status, 204);
}

/// Match `id` in the listing, as `token` reads it.
async fn listed(s: &TestServer, id: &str, token: &str) -> Value {
    let listing = s.get_as("/api/matches", Some(token)).await.body;
    listing
        .as_array()
        .and_then(|all| all.iter().find(|m| m["id"] == id))
        .cloned()
        .unwrap_or_else(|| panic!("{id} is not listed: {listing}"))
}

/// Polls `path` until `done` holds of its body (at most `secs`).
async fn until(s: &TestServer, path: &str, secs: u64, done: impl Fn(&Value) -> bool) -> Value {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(secs);
    loop {
        let r = s.get_as(path, None).await;
        if r.status == 200 && done(&r.body) {
            return r.body;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "{path} after {secs} s: {} {}",
            r.status,
            r.body
        );
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
}

/// Claims `name` on the server: its token.
async fn keep(s: &TestServer, name: &str) -> String {
    let r = s.post_as("/api/names", &json!({"name": name}), None).await;
    assert_eq!(r.status, 201, "{}", r.body);
    r.body["name_token"].as_str().unwrap().to_string()
}

/// Creates a rated match and seats `name` in it (with `name_token` when given): the match
/// and the person's WebSocket.
async fn seated(s: &TestServer, name: &str, name_token: Option<&str>) -> (String, common::Ws) {
    let r = s.post_as("/api/matches", &rated_request(), None).await;
    assert_eq!(r.status, 201, "{}", r.body);
    assert_eq!(r.body["rated"], true, "{}", r.body);
    let id = r.body["id"].as_str().unwrap().to_string();
    let mut body = json!({"name": name});
    if let Some(t) = name_token {
        body["name_token"] = json!(t);
    }
    let r = s
        .post_as(&format!("/api/matches/{id}/players"), &body, None)
        .await;
    assert_eq!(r.status, 201, "{}", r.body);
    let token = r.body["token"].as_str().unwrap().to_string();
    let ws = s.ws(&id, Some(&token)).await.expect("the player connects");
    (id, ws)
}

/// Plays on `ws` until the match finishes: the `finished` message.
async fn until_finished(ws: &mut common::Ws) -> Value {
    loop {
        let msg = tokio::time::timeout(Duration::from_secs(150), ws.json())
            .await
            .expect("the match ends within its two minutes");
        if msg["type"] == "finished" {
            return msg;
        }
    }
}

/// Whole rated matches, as people play them, side by side: each lasts until the robot tags
/// its person or the two minutes are up (whichever the secret seed brings). Only a kept
/// name whose person played is rated: one who stands still all match, or plays under a
/// name nobody keeps, rates nobody (a rating can be neither farmed by idling nor wrecked
/// under a name one does not hold).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_rated_match_played_to_its_end_rates_its_player() {
    let s = stored_server("ratings-played").await;
    let rita = keep(&s, "rita").await;
    let idle = keep(&s, "idle").await;
    let (id, mut ws) = seated(&s, "rita", Some(&rita)).await;
    let (idle_id, mut idle_ws) = seated(&s, "idle", Some(&idle)).await;
    let (_, mut free_ws) = seated(&s, "free", None).await;
    // rita walks in a circle for eight seconds, then stands; the others send one input (a
    // slot held without input lapses) and stand where they spawned, connected, to the end.
    let walk = json!({"type": "input", "forward": 1.0, "turn": 0.5, "tag": false});
    let still = json!({"type": "input", "forward": 0.0, "turn": 0.0, "tag": false});
    ws.send_json(&walk).await.expect("input");
    idle_ws.send_json(&still).await.expect("input");
    free_ws.send_json(&walk).await.expect("input");
    tokio::time::sleep(Duration::from_secs(8)).await;
    ws.send_json(&still).await.expect("input");
    let (finished, idle_finished, _) = tokio::join!(
        until_finished(&mut ws),
        until_finished(&mut idle_ws),
        until_finished(&mut free_ws)
    );
    let won = finished["winner"] == "opponents";
    s.flush_history();

    let player = until(&s, "/api/players/rita", 10, |b| {
        b["recent"][0]["rating_after"].is_number()
    })
    .await;
    let played = &player["recent"][0];
    assert_eq!(played["id"], id.as_str(), "{player}");
    assert_eq!(played["rating_before"], 1500.0, "{player}");
    let after = played["rating_after"].as_f64().unwrap();
    assert_eq!(after > 1500.0, won, "won {won}, rated {after}: {player}");
    assert_eq!(player["rating"]["rating"].as_f64(), Some(after), "{player}");
    assert_eq!(player["rating"]["matches"], 1, "{player}");
    assert!(player["rating"]["deviation"].as_f64().unwrap() < 350.0);

    // Standing still: the match counts for the name's figures, not its rating.
    let idler = until(&s, "/api/players/idle", 10, |_| true).await;
    assert_eq!(idler["recent"][0]["id"], idle_id.as_str(), "{idler}");
    assert!(idler["recent"][0]["rating_after"].is_null(), "{idler}");
    assert!(idler["rating"].is_null(), "{idler} after {idle_finished}");
    // A name nobody keeps has no figures at all.
    assert_eq!(s.get("/api/players/free").await.status, 404);

    let board = until(&s, "/api/leaderboard?by=rating", 5, |_| true).await;
    assert_eq!(board["by"], "rating");
    assert_eq!(board["players"][0]["name"], "rita", "{board}");
    assert_eq!(
        board["players"].as_array().map(Vec::len),
        Some(1),
        "{board}"
    );
    let replay = until(&s, &format!("/api/replays/{id}"), 5, |_| true).await;
    assert_eq!(replay["settings"]["rated"], true, "{replay}");
    assert_eq!(replay["settings"]["difficulty"], "recruit", "{replay}");
}
