//! The replay WebSocket `/ws/replays/{id}` over a real server: a short match played to its
//! end, then watched again: the first message, snapshots in tick order, pause, seek (whose
//! snapshot is the REST replay's state at that tick), speed, the end, bad messages, a
//! player's fogged view and the refusals before the upgrade.

mod common;

use std::time::Duration;

use common::{Got, TestServer, Ws, WsError, WsMessage, assert_error};
use futures_util::StreamExt;
use nalgebra::Point2;
use serde_json::{Value, json};

/// A manual office match with one person (ada, o0) who drives forward from the start, two
/// robots (coordinated unless `more` says otherwise), and an 8 s time limit, stepped to its
/// end. Returns its id.
async fn finished_match(s: &TestServer, more: Value) -> String {
    let mut request = json!({"map": "office", "robots": 2, "opponents": 1, "clock": "manual",
            "opponent_control": "human", "spectator_delay_s": 0, "time_limit_s": 8});
    if let (Some(r), Some(m)) = (request.as_object_mut(), more.as_object()) {
        r.extend(m.clone());
    }
    let id = s.create_match(request).await;
    let (_, token) = s.join(&id, "ada").await;
    let mut player = s.ws(&id, Some(&token)).await.expect("player connects");
    player.next_of("welcome").await;
    player
        .send_json(&json!({"type": "input", "forward": 1.0, "turn": 0.2}))
        .await
        .unwrap();
    // Let the connection hand the keys to the match task before it steps.
    tokio::time::sleep(Duration::from_millis(50)).await;
    let end = s.step(&id, 1000).await;
    assert_eq!(end["status"], "finished", "{end}");
    drop(player);
    // A match is in the history from the moment it ends; give its task a moment.
    for _ in 0..50 {
        if s.get(&format!("/api/replays/{id}")).await.status == 200 {
            return id;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("match {id} never became a replay");
}

async fn open(s: &TestServer, id: &str, query: &str) -> Result<Ws, WsError> {
    let url = format!("ws://{}/ws/replays/{id}{query}", s.addr);
    let (stream, _) = tokio_tungstenite::connect_async(url).await?;
    Ok(Ws { stream })
}

/// Waits until nothing comes for `quiet`, returning what came before.
async fn drain(ws: &mut Ws, quiet: Duration) -> Vec<Value> {
    let mut got = Vec::new();
    while let Ok(Some(Ok(m))) = tokio::time::timeout(quiet, ws.stream.next()).await {
        if let WsMessage::Text(t) = m {
            got.push(serde_json::from_str(t.as_str()).expect("JSON text"));
        }
    }
    got
}

/// The next `replay_status`, checking that only snapshots and events come before it.
async fn status(ws: &mut Ws) -> Value {
    loop {
        let v = ws.json().await;
        match v["type"].as_str() {
            Some("replay_status") => return v,
            Some("snapshot") | Some("event") => {}
            _ => panic!("unexpected before replay_status: {v}"),
        }
    }
}

/// The fields a snapshot shares with the REST state: equal, agent by agent.
fn assert_same_as_state(snap: &Value, state: &Value) {
    for k in ["tick", "time_s", "status", "winner"] {
        assert_eq!(snap[k], state[k], "{k}");
    }
    let robots = snap["robots"].as_array().unwrap();
    assert_eq!(robots.len(), state["robots"].as_array().unwrap().len());
    for (a, b) in robots.iter().zip(state["robots"].as_array().unwrap()) {
        for k in [
            "id", "x", "y", "theta", "frozen", "estimate", "goal", "spread",
        ] {
            assert_eq!(a[k], b[k], "robot {} {k}", a["id"]);
        }
    }
    let opponents = snap["opponents"].as_array().unwrap();
    for (a, b) in opponents.iter().zip(state["opponents"].as_array().unwrap()) {
        for k in ["id", "x", "y", "theta", "tagged", "control"] {
            assert_eq!(a[k], b[k], "opponent {} {k}", a["id"]);
        }
    }
}

#[tokio::test]
async fn a_replay_plays_pauses_seeks_and_stops_at_its_end() {
    let s = TestServer::start().await;
    let id = finished_match(&s, json!({})).await;
    let detail = s.get(&format!("/api/replays/{id}")).await.body;
    let last = detail["ticks"].as_u64().unwrap();
    assert!(last >= 100, "{detail}");

    let mut ws = open(&s, &id, "").await.expect("replay socket opens");
    let first = ws.json().await;
    assert_eq!(first["type"], "replay", "{first}");
    assert_eq!(first["id"], id.as_str());
    assert_eq!(first["ticks"], last);
    assert_eq!(first["tick_hz"], 20);
    assert_eq!(first["speed"], 1.0);
    assert_eq!(first["playing"], true);
    assert_eq!(first["view"], "full");
    assert_eq!(first["belief"], true);
    assert_eq!(first["map"]["name"], "office");
    assert!(
        first["kinematics"]["speed"].as_f64().unwrap() > 0.0,
        "{first}"
    );

    // Snapshots come in tick order, from the start, with the belief.
    let mut ticks = Vec::new();
    let mut with_belief = 0;
    while ticks.len() < 12 {
        let snap = ws.next_of("snapshot").await;
        assert_eq!(snap["view"], "spectator");
        with_belief += snap.get("belief").is_some() as usize;
        ticks.push(snap["tick"].as_u64().unwrap());
    }
    assert_eq!(ticks[0], 0);
    assert!(ticks.windows(2).all(|w| w[0] < w[1]), "{ticks:?}");
    assert!(with_belief >= 3, "{with_belief} snapshots with the belief");

    // Pause: a status, then nothing more.
    ws.send_json(&json!({"type": "pause"})).await.unwrap();
    let paused = status(&mut ws).await;
    assert_eq!(paused["playing"], false, "{paused}");
    assert_eq!(paused["speed"], 1.0);
    let after = drain(&mut ws, Duration::from_millis(400)).await;
    assert!(after.is_empty(), "sent while paused: {after:?}");

    // Seek while paused: that tick's snapshot at once, the replay's state at that tick.
    ws.send_json(&json!({"type": "seek", "tick": 100}))
        .await
        .unwrap();
    let snap = ws.next_of("snapshot").await;
    assert_eq!(snap["tick"], 100);
    let state = s.get(&format!("/api/replays/{id}/state?tick=100")).await;
    assert_eq!(state.status, 200, "{}", state.body);
    assert_same_as_state(&snap, &state.body);
    // A seek always carries the belief of its tick: the roles the tracker held then.
    let belief = s
        .get(&format!("/api/replays/{id}/belief?tick=100"))
        .await
        .body;
    let roles = |b: &Value| -> Vec<(Value, Value, Value)> {
        b["roles"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| (r["id"].clone(), r["count"].clone(), r["tagged"].clone()))
            .collect()
    };
    assert_eq!(roles(&snap["belief"]), roles(&belief));
    // A later seek replaces one not shown yet: the last is always shown.
    for t in [10, 20, 30, 40, 50] {
        ws.send_json(&json!({"type": "seek", "tick": t}))
            .await
            .unwrap();
    }
    let shown: Vec<u64> = drain(&mut ws, Duration::from_millis(400))
        .await
        .iter()
        .filter(|v| v["type"] == "snapshot")
        .map(|v| v["tick"].as_u64().unwrap())
        .collect();
    assert_eq!(shown.last(), Some(&50), "{shown:?}");
    assert!(shown.len() <= 5, "{shown:?}");

    // Speed is echoed; play goes on from the tick sought, and stops at the end.
    ws.send_json(&json!({"type": "speed", "speed": 8}))
        .await
        .unwrap();
    let fast = status(&mut ws).await;
    assert_eq!(
        (fast["speed"].as_f64(), fast["playing"].as_bool()),
        (Some(8.0), Some(false))
    );
    ws.send_json(&json!({"type": "play"})).await.unwrap();
    assert_eq!(status(&mut ws).await["playing"], true);
    let mut seen = vec![50];
    let end = loop {
        let v = ws.json().await;
        match v["type"].as_str() {
            Some("snapshot") => seen.push(v["tick"].as_u64().unwrap()),
            Some("replay_status") => break v,
            _ => {}
        }
    };
    assert!(seen.windows(2).all(|w| w[0] < w[1]), "{seen:?}");
    assert_eq!(seen.last(), Some(&last));
    assert_eq!(end["playing"], false, "{end}");
    assert_eq!(end["tick"], last);
    assert!(drain(&mut ws, Duration::from_millis(300)).await.is_empty());

    // Bad messages get an error naming what is wrong; the socket stays.
    for (bad, names) in [
        ("not json".to_string(), "message"),
        (json!({"type": "rewind"}).to_string(), "type"),
        (json!({"type": "speed", "speed": 100}).to_string(), "speed"),
        (
            json!({"type": "seek", "tick": last + 1}).to_string(),
            "tick",
        ),
        (json!({"type": "seek"}).to_string(), "tick"),
    ] {
        ws.send_text(bad.clone()).await.unwrap();
        let e = ws.json().await;
        assert_eq!(e["type"], "error", "{bad}: {e}");
        let message = e["message"].as_str().unwrap();
        assert!(message.contains(names), "{bad}: {message}");
        assert_eq!(e["error"], e["message"]);
    }
    ws.send_json(&json!({"type": "seek", "tick": 5}))
        .await
        .unwrap();
    assert_eq!(ws.next_of("snapshot").await["tick"], 5);
    // Play at the end starts again.
    ws.send_json(&json!({"type": "seek", "tick": last}))
        .await
        .unwrap();
    assert_eq!(ws.next_of("snapshot").await["tick"], last);
    ws.send_json(&json!({"type": "play"})).await.unwrap();
    let again = ws.next_of("snapshot").await;
    assert!(again["tick"].as_u64().unwrap() < 20, "{again}");
}

#[tokio::test]
async fn as_a_player_the_replay_shows_only_what_it_saw() {
    let s = TestServer::start().await;
    // Robots that stand still, one in the corridor in front of the person, one far away.
    let id = finished_match(
        &s,
        json!({"planner": "idle", "robot_starts": [[7.0, 8.0, std::f64::consts::PI], [22.0, 1.5, 0.0]],
            "opponent_starts": [[3.0, 8.0]]}),
    )
    .await;
    let arena = common::shipped_arena("office");
    let mut ws = open(&s, &id, "?as=o0&speed=0.5").await.expect("opens");
    let first = ws.json().await;
    assert_eq!(first["view"], "o0", "{first}");
    assert_eq!(first["you"], "o0");
    assert_eq!(first["name"], "ada");
    assert_eq!(first["belief"], false);
    assert_eq!(first["speed"], 0.5);
    ws.send_json(&json!({"type": "pause"})).await.unwrap();
    status(&mut ws).await;
    let (mut hidden, mut shown) = (0, 0);
    for tick in (0..=first["ticks"].as_u64().unwrap()).step_by(15) {
        ws.send_json(&json!({"type": "seek", "tick": tick}))
            .await
            .unwrap();
        let snap = ws.next_of("snapshot").await;
        assert_eq!(snap["tick"], tick);
        // (Seeks past the rate would be coalesced; each is waited for, so none is.)
        let truth = s
            .get(&format!("/api/replays/{id}/state?tick={tick}"))
            .await
            .body;
        let me = &truth["opponents"][0];
        tokio::time::sleep(Duration::from_millis(100)).await;
        if me["tagged"] == true {
            // Tagged, the person watched as spectators do.
            assert_eq!(snap["view"], "spectator", "{snap}");
            continue;
        }
        assert_eq!(snap["view"], "player", "{snap}");
        assert_eq!(snap["you"], "o0");
        assert!(
            snap.get("belief").is_none(),
            "a player's view has no belief"
        );
        let at = |v: &Value| {
            Point2::new(
                v["x"].as_f64().unwrap() as f32,
                v["y"].as_f64().unwrap() as f32,
            )
        };
        assert_eq!(snap["opponents"][0]["name"], "ada");
        for r in truth["robots"].as_array().unwrap() {
            let sent = snap["robots"]
                .as_array()
                .unwrap()
                .iter()
                .find(|x| x["id"] == r["id"]);
            assert_eq!(
                sent.is_some(),
                arena.line_of_sight(at(me), at(r)),
                "{} at {tick}",
                r["id"]
            );
            if let Some(x) = sent {
                assert!(x.get("scan").is_none() && x.get("goal").is_none(), "{x}");
                shown += 1;
            } else {
                hidden += 1;
            }
        }
    }
    assert!(
        hidden > 0 && shown > 0,
        "robots shown {shown} times, hidden {hidden}"
    );
    // The belief can be switched on, as in the game (B): a paused replay shows it at once.
    ws.send_json(&json!({"type": "belief", "on": true}))
        .await
        .unwrap();
    let snap = ws.next_of("snapshot").await;
    assert!(snap.get("belief").is_some(), "{snap}");

    // The compact format as on the live socket: binary snapshots after the JSON first message.
    let mut compact = open(&s, &id, "?format=compact").await.expect("opens");
    assert_eq!(compact.json().await["format"], "compact");
    let binary = tokio::time::timeout(Duration::from_secs(10), async {
        loop {
            match compact.stream.next().await {
                Some(Ok(WsMessage::Binary(b))) => return b,
                Some(Ok(_)) => continue,
                other => panic!("{other:?}"),
            }
        }
    })
    .await
    .expect("a binary snapshot");
    assert_eq!(binary[0], 1, "a whole compact snapshot");
}

#[tokio::test]
async fn a_replay_socket_is_refused_before_the_upgrade() {
    let s = TestServer::start().await;
    match open(&s, "nope", "").await {
        Err(WsError::Http(r)) => assert_eq!(r.status(), 404),
        Err(e) => panic!("expected 404, got {e}"),
        Ok(_) => panic!("an unknown replay was let in"),
    }
    // The same JSON errors as the REST endpoints (a plain GET is refused as they are, before
    // it is found not to be an upgrade).
    assert_error(&s.get("/ws/replays/nope").await, 404, "no replay");
    let id = finished_match(&s, json!({})).await;
    let last = s.get(&format!("/api/replays/{id}")).await.body["ticks"]
        .as_u64()
        .unwrap();
    let get = |q: String| {
        let path = format!("/ws/replays/{id}{q}");
        let s = &s;
        async move { s.get(&path).await }
    };
    assert_error(&get("?speed=9".into()).await, 400, "speed");
    assert_error(&get("?speed=fast".into()).await, 400, "speed");
    assert_error(&get("?tick=x".into()).await, 400, "tick");
    assert_error(&get(format!("?tick={}", last + 1)).await, 404, "tick");
    assert_error(&get("?as=x0".into()).await, 400, "as");
    assert_error(&get("?as=r7".into()).await, 404, "as");
    assert_error(&get("?as=o7".into()).await, 404, "as");
    assert_error(&get("?format=xml".into()).await, 400, "format");
    assert_error(&get("?token=x".into()).await, 400, "token");
    assert_error(&get("?tick=3".into()).await, 400, "WebSocket");
    match open(&s, &id, "?speed=0.1").await {
        Err(WsError::Http(r)) => assert_eq!(r.status(), 400),
        other => panic!("speed 0.1 accepted: {:?}", other.is_ok()),
    }
    // A socket that is refused nothing still closes cleanly when the client leaves.
    let mut ws = open(&s, &id, &format!("?tick={last}"))
        .await
        .expect("opens");
    assert_eq!(ws.json().await["playing"], false);
    assert_eq!(ws.next_of("snapshot").await["tick"], last);
    ws.stream.close(None).await.unwrap();
    assert!(matches!(ws.next().await, Got::Closed { .. } | Got::Ended));

    // The server shutting down closes a replay socket, playing or not, as it does the live ones.
    let mut ws = open(&s, &id, "").await.expect("opens");
    assert_eq!(ws.json().await["type"], "replay");
    s.registry.begin_shutdown().await;
    let closed = loop {
        match ws.next().await {
            Got::Json(_) => continue,
            other => break other,
        }
    };
    assert!(
        matches!(&closed, Got::Closed { code: 1001, .. }),
        "{closed:?}"
    );
    tokio::time::timeout(Duration::from_secs(5), s.registry.connections_closed())
        .await
        .expect("every connection counted closed");
}
