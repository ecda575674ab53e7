//! Replays against the live match: whole matches played with bots, robot commands and a
//! WebSocket player sending random keys; once each has ended, its replay's state at every
//! tick (and belief at many) must be the JSON the live endpoints gave then.

mod common;

use common::{TestServer, assert_error, duel_map, temp_dir};
use rand::{RngExt, SeedableRng};
use serde_json::{Value, json};

/// Steps `id` one tick at a time for `ticks`, calling `between` before each step, and
/// returns the live state after every tick and the belief after every 10th.
async fn play(
    s: &TestServer,
    id: &str,
    ticks: u64,
    mut between: impl AsyncFnMut(u64),
) -> (Vec<Value>, Vec<(u64, Value)>) {
    let (mut states, mut beliefs) = (Vec::new(), Vec::new());
    for k in 0..ticks {
        between(k).await;
        let state = s.step(id, 1).await;
        let tick = state["tick"].as_u64().unwrap();
        if tick % 10 == 0 {
            let b = s.get(&format!("/api/matches/{id}/belief")).await;
            beliefs.push((tick, b.body));
        }
        let finished = state["status"] == "finished";
        states.push(state);
        if finished {
            break;
        }
    }
    (states, beliefs)
}

async fn end(s: &TestServer, id: &str) {
    assert_eq!(s.delete(&format!("/api/matches/{id}")).await.status, 204);
}

/// The same server restarted: a new one on `dir`, once the old one's store has everything.
async fn restart(old: &TestServer, dir: &std::path::Path) -> TestServer {
    old.flush_history();
    TestServer::start_stored(dir).await
}

async fn check_replay(s: &TestServer, id: &str, states: &[Value], beliefs: &[(u64, Value)]) {
    let r = s.get(&format!("/api/replays/{id}")).await;
    assert_eq!(r.status, 200, "{}", r.body);
    assert_eq!(r.body["id"], id);
    assert_eq!(r.body["complete"], true);
    let last = r.body["ticks"].as_u64().unwrap();
    assert!(last >= states.last().unwrap()["tick"].as_u64().unwrap());
    for live in states {
        let tick = live["tick"].as_u64().unwrap();
        let replayed = s.get(&format!("/api/replays/{id}/state?tick={tick}")).await;
        assert_eq!(replayed.status, 200, "{}", replayed.body);
        // The live read of a match that ended by deletion still said "running" at its last
        // tick; the end is an input applied after it.
        if tick < last {
            assert_eq!(replayed.body, *live, "state at tick {tick}");
        } else {
            assert_eq!(
                replayed.body["robots"], live["robots"],
                "robots at tick {tick}"
            );
        }
    }
    for (tick, live) in beliefs {
        let replayed = s
            .get(&format!("/api/replays/{id}/belief?tick={tick}"))
            .await;
        assert_eq!(replayed.body, *live, "belief at tick {tick}");
    }
}

#[tokio::test]
async fn a_replay_shows_what_the_live_match_showed_at_every_tick() {
    let dir = temp_dir("replays-live");
    let s = TestServer::start_stored(&dir).await;

    // Bots against the coordinated planner.
    let bots = s
        .create_match(
            json!({"map": "office", "robots": 2, "opponents": 2, "clock": "manual",
            "opponent_bot": "evade", "seed": 3}),
        )
        .await;
    let (bot_states, bot_beliefs) = play(&s, &bots, 300, async |_| {}).await;
    end(&s, &bots).await;
    check_replay(&s, &bots, &bot_states, &bot_beliefs).await;

    // Robots driven from outside, and API-driven opponents, with random commands.
    let api = s
        .create_match(
            json!({"map": duel_map(), "robots": 2, "opponents": 2, "planner": "api",
            "opponent_control": "api", "clock": "manual", "seed": 5}),
        )
        .await;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let mut commands = Vec::new();
    for k in 0..200u64 {
        if k % 7 == 0 {
            let c = json!({"forward": rng.random_range(-1.0..=1.0), "turn": rng.random_range(-1.0..=1.0),
                "tag": rng.random_bool(0.3)});
            commands.push((k, "r0", c));
        }
        if k % 25 == 0 {
            let p = [rng.random_range(1.0..13.0), rng.random_range(1.0..7.0)];
            commands.push((k, "o1", json!({"waypoints": [p]})));
        }
    }
    let (states, beliefs) = play(&s, &api, 200, async |k| {
        for (_, who, c) in commands.iter().filter(|(at, _, _)| *at == k) {
            let path = if who.starts_with('r') {
                format!("/api/matches/{api}/robots/{who}/command")
            } else {
                format!("/api/matches/{api}/opponents/{who}/command")
            };
            let r = s.post(&path, c).await;
            assert!(r.status == 204 || r.status == 409, "{}", r.body);
        }
    })
    .await;
    end(&s, &api).await;
    check_replay(&s, &api, &states, &beliefs).await;

    // After a restart both come from the database alone.
    let s = restart(&s, &dir).await;
    assert!(s.registry.history.get(&api).is_none(), "not in memory");
    check_replay(&s, &bots, &bot_states, &bot_beliefs).await;
    check_replay(&s, &api, &states, &beliefs).await;
}

#[tokio::test]
async fn a_replay_of_a_long_record_read_from_the_store_shows_the_live_match() {
    // Commands of 1,000 waypoints past what a replay keeps in memory (4 MB): the replay
    // reads them back from the store in windows, and still shows every tick as it was.
    let dir = temp_dir("replays-long");
    let s = TestServer::start_stored(&dir).await;
    let id = s
        .create_match(
            json!({"map": "office", "opponents": 1, "opponent_control": "api",
            "planner": "idle", "clock": "manual", "seed": 11}),
        )
        .await;
    let path = format!("/api/matches/{id}/opponents/o0/command");
    let (states, beliefs) = play(&s, &id, 75, async |k| {
        for j in 0..8u64 {
            let route: Vec<[f64; 2]> = (0..1000u64)
                .map(|i| [2.0 + ((i + k + j) % 20) as f64, 2.0 + (i % 5) as f64])
                .collect();
            let r = s.post(&path, &json!({ "waypoints": route })).await;
            assert_eq!(r.status, 204, "{}", r.body);
        }
    })
    .await;
    end(&s, &id).await;
    s.flush_history();
    assert!(
        s.registry.history.get(&id).is_none(),
        "a record this long is not kept in memory"
    );
    check_replay(&s, &id, &states, &beliefs).await;
}

#[tokio::test]
async fn a_replay_follows_a_player_over_the_websocket() {
    let dir = temp_dir("replays-player");
    let s = TestServer::start_stored(&dir).await;
    let id = s
        .create_match(
            json!({"map": "office", "robots": 1, "opponents": 2, "clock": "manual",
            "opponent_control": "human", "spectator_delay_s": 0}),
        )
        .await;
    // A kept name: only kept names have a history (docs/api.md, "Names people keep").
    let (_, token) = s.join_kept(&id, "ada").await;
    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    ws.next_of("welcome").await;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
    let mut seq = 0;
    let (mut states, mut beliefs) = (Vec::new(), Vec::new());
    for _ in 0..150 {
        seq += 1;
        let keys = json!({"type": "input", "seq": seq, "forward": rng.random_range(-1..=1),
            "turn": rng.random_range(-1..=1), "tag": rng.random_bool(0.1)});
        ws.send_json(&keys).await.unwrap();
        // The input is queued before the step: wait for its acknowledgement after it.
        let state = s.step(&id, 1).await;
        let tick = state["tick"].as_u64().unwrap();
        if tick % 10 == 0 {
            beliefs.push((tick, s.get(&format!("/api/matches/{id}/belief")).await.body));
        }
        let done = state["status"] == "finished";
        states.push(state);
        if done {
            break;
        }
    }
    drop(ws);
    end(&s, &id).await;
    check_replay(&s, &id, &states, &beliefs).await;
    let listed = s.get("/api/replays").await.body;
    let row = listed
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["id"] == id.as_str())
        .cloned()
        .expect("listed");
    assert_eq!(row["players"], json!(["ada"]));
    assert_eq!(row["reason"], "stopped");

    let s = restart(&s, &dir).await;
    check_replay(&s, &id, &states, &beliefs).await;
    // Deleted by its owner: the opponents won, with ada still in it.
    let ada = s.get("/api/players/ada").await;
    assert_eq!(ada.status, 200, "{}", ada.body);
    assert_eq!(
        (ada.body["matches"].as_u64(), ada.body["wins"].as_u64()),
        (Some(1), Some(1))
    );
    assert_eq!(ada.body["recent"][0]["id"], id.as_str());
    let board = s.get("/api/leaderboard?by=survival").await;
    assert_eq!(board.body["players"][0]["name"], "ada", "{}", board.body);
    assert!(
        board.body["players"][0]["longest_survival_s"]
            .as_f64()
            .unwrap()
            > 0.0
    );
    assert_error(&s.get("/api/players/nobody").await, 404, "nobody");

    // The export: a line every tenth tick, each the replay's state and belief then.
    let text = s
        .client
        .get(s.url(&format!("/api/replays/{id}/export?every=10&belief=true")))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    let mut lines: Vec<Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let last = states.last().unwrap()["tick"].as_u64().unwrap();
    // The last line says the export is whole.
    let end = lines.pop().unwrap();
    assert_eq!(end, json!({"complete": true, "lines": last / 10 + 1}));
    assert_eq!(lines.len() as u64, last / 10 + 1, "{text:.300}");
    for line in lines.iter().step_by(4) {
        let tick = line["tick"].as_u64().unwrap();
        let state = s.get(&format!("/api/replays/{id}/state?tick={tick}")).await;
        assert_eq!(line["state"], state.body, "tick {tick}");
        let belief = s
            .get(&format!("/api/replays/{id}/belief?tick={tick}"))
            .await;
        assert_eq!(line["belief"], belief.body, "tick {tick}");
    }
    assert_error(
        &s.get(&format!("/api/replays/{id}/export?from=5&to=2"))
            .await,
        400,
        "from",
    );
    assert_error(
        &s.get(&format!("/api/replays/{id}/export?every=0")).await,
        400,
        "every",
    );
    assert_error(
        &s.get(&format!("/api/replays/{id}/export?belief=maybe"))
            .await,
        400,
        "belief",
    );
    assert_error(&s.get("/api/leaderboard?by=luck").await, 400, "by");
}

#[tokio::test]
async fn replays_name_what_is_wrong() {
    let s = TestServer::start().await;
    assert_error(&s.get("/api/replays/nope").await, 404, "no replay");
    let id = s
        .create_match(json!({"map": "office", "clock": "manual", "seed": 1}))
        .await;
    s.step(&id, 5).await;
    // A match that runs is not a replay yet.
    assert_error(&s.get(&format!("/api/replays/{id}")).await, 404, "ended");
    end(&s, &id).await;
    assert_error(
        &s.get(&format!("/api/replays/{id}/state?tick=99")).await,
        404,
        "tick",
    );
    assert_error(&s.get("/api/replays?limit=0").await, 400, "limit");
    assert_error(
        &s.get(&format!("/api/replays/{id}/state")).await,
        400,
        "tick",
    );
    assert_eq!(
        s.get(&format!("/api/replays/{id}/state?tick=5"))
            .await
            .status,
        200
    );
    assert_error(&s.get("/api/replays?limit=x").await, 400, "limit");
}

/// The history lists matches the last to end first (a match that started first and ended
/// last comes first), and says what is wrong with a bad `showcase`.
#[tokio::test]
async fn past_matches_are_listed_in_the_order_they_ended() {
    let dir = temp_dir("replays-end-order");
    let s = TestServer::start_stored(&dir).await;
    let body = json!({"map": "office", "clock": "manual", "planner": "idle"});
    let first = s.create_match(body.clone()).await;
    let second = s.create_match(body).await;
    s.step(&first, 2).await;
    s.step(&second, 2).await;
    end(&s, &second).await;
    // Ends are kept to the second.
    tokio::time::sleep(std::time::Duration::from_millis(1100)).await;
    end(&s, &first).await;
    s.flush_history();
    for query in ["", "?showcase=false", "?showcase=true"] {
        let listed = s.get(&format!("/api/replays{query}")).await;
        assert_eq!(listed.status, 200, "{}", listed.body);
        let ids: Vec<&str> = (listed.body.as_array().unwrap().iter())
            .map(|r| r["id"].as_str().unwrap())
            .collect();
        assert_eq!(ids, [first.as_str(), second.as_str()], "{query}");
    }
    let older = s.get(&format!("/api/replays?before={first}")).await;
    assert_eq!(older.body.as_array().unwrap().len(), 1);
    assert_eq!(older.body[0]["id"], second.as_str());
    let r = s.get("/api/replays?showcase=maybe").await;
    assert_error(&r, 400, "showcase");
    // The browser's own request for an icon finds one.
    let icon = reqwest::get(s.url("/favicon.ico")).await.unwrap();
    assert_eq!(icon.status(), 200);
    assert!(icon.text().await.unwrap().contains("<svg"));
}
