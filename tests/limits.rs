//! Every limit of the server, crossed over real HTTP and WebSocket with a
//! tiny setting: each refusal has the right status or close code and a reason, and the
//! server is healthy afterwards (health answers, a real-time match keeps ticking, a client
//! within the limits is still served).

mod common;

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::Duration;

use common::{Got, TestServer, Ws, WsError, assert_error, test_config};
use lasertag::config::Config;
use serde_json::{Value, json};

/// A real-time bot match to check the server's health against (idle robots: it never ends
/// before its time limit).
async fn live_match(s: &TestServer) -> String {
    s.create_match(json!({"map": "office", "planner": "idle", "opponents": 1}))
        .await
}

/// Health answers and the live match has moved on since `since`.
async fn assert_healthy(s: &TestServer, live: &str, since: u64) -> u64 {
    let r = s.get("/api/health").await;
    assert_eq!(r.status, 200, "{}", r.body);
    let mut tick = 0;
    for _ in 0..50 {
        let r = s.get(&format!("/api/matches/{live}")).await;
        assert_eq!(r.status, 200, "{}", r.body);
        tick = r.body["tick"].as_u64().unwrap();
        if tick > since {
            return tick;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    panic!("the live match is stuck at tick {tick}");
}

async fn tick_of(s: &TestServer, id: &str) -> u64 {
    s.get(&format!("/api/matches/{id}")).await.body["tick"]
        .as_u64()
        .unwrap()
}

/// The handshake's HTTP refusal: (status, body).
fn refusal(e: WsError) -> (u16, String) {
    match e {
        WsError::Http(resp) => {
            let body = resp
                .body()
                .as_ref()
                .map(|b| String::from_utf8_lossy(b).to_string())
                .unwrap_or_default();
            (resp.status().as_u16(), body)
        }
        other => panic!("expected an HTTP refusal, got {other}"),
    }
}

/// A WebSocket to `path` from the local address `from` (another loopback address).
async fn ws_from(s: &TestServer, from: Ipv4Addr, path: &str) -> Result<Ws, WsError> {
    let socket = tokio::net::TcpSocket::new_v4().unwrap();
    socket
        .bind(SocketAddr::new(IpAddr::V4(from), 0))
        .expect("bind a loopback address");
    let stream = socket.connect(s.addr).await.unwrap();
    let url = format!("ws://{}{path}", s.addr);
    let (stream, _) =
        tokio_tungstenite::client_async(url, tokio_tungstenite::MaybeTlsStream::Plain(stream))
            .await?;
    Ok(Ws { stream })
}

#[tokio::test]
async fn matches_past_the_server_limit_get_503_and_room_comes_back_when_one_goes() {
    let s = TestServer::start_with(Config {
        max_matches: 2,
        ..test_config()
    })
    .await;
    let live = live_match(&s).await;
    let other = s
        .create_match(json!({"map": "office", "clock": "manual"}))
        .await;
    let r = s
        .post("/api/matches", &json!({"map": "office", "clock": "manual"}))
        .await;
    assert_error(&r, 503, "2 matches");
    assert_eq!(
        s.get("/api/matches").await.body.as_array().unwrap().len(),
        2
    );
    let t = assert_healthy(&s, &live, 0).await;
    // Deleting one makes room.
    assert_eq!(s.delete(&format!("/api/matches/{other}")).await.status, 204);
    s.create_match(json!({"map": "office", "clock": "manual"}))
        .await;
    assert_healthy(&s, &live, t).await;
}

#[tokio::test]
async fn matches_with_too_many_agents_or_particles_are_refused_with_400() {
    let s = TestServer::start_with(Config {
        max_agents_per_match: 4,
        max_particles_per_match: 3000,
        ..test_config()
    })
    .await;
    let live = live_match(&s).await;
    let r = s
        .post(
            "/api/matches",
            &json!({"map": "office", "robots": 2, "opponents": 3, "clock": "manual"}),
        )
        .await;
    assert_error(&r, 400, "5 agents is over this server's limit of 4");
    let r = s
        .post(
            "/api/matches",
            &json!({"map": "office", "robots": 1, "opponents": 2, "clock": "manual",
                    "tracker": {"particles_per_role": 2000}}),
        )
        .await;
    assert_error(&r, 400, "tracker.particles_per_role");
    assert_error(
        &r,
        400,
        "4000 particles is over this server's limit of 3000",
    );
    // Within both limits: created.
    s.create_match(
        json!({"map": "office", "robots": 2, "opponents": 2, "clock": "manual",
                          "tracker": {"particles_per_role": 1500}}),
    )
    .await;
    assert_eq!(
        s.get("/api/matches").await.body.as_array().unwrap().len(),
        2
    );
    assert_healthy(&s, &live, 0).await;
}

#[tokio::test]
async fn players_past_the_match_limit_are_refused_with_409() {
    let s = TestServer::start_with(Config {
        max_players_per_match: 1,
        ..test_config()
    })
    .await;
    let live = live_match(&s).await;
    let id = s
        .create_match(
            json!({"map": "office", "opponents": 2, "opponent_control": "human",
                             "clock": "manual"}),
        )
        .await;
    s.join(&id, "alice").await;
    let r = s
        .post(
            &format!("/api/matches/{id}/players"),
            &json!({"name": "bob"}),
        )
        .await;
    assert_error(&r, 409, "players: match");
    assert_error(&r, 409, "at this server's limit of 1 per match");
    // The refused join changed nothing: one player, one free slot still listed.
    let summary = s.get("/api/matches").await.body.as_array().unwrap()[1].clone();
    assert_eq!(summary["players"], 1, "{summary}");
    assert_healthy(&s, &live, 0).await;
}

#[tokio::test]
async fn spectators_past_the_match_limit_are_refused_before_the_upgrade() {
    let s = TestServer::start_with(Config {
        max_spectators_per_match: 2,
        ..test_config()
    })
    .await;
    let live = live_match(&s).await;
    let mut a = s.ws(&live, None).await.unwrap();
    let _b = s.ws(&live, None).await.unwrap();
    let (status, body) = refusal(s.ws(&live, None).await.err().expect("refused"));
    assert_eq!(status, 503, "{body}");
    assert!(body.contains("spectators: this match"), "{body}");
    assert!(body.contains("limit of 2 spectators"), "{body}");
    // The two still get snapshots; when one leaves, a new spectator is let in.
    a.next_of("snapshot").await;
    drop(a);
    let mut c = None;
    for _ in 0..50 {
        tokio::time::sleep(Duration::from_millis(50)).await;
        if let Ok(ws) = s.ws(&live, None).await {
            c = Some(ws);
            break;
        }
    }
    c.expect("a place freed by a spectator who left")
        .next_of("snapshot")
        .await;
    assert_healthy(&s, &live, 0).await;
}

#[tokio::test]
async fn websockets_past_the_address_limit_get_429_and_other_addresses_are_not_affected() {
    let s = TestServer::start_with(Config {
        max_connections_per_address: 2,
        ..test_config()
    })
    .await;
    let live = live_match(&s).await;
    let other = live_match(&s).await;
    let _a = s.ws(&live, None).await.unwrap();
    let _b = s.ws(&other, None).await.unwrap();
    // The limit is per address, across matches.
    let (status, body) = refusal(s.ws(&live, None).await.err().expect("refused"));
    assert_eq!(status, 429, "{body}");
    assert!(
        body.contains("too many connections from 127.0.0.1"),
        "{body}"
    );
    // Another address still connects.
    let path = format!("/ws/matches/{live}");
    let mut elsewhere = ws_from(&s, Ipv4Addr::new(127, 0, 0, 2), &path)
        .await
        .unwrap();
    elsewhere.next_of("snapshot").await;
    assert_healthy(&s, &live, 0).await;
}

#[tokio::test]
async fn requests_over_the_address_rate_get_429_with_retry_after() {
    let s = TestServer::start_with(Config {
        requests_per_s: 2.0,
        request_burst: 5.0,
        ..Config::default()
    })
    .await;
    let mut refused = None;
    for _ in 0..20 {
        let r = s.client.get(s.url("/api/health")).send().await.unwrap();
        if r.status() == 429 {
            refused = Some(r);
            break;
        }
        assert_eq!(r.status(), 200);
    }
    let r = refused.expect("a request over the rate is refused");
    let retry: u64 = r
        .headers()
        .get("retry-after")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse().ok())
        .expect("a Retry-After in seconds");
    assert!((1..=2).contains(&retry), "Retry-After {retry}");
    let body: Value = r.json().await.unwrap();
    let msg = body["error"].as_str().unwrap();
    assert!(msg.contains("too many requests from 127.0.0.1"), "{msg}");
    // Another address is served at once...
    let other = reqwest::Client::builder()
        .local_address(IpAddr::V4(Ipv4Addr::new(127, 0, 0, 3)))
        .build()
        .unwrap();
    let r = other.get(s.url("/api/health")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    // ...and this one again once it has waited.
    tokio::time::sleep(Duration::from_secs(retry)).await;
    assert_eq!(s.get("/api/health").await.status, 200);
}

#[tokio::test]
async fn bodies_over_the_limit_get_413() {
    let s = TestServer::start_with(Config {
        max_body_bytes: 1024,
        ..test_config()
    })
    .await;
    let live = live_match(&s).await;
    let mut big = common::duel_map();
    big["name"] = json!("x".repeat(2000));
    let r = s.post("/api/maps", &big).await;
    assert_error(&r, 413, "larger than the limit of 1024 bytes");
    assert_healthy(&s, &live, 0).await;
}

#[tokio::test]
async fn websocket_messages_over_the_rate_get_errors_then_a_1008_close() {
    let s = TestServer::start_with(Config {
        messages_per_s: 2.0,
        message_burst: 3.0,
        ..test_config()
    })
    .await;
    let live = live_match(&s).await;
    let id = s
        .create_match(json!({"map": "office", "opponent_control": "human", "clock": "manual"}))
        .await;
    let (_, token) = s.join(&id, "speedy").await;
    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    let welcome = ws.json().await;
    assert_eq!(welcome["limits"]["messages_per_s"], 2.0);
    for t in 0..40 {
        if ws
            .send_json(&json!({"type": "ping", "t": t}))
            .await
            .is_err()
        {
            break;
        }
    }
    let (mut pongs, mut errors) = (0, 0);
    let closed = loop {
        match ws.next().await {
            Got::Json(v) if v["type"] == "pong" => pongs += 1,
            Got::Json(v) if v["type"] == "error" => {
                assert!(v["error"].as_str().unwrap().contains("rate limit"), "{v}");
                errors += 1;
            }
            Got::Json(_) => {}
            Got::Closed { code, reason } => break (code, reason),
            Got::Ended => panic!("dropped without a close frame"),
        }
    };
    assert_eq!(closed.0, 1008, "{closed:?}");
    assert!(closed.1.contains("rate limit"), "{closed:?}");
    assert!((3..=5).contains(&pongs), "{pongs} pongs");
    assert!(errors >= 5, "{errors} errors");
    // The player may come back with the same token, and the server is well.
    let mut again = s.ws(&id, Some(&token)).await.unwrap();
    again.next_of("snapshot").await;
    assert_healthy(&s, &live, 0).await;
}

#[tokio::test]
async fn websocket_messages_over_the_size_limit_get_an_error_and_far_over_it_a_1009_close() {
    let s = TestServer::start_with(Config {
        max_message_bytes: 256,
        ..test_config()
    })
    .await;
    let live = live_match(&s).await;
    let mut ws = s.ws(&live, None).await.unwrap();
    assert_eq!(ws.json().await["limits"]["max_message_bytes"], 256);
    ws.send_text(format!(
        "{{\"type\": \"ping\", \"t\": 1, \"pad\": \"{}\"}}",
        "x".repeat(300)
    ))
    .await
    .unwrap();
    let e = ws.next_of("error").await;
    assert!(
        e["error"]
            .as_str()
            .unwrap()
            .contains("over the 256-byte limit"),
        "{e}"
    );
    // Still connected: a good message is answered.
    ws.send_json(&json!({"type": "ping", "t": 2}))
        .await
        .unwrap();
    assert_eq!(ws.next_of("pong").await["t"], 2.0);
    // Over the hard cap (16 × 256 B, at least 64 KiB): closed at once.
    let _ = ws.send_text("x".repeat(70_000)).await;
    loop {
        match ws.next().await {
            Got::Json(_) => continue,
            Got::Closed { code, reason } => {
                assert_eq!(code, 1009, "{reason}");
                assert!(reason.contains("65536 bytes"), "{reason}");
                break;
            }
            Got::Ended => break, // cut before the close frame got through
        }
    }
    assert_healthy(&s, &live, 0).await;
}

#[tokio::test]
async fn finished_matches_are_removed_after_the_grace_period() {
    let s = TestServer::start_with(Config {
        finished_grace: Duration::from_millis(500),
        ..test_config()
    })
    .await;
    let live = live_match(&s).await;
    let id = s
        .create_match(json!({"map": "office", "clock": "manual", "time_limit_s": 1}))
        .await;
    let mut ws = s.ws(&id, None).await.unwrap();
    let state = s.step(&id, 100).await;
    assert_eq!(state["status"], "finished");
    // Readable during the grace...
    assert_eq!(s.get(&format!("/api/matches/{id}")).await.status, 200);
    assert_eq!(ws.next_of("finished").await["reason"], "time_limit");
    // ...then gone, and its viewer closed with a reason.
    let closed = loop {
        match ws.next().await {
            Got::Json(_) => continue,
            other => break other,
        }
    };
    assert!(
        matches!(&closed, Got::Closed { code: 1000, reason } if reason.contains("ended")),
        "{closed:?}"
    );
    assert_error(&s.get(&format!("/api/matches/{id}")).await, 404, "no match");
    let list = s.get("/api/matches").await.body;
    assert_eq!(list.as_array().unwrap().len(), 1, "{list}");
    let metrics = s.client.get(s.url("/metrics")).send().await.unwrap();
    let text = metrics.text().await.unwrap();
    assert!(
        text.contains("lasertag_matches_removed_total{reason=\"finished\"} 1"),
        "{text}"
    );
    // The running one is untouched.
    let t = tick_of(&s, &live).await;
    assert_healthy(&s, &live, t).await;
}

#[tokio::test]
async fn abandoned_human_matches_end_and_go_but_bot_and_watched_matches_run_on() {
    let s = TestServer::start_with(Config {
        abandoned_after: Duration::from_millis(600),
        finished_grace: Duration::from_secs(600),
        ..test_config()
    })
    .await;
    // Nobody ever comes to this one.
    let empty = s
        .create_match(json!({"map": "office", "opponent_control": "human"}))
        .await;
    // This one has a spectator the whole time (shown live, so that snapshots keep coming).
    let watched = s
        .create_match(json!({"map": "office", "opponent_control": "human",
            "spectator_delay_s": 0}))
        .await;
    let mut watcher = s.ws(&watched, None).await.unwrap();
    // Bots and API opponents with nobody watching: never abandoned.
    let bots = s
        .create_match(json!({"map": "office", "planner": "idle"}))
        .await;
    let api = s
        .create_match(json!({"map": "office", "opponent_control": "api", "planner": "idle"}))
        .await;
    let mut gone = false;
    for _ in 0..60 {
        tokio::time::sleep(Duration::from_millis(100)).await;
        // Only the watcher keeps `watched` alive: no request touches `empty`.
        watcher.next_of("snapshot").await;
        if s.registry.get(&empty).is_none() {
            gone = true;
            break;
        }
    }
    assert!(gone, "the abandoned match is still there");
    tokio::time::sleep(Duration::from_millis(800)).await;
    for id in [&watched, &bots, &api] {
        let r = s.get(&format!("/api/matches/{id}")).await;
        assert_eq!(r.status, 200, "{id}: {}", r.body);
        assert_eq!(r.body["status"], "running", "{id}");
    }
    assert_error(
        &s.get(&format!("/api/matches/{empty}")).await,
        404,
        "no match",
    );
}
