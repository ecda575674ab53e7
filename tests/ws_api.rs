//! The WebSocket interface `/ws/matches/{id}` over a real server on an ephemeral port.

mod common;

use std::collections::BTreeSet;
use std::path::Path;
use std::time::Duration;

use common::{Got, TestServer, WsError, duel_map, idle_human_match, ids};
use lasertag::config::Config;
use lasertag::maps::MapStore;
use nalgebra::Point2;
use serde_json::json;

#[tokio::test]
async fn a_spectator_gets_every_tick_with_everything() {
    let s = TestServer::start().await;
    let id = s
        .create_match(json!({"map": "office", "opponents": 2, "planner": "baseline"}))
        .await;
    let mut ws = s.ws(&id, None).await.unwrap();
    let welcome = ws.json().await;
    assert_eq!(welcome["type"], "welcome");
    assert_eq!(welcome["role"], "spectator");
    assert_eq!(welcome["map"]["name"], "office");
    assert_eq!(welcome["belief"], true);
    let mut ticks = Vec::new();
    let mut with_belief = 0;
    while ticks.len() < 60 {
        let snap = ws.next_of("snapshot").await;
        assert_eq!(snap["view"], "spectator");
        assert_eq!(snap["robots"].as_array().unwrap().len(), 2);
        assert_eq!(snap["opponents"].as_array().unwrap().len(), 2);
        let r0 = &snap["robots"][0];
        assert_eq!(r0["scan"].as_array().unwrap().len(), 181, "{r0}");
        assert!(r0.get("goal").is_some());
        // Where the robot believes it is: near the truth, with a cloud of particles around.
        let (ex, ey) = (
            r0["estimate"]["x"].as_f64().unwrap(),
            r0["estimate"]["y"].as_f64().unwrap(),
        );
        let (tx, ty) = (r0["x"].as_f64().unwrap(), r0["y"].as_f64().unwrap());
        assert!((ex - tx).hypot(ey - ty) < 0.5, "{r0}");
        let cloud = r0["cloud"].as_array().unwrap();
        assert!(cloud.len() >= 2 * 20 && cloud.len() % 2 == 0, "{r0}");
        assert!(r0["spread"].as_f64().unwrap() < 0.5, "{r0}");
        if let Some(b) = snap.get("belief") {
            with_belief += 1;
            let roles = b["roles"].as_array().unwrap();
            let counted: u64 = roles
                .iter()
                .filter(|r| r["tagged"] == false)
                .map(|r| r["count"].as_u64().unwrap())
                .sum();
            assert_eq!(counted, 2, "{b}");
            let points: usize = roles
                .iter()
                .map(|r| r["points"].as_array().unwrap().len() / 2)
                .sum();
            assert!((1..=600).contains(&points), "{points} belief points shown");
        }
        ticks.push(snap["tick"].as_u64().unwrap());
    }
    // One snapshot per tick: a client that keeps up misses (almost) none.
    let span = ticks.last().unwrap() - ticks.first().unwrap() + 1;
    let distinct: BTreeSet<u64> = ticks.iter().copied().collect();
    assert!(
        distinct.len() as f64 >= 0.9 * span as f64,
        "{} snapshots over {span} ticks",
        distinct.len()
    );
    // The belief comes every fourth tick.
    assert!((12..=17).contains(&with_belief), "{with_belief} of 60");
    let summary = s.get(&format!("/api/matches/{id}")).await;
    assert_eq!(summary.status, 200);
    let listed = s.get("/api/matches").await;
    assert_eq!(listed.body[0]["spectators"], 1);
    let stats = s.get(&format!("/api/matches/{id}/stats")).await;
    assert_eq!(stats.status, 200, "{}", stats.body);
    assert!(stats.body["ticks_measured"].as_u64().unwrap() >= 50);
    assert!(stats.body["tick_us_p99"].as_f64().unwrap() > 0.0);
    // Most ticks come a period apart, so the longest interval is at least about one.
    let gap = stats.body["longest_tick_gap_ms"].as_f64().unwrap();
    assert!(gap >= 45.0, "longest tick gap {gap} ms");
    assert_eq!(stats.body["spectators"], 1);
}

#[tokio::test]
async fn a_player_never_sees_a_robot_out_of_its_line_of_sight() {
    let s = TestServer::start().await;
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let store = MapStore::load_dir(&root.join("maps")).unwrap();
    let arena = store.get("office").unwrap().arena.clone();
    let id = s
        .create_match(json!({"map": "office", "robots": 3, "opponents": 1,
            "opponent_control": "human", "planner": "baseline", "clock": "manual",
            "time_limit_s": 120}))
        .await;
    let (me, token) = s.join(&id, "alice").await;
    assert_eq!(me, "o0");
    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    let welcome = ws.json().await;
    assert_eq!(welcome["role"], "player");
    assert_eq!(welcome["you"], "o0");
    assert_eq!(welcome["belief"], false);
    ws.next_of("snapshot").await;
    let (mut seen, mut hidden, mut checked) = (0, 0, 0);
    let los = |a: [f64; 2], b: [f64; 2]| {
        arena.line_of_sight(
            Point2::new(a[0] as f32, a[1] as f32),
            Point2::new(b[0] as f32, b[1] as f32),
        )
    };
    loop {
        let t = s.get(&format!("/api/matches/{id}")).await.body["tick"]
            .as_u64()
            .unwrap();
        if t % 40 == 0 {
            // Wander: drive forward, turning one way then the other.
            let turn = if (t / 40) % 2 == 0 { 0.6 } else { -0.4 };
            ws.send_json(&json!({"type": "input", "forward": 1.0, "turn": turn, "tag": false}))
                .await
                .unwrap();
            // Let the connection hand the input to the match task (on a loaded machine
            // 30 ms was not always enough, and the player then walked another way).
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        let truth = s.step(&id, 1).await;
        let tick = truth["tick"].as_u64().unwrap();
        let snap = loop {
            let v = ws.next_of("snapshot").await;
            if v["tick"].as_u64().unwrap() >= tick {
                break v;
            }
        };
        assert_eq!(snap["tick"].as_u64().unwrap(), tick);
        let opp = &truth["opponents"][0];
        if opp["tagged"] == true {
            // Tagged: live, through its teammates' eyes (it has none here: only its own
            // tagged body), never the truth and never back in time.
            assert_eq!(snap["view"], "teammates");
            assert_eq!(snap["tick"].as_u64().unwrap(), tick);
            assert!(ids(&snap["robots"]).is_empty(), "{snap}");
            break;
        }
        assert_eq!(snap["view"], "player");
        assert!(
            snap["robots"][0].get("scan").is_none(),
            "players get no scans"
        );
        assert!(
            snap["robots"][0].get("cloud").is_none(),
            "players get no localisation clouds"
        );
        assert!(
            snap.get("belief").is_none(),
            "belief is off until asked for"
        );
        let me = [opp["x"].as_f64().unwrap(), opp["y"].as_f64().unwrap()];
        let sent = ids(&snap["robots"]);
        for r in truth["robots"].as_array().unwrap() {
            let at = [r["x"].as_f64().unwrap(), r["y"].as_f64().unwrap()];
            let expected = los(me, at);
            // Positions are rounded to millimetres: skip the rare grazing case where that
            // rounding could flip the answer.
            let nudged = [(0.002, 0.0), (-0.002, 0.0), (0.0, 0.002), (0.0, -0.002)]
                .iter()
                .all(|(dx, dy)| los([me[0] + dx, me[1] + dy], at) == expected);
            // Bodies hide too (game rules, fog): leave out the lines that pass near another
            // robot, where whether its disc hides this one is the server's finer call.
            let near_a_body = truth["robots"].as_array().unwrap().iter().any(|o| {
                let c = [o["x"].as_f64().unwrap(), o["y"].as_f64().unwrap()];
                c != at && distance_to_segment(c, me, at) < 0.6
            });
            if !nudged || (expected && near_a_body) {
                continue;
            }
            checked += 1;
            let id = r["id"].as_str().unwrap();
            assert_eq!(
                sent.contains(id),
                expected,
                "tick {tick}: robot {id} at {at:?}, player at {me:?}, line of sight {expected}"
            );
            if expected { seen += 1 } else { hidden += 1 }
        }
        // Enough of both answers seen (a player who wandered where no robot came for a
        // while only makes the walk longer).
        if truth["status"] == "finished" || (seen > 20 && hidden > 100) {
            break;
        }
    }
    assert!(checked > 100, "{checked} robot-ticks checked");
    assert!(seen > 0 && hidden > 0, "seen {seen}, hidden {hidden}");
    // Asking for the belief adds it to the player's snapshots.
    let id2 = s
        .create_match(json!({"map": "office", "opponent_control": "human", "clock": "manual"}))
        .await;
    let (_, token) = s.join(&id2, "bob").await;
    let mut ws = s.ws(&id2, Some(&token)).await.unwrap();
    ws.next_of("snapshot").await;
    ws.send_json(&json!({"type": "belief", "on": true}))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(100)).await;
    s.step(&id2, 4).await;
    let snap = ws.next_of("snapshot").await;
    assert!(snap["belief"]["roles"].as_array().is_some(), "{snap}");
}

/// The distance from `c` to the segment from `a` to `b`.
fn distance_to_segment(c: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 == 0.0 {
        0.0
    } else {
        (((c[0] - a[0]) * dx + (c[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    };
    let (px, py) = (a[0] + t * dx - c[0], a[1] + t * dy - c[1]);
    (px * px + py * py).sqrt()
}

#[tokio::test]
async fn bad_tokens_and_unknown_matches_are_refused_before_the_upgrade() {
    let s = TestServer::start().await;
    let id = s
        .create_match(json!({"map": "office", "opponent_control": "human", "clock": "manual"}))
        .await;
    match s.ws(&id, Some("not-a-token")).await {
        Err(WsError::Http(r)) => assert_eq!(r.status(), 401),
        Err(e) => panic!("expected 401, got {e}"),
        Ok(_) => panic!("a bad token was let in"),
    }
    match s.ws("nope", None).await {
        Err(WsError::Http(r)) => assert_eq!(r.status(), 404),
        Err(e) => panic!("expected 404, got {e}"),
        Ok(_) => panic!("an unknown match was let in"),
    }
    // A plain GET is not an upgrade.
    let r = s.get(&format!("/ws/matches/{id}")).await;
    assert_eq!(r.status, 400, "{}", r.body);
}

#[tokio::test]
async fn junk_gets_errors_then_a_close_and_never_reaches_the_match() {
    let s = TestServer::start().await;
    let id = idle_human_match(&s).await;
    let (_, token) = s.join(&id, "mallory").await;
    let before = s.get(&format!("/api/matches/{id}")).await.body["opponents"][0].clone();
    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    let mut watcher = s.ws(&id, None).await.unwrap();
    ws.next_of("snapshot").await;
    // One bad message: a clear error, and the connection stays.
    ws.send_json(&json!({"type": "input", "forward": 5, "turn": 0}))
        .await
        .unwrap();
    let e = ws.next_of("error").await;
    assert_eq!(e["error"], "forward: 5 must be in -1..=1");
    // A thousand junk, malformed and oversized messages.
    let junk = [
        "junk".to_string(),
        "{\"type\": \"input\", \"forward\": 1}".to_string(),
        format!(
            "{{\"type\": \"input\", \"forward\": 1, \"turn\": 0, \"pad\": \"{}\"}}",
            "x".repeat(5000)
        ),
        "{\"type\": \"teleport\", \"x\": 3}".to_string(),
        "[1, 2, 3]".to_string(),
    ];
    for i in 0..1000 {
        if ws.send_text(junk[i % junk.len()].clone()).await.is_err() {
            break; // the server has closed us already
        }
    }
    let mut errors = 1;
    let closed = loop {
        match ws.next().await {
            Got::Json(v) if v["type"] == "error" => errors += 1,
            Got::Json(_) => {}
            Got::Closed { code, reason } => break (code, reason),
            Got::Ended => panic!("the server dropped the connection without a reason"),
        }
    };
    assert_eq!(closed.0, 1008, "{closed:?}");
    assert!(closed.1.contains("too many bad messages"), "{closed:?}");
    assert!(errors >= 5, "{errors} error messages before the close");
    // The match runs on, untouched: nothing reached the opponent, others still watch.
    let after = s.step(&id, 20).await;
    assert_eq!(after["status"], "running");
    assert_eq!(after["opponents"][0]["x"], before["x"]);
    assert_eq!(after["opponents"][0]["y"], before["y"]);
    let snap = watcher.next_of("snapshot").await;
    assert!(snap["tick"].as_u64().unwrap() <= 20);
    // A message over the hard cap closes at once with 1009.
    let mut big = s.ws(&id, None).await.unwrap();
    big.next_of("snapshot").await;
    let _ = big.send_text("x".repeat(100_000)).await;
    loop {
        match big.next().await {
            Got::Json(_) => continue,
            Got::Closed { code, .. } => {
                assert_eq!(code, 1009);
                break;
            }
            Got::Ended => break, // the socket was cut before the close frame got through
        }
    }
    // A spectator may not drive anyone.
    watcher
        .send_json(&json!({"type": "input", "forward": 1, "turn": 0}))
        .await
        .unwrap();
    let e = watcher.next_of("error").await;
    assert!(e["error"].as_str().unwrap().contains("spectators"), "{e}");
}

#[tokio::test]
async fn a_player_who_drops_keeps_the_slot_for_the_grace_period() {
    let s = TestServer::start().await;
    let id = idle_human_match(&s).await;
    let (me, token) = s.join(&id, "alice").await;
    let start = s.get(&format!("/api/matches/{id}")).await.body["opponents"][0].clone();
    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    ws.next_of("snapshot").await;
    ws.send_json(&json!({"type": "input", "forward": 1, "turn": 0}))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(150)).await;
    let moving = s.step(&id, 10).await["opponents"][0].clone();
    drop(ws);
    // The task notices the drop within its housekeeping period; meanwhile it stands still.
    tokio::time::sleep(Duration::from_millis(400)).await;
    let a = s.step(&id, 1).await["opponents"][0].clone();
    let b = s.step(&id, 10).await["opponents"][0].clone();
    assert_ne!(
        (&moving["x"], &moving["y"]),
        (&start["x"], &start["y"]),
        "it moves while connected"
    );
    assert_eq!(
        (a["x"].clone(), a["y"].clone()),
        (b["x"].clone(), b["y"].clone())
    );
    // Back with the same token: the same opponent, no one left.
    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    let welcome = ws.json().await;
    assert_eq!(welcome["you"], me);
    let kinds: Vec<String> = s
        .events(&id)
        .await
        .iter()
        .map(|e| e["kind"].as_str().unwrap().to_string())
        .collect();
    assert!(!kinds.contains(&"player_left".to_string()), "{kinds:?}");
    // A second connection with the token takes over; the first is told why.
    let mut again = s.ws(&id, Some(&token)).await.unwrap();
    assert_eq!(again.json().await["you"], me);
    let closed = loop {
        match ws.next().await {
            Got::Closed { code, reason } => break (code, reason),
            Got::Json(_) => continue,
            Got::Ended => panic!("closed without a reason"),
        }
    };
    assert_eq!(closed.0, 1008);
    assert!(closed.1.contains("another connection"), "{closed:?}");
    let summary = s.get("/api/matches").await.body[0].clone();
    assert_eq!(summary["players"], 1);
    assert_eq!(summary["free_slots"], 0);
}

#[tokio::test]
async fn a_slot_is_freed_after_the_grace_period_and_a_bot_comes_back() {
    let s = TestServer::start_with(Config {
        reconnect_grace: Duration::from_millis(600),
        ..common::test_config()
    })
    .await;
    // People may take over the bots of this match (as in the showcase).
    let id = s
        .create_match(json!({"map": "office", "opponents": 1, "clock": "manual",
            "bots_joinable": true}))
        .await;
    let summary = s.get("/api/matches").await.body[0].clone();
    assert_eq!(summary["free_slots"], 1);
    let (_, token) = s.join(&id, "carol").await;
    let state = s.get(&format!("/api/matches/{id}")).await.body;
    assert_eq!(state["opponents"][0]["control"], "human");
    let ws = s.ws(&id, Some(&token)).await.unwrap();
    drop(ws);
    tokio::time::sleep(Duration::from_millis(1500)).await;
    match s.ws(&id, Some(&token)).await {
        Err(WsError::Http(r)) => assert_eq!(r.status(), 401),
        other => panic!(
            "expected 401 after the grace period, got {:?}",
            other.is_ok()
        ),
    }
    let state = s.get(&format!("/api/matches/{id}")).await.body;
    assert_eq!(state["opponents"][0]["control"], "bot");
    let kinds: Vec<String> = s
        .events(&id)
        .await
        .iter()
        .map(|e| e["kind"].as_str().unwrap().to_string())
        .collect();
    assert!(kinds.contains(&"player_left".to_string()), "{kinds:?}");
    let summary = s.get("/api/matches").await.body[0].clone();
    assert_eq!(summary["players"], 0);
    assert_eq!(summary["free_slots"], 1);
}

#[tokio::test]
async fn events_and_the_end_reach_players_and_spectators() {
    let s = TestServer::start().await;
    // The opponent starts at (3, 4) facing the arena's centre (east); a robot idles at (6, 4).
    let id = s
        .create_match(json!({"map": duel_map(), "robots": 1, "opponents": 1,
            "opponent_control": "human", "planner": "idle", "clock": "realtime",
            "spectator_delay_s": 0,
            "robot_starts": [[6.0, 4.0, std::f64::consts::PI]], "opponent_starts": [[3.0, 4.0]],
            "time_limit_s": 3}))
        .await;
    let (_, token) = s.join(&id, "dave").await;
    let mut player = s.ws(&id, Some(&token)).await.unwrap();
    let mut spectator = s.ws(&id, None).await.unwrap();
    let snap = player.next_of("snapshot").await;
    assert_eq!(
        ids(&snap["robots"]).len(),
        1,
        "the robot in front is in sight"
    );
    player
        .send_json(&json!({"type": "input", "forward": 0, "turn": 0, "tag": true}))
        .await
        .unwrap();
    player
        .send_json(&json!({"type": "ping", "t": 12.5}))
        .await
        .unwrap();
    assert_eq!(player.next_of("pong").await["t"], 12.5);
    let tagged = loop {
        let e = player.next_of("event").await;
        if e["kind"] == "robot_tagged" {
            break e;
        }
    };
    assert_eq!(tagged["by"], "o0");
    assert_eq!(tagged["target"], "r0");
    let mut kinds = Vec::new();
    let finished = loop {
        match spectator.json().await {
            v if v["type"] == "finished" => break v,
            v if v["type"] == "event" => kinds.push(v["kind"].as_str().unwrap().to_string()),
            _ => {}
        }
    };
    assert!(kinds.contains(&"robot_tagged".to_string()), "{kinds:?}");
    assert_eq!(kinds.last().map(String::as_str), Some("finished"));
    assert_eq!(finished["winner"], "opponents");
    assert_eq!(finished["reason"], "time_limit");
    assert_eq!(player.next_of("finished").await["winner"], "opponents");
    // Deleting the match closes its viewers with a reason.
    s.delete(&format!("/api/matches/{id}")).await;
    loop {
        match spectator.next().await {
            Got::Closed { code, reason } => {
                assert_eq!(code, 1000);
                assert!(reason.contains("ended"), "{reason}");
                break;
            }
            Got::Json(_) => continue,
            Got::Ended => panic!("closed without a reason"),
        }
    }
}

#[tokio::test]
async fn input_at_20_hz_is_never_rate_limited() {
    let s = TestServer::start().await;
    let id = idle_human_match(&s).await;
    let (_, token) = s.join(&id, "erin").await;
    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    ws.next_of("snapshot").await;
    // Three seconds of keys at 20 Hz with a ping every second, as the web client sends them.
    for i in 0..60 {
        let turn = if i % 2 == 0 { 0.5 } else { -0.5 };
        ws.send_json(&json!({"type": "input", "forward": 1, "turn": turn, "tag": i % 20 == 0}))
            .await
            .unwrap();
        if i % 20 == 0 {
            ws.send_json(&json!({"type": "ping", "t": i}))
                .await
                .unwrap();
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    ws.send_json(&json!({"type": "ping", "t": -1}))
        .await
        .unwrap();
    loop {
        let v = ws.json().await;
        assert_ne!(v["type"], "error", "{v}");
        if v["type"] == "pong" && v["t"].as_f64() == Some(-1.0) {
            break;
        }
    }
}

#[tokio::test]
async fn a_tagged_player_watches_live_and_never_back_in_time() {
    let s = TestServer::start().await;
    // o0 stands right behind a searching robot; o1, far off, keeps the match going.
    let id = s
        .create_match(json!({"map": duel_map(), "robots": 1, "opponents": 2,
            "opponent_control": "human", "planner": "baseline", "clock": "manual",
            "robot_starts": [[6.0, 4.0, std::f64::consts::PI]],
            "opponent_starts": [[8.0, 4.0], [13.0, 1.0]],
            "spectator_delay_s": 1}))
        .await;
    let (me, token) = s.join(&id, "erin").await;
    assert_eq!(me, "o0");
    let mut player = s.ws(&id, Some(&token)).await.unwrap();
    assert_eq!(player.json().await["spectator_delay_s"], 1.0);
    // Live while it plays.
    let truth = s.step(&id, 1).await;
    let live = loop {
        let snap = player.next_of("snapshot").await;
        if snap["tick"] == truth["tick"] {
            break snap;
        }
    };
    assert_eq!(live["view"], "player");
    let mut now = 1;
    while s.get(&format!("/api/matches/{id}")).await.body["opponents"][0]["tagged"] != true {
        assert!(now < 400, "o0 was never tagged");
        now = s.step(&id, 1).await["tick"].as_u64().unwrap();
    }
    // Then live still, through o1's eyes: every snapshot's tick at least the one before.
    let until = s.step(&id, 30).await["tick"].as_u64().unwrap();
    let mut last = 0;
    let mut teammates = 0;
    loop {
        let snap = player.next_of("snapshot").await;
        let tick = snap["tick"].as_u64().unwrap();
        assert!(tick >= last, "the clock went back from {last} to {tick}");
        assert_ne!(snap["view"], "spectator", "{snap}");
        last = tick;
        teammates += (snap["view"] == "teammates") as usize;
        if tick >= until {
            break;
        }
    }
    // (A step of 30 ticks publishes them faster than a socket sends: it may skip some.)
    assert!(teammates > 0, "no snapshot in the teammates' view");
}
