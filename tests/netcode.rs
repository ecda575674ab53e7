//! Playing over a network: numbered inputs applied one per tick and acknowledged, what a
//! page needs to predict its own motion, and all of it through a proxy that adds a real
//! network's delay, jitter and loss (`common/netem.rs`).

mod common;
#[path = "common/netem.rs"]
mod netem;

use std::time::Duration;

use common::{TestServer, Ws, idle_human_match};
use lasertag::protocol::compact;
use netem::{Conditions, Netem};
use serde_json::json;

#[tokio::test]
async fn numbered_inputs_are_applied_one_per_tick_in_order_and_acknowledged() {
    let s = TestServer::start().await;
    let id = idle_human_match(&s).await;
    let (_, token) = s.join(&id, "frank").await;
    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    let welcome = ws.json().await;
    // What the client needs to predict its own motion.
    let k = &welcome["kinematics"];
    assert_eq!(k["dt"], 0.05);
    assert!(k["speed"].as_f64().unwrap() > 0.5 && k["radius"].as_f64().unwrap() > 0.1);
    assert_eq!(ws.next_of("snapshot").await["ack"], 0);
    // Three ticks' worth at once: forward, turn left, forward. None may be dropped for
    // arriving within one tick, and each is applied for exactly one tick.
    for (seq, forward, turn) in [(1, 1.0, 0.0), (2, 0.0, 1.0), (3, 1.0, 0.0)] {
        ws.send_json(&json!({"type": "input", "seq": seq, "forward": forward, "turn": turn}))
            .await
            .unwrap();
    }
    // A repeat of an applied or queued number is ignored.
    ws.send_json(&json!({"type": "input", "seq": 2, "forward": -1.0, "turn": 0.0}))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(100)).await;
    let start = s.get(&format!("/api/matches/{id}")).await.body["opponents"][0].clone();
    let speed = k["speed"].as_f64().unwrap();
    let turn = k["turn_rate"].as_f64().unwrap() * 0.05;
    let mut poses = vec![];
    for expected_ack in 1..=4u64 {
        let truth = s.step(&id, 1).await;
        let snap = loop {
            let v = ws.next_of("snapshot").await;
            if v["tick"] == truth["tick"] {
                break v;
            }
        };
        // The fourth tick repeats the last input (keys still down).
        assert_eq!(snap["ack"], expected_ack.min(3), "{snap}");
        let o = &truth["opponents"][0];
        poses.push([
            o["x"].as_f64().unwrap(),
            o["y"].as_f64().unwrap(),
            o["theta"].as_f64().unwrap(),
        ]);
    }
    let x0 = start["x"].as_f64().unwrap();
    let t0 = start["theta"].as_f64().unwrap();
    let step = speed * 0.05;
    assert!(
        (poses[0][0] - x0).abs() > 0.5 * step
            || (poses[0][1] - start["y"].as_f64().unwrap()).abs() > 0.5 * step,
        "tick 1 moved: {poses:?}"
    );
    assert!(
        (poses[1][2] - t0).abs() > 0.9 * turn,
        "tick 2 turned: {poses:?}"
    );
    let moved = |a: [f64; 3], b: [f64; 3]| ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt();
    assert!(
        moved(poses[0], poses[1]) < 1e-3,
        "tick 2 only turned: {poses:?}"
    );
    assert!(
        moved(poses[1], poses[2]) > 0.5 * step,
        "tick 3 moved: {poses:?}"
    );
    assert!(
        moved(poses[2], poses[3]) > 0.5 * step,
        "tick 4 held the keys: {poses:?}"
    );
}

#[tokio::test]
async fn over_a_slow_lossy_network_every_input_is_applied_in_order() {
    let s = TestServer::start().await;
    let net = Netem::start(
        s.addr,
        Conditions {
            rtt: Duration::from_millis(150),
            jitter: Duration::from_millis(20),
            loss: 0.02,
            ..Conditions::rtt_ms(150)
        },
    )
    .await;
    let id = s
        .create_match(
            json!({"map": "office", "opponent_control": "human", "planner": "idle",
            "spectator_delay_s": 0}),
        )
        .await;
    let (_, token) = s.join(&id, "gina").await;
    let url = format!("ws://{}/ws/matches/{id}?token={token}", net.addr);
    let (stream, _) = tokio_tungstenite::connect_async(url).await.unwrap();
    let mut ws = Ws { stream };
    assert_eq!(ws.json().await["type"], "welcome");
    // The proxy really delays: a ping takes at least its round trip.
    let sent = std::time::Instant::now();
    ws.send_json(&json!({"type": "ping", "t": 1}))
        .await
        .unwrap();
    ws.next_of("pong").await;
    let rtt = sent.elapsed();
    assert!(rtt >= Duration::from_millis(130), "round trip {rtt:?}");
    // Two seconds of inputs at 20 Hz, as a page sends them: each is applied, in order.
    let mut tick = tokio::time::interval(Duration::from_millis(50));
    for seq in 1..=40u64 {
        tick.tick().await;
        let turn = if seq % 10 < 5 { 1.0 } else { -1.0 };
        ws.send_json(&json!({"type": "input", "seq": seq, "forward": 1.0, "turn": turn}))
            .await
            .unwrap();
    }
    let mut last = 0;
    while last < 40 {
        let snap = ws.next_of("snapshot").await;
        let ack = snap["ack"].as_u64().unwrap();
        assert!(ack >= last, "ack went back from {last} to {ack}");
        last = ack;
    }
    let events = s.events(&id).await;
    assert!(
        events.iter().all(|e| e["kind"] != "player_left"),
        "{events:?}"
    );
}

/// The next binary message (a compact snapshot), skipping text ones.
async fn next_compact(ws: &mut Ws) -> Vec<u8> {
    use futures_util::StreamExt;
    loop {
        let msg = tokio::time::timeout(Duration::from_secs(10), ws.stream.next())
            .await
            .expect("a message within 10 s")
            .expect("the connection is open")
            .expect("a message");
        if let common::WsMessage::Binary(b) = msg {
            return b.to_vec();
        }
    }
}

#[tokio::test]
async fn compact_snapshots_are_small_and_say_what_the_json_says() {
    let s = TestServer::start().await;
    let id = s
        .create_match(
            json!({"map": "office", "robots": 2, "opponent_control": "human",
            "clock": "manual", "spectator_delay_s": 0}),
        )
        .await;
    let (_, token) = s.join(&id, "hana").await;
    let connect = |q: String| {
        let url = format!("ws://{}/ws/matches/{id}?format=compact{q}", s.addr);
        async move {
            Ws {
                stream: tokio_tungstenite::connect_async(url).await.unwrap().0,
            }
        }
    };
    let mut player = connect(format!("&token={token}")).await;
    let mut spectator = connect(String::new()).await;
    let welcome = player.json().await;
    assert_eq!(
        (welcome["protocol"].as_u64(), welcome["format"].as_str()),
        (Some(3), Some("compact"))
    );
    assert_eq!(spectator.json().await["format"], "compact");
    let mut biggest = (0, 0);
    let mut with_belief = 0;
    // The last whole snapshot each holds, and the bytes of the deltas the player got.
    let mut held: [Vec<u8>; 2] = [Vec::new(), Vec::new()];
    let (mut deltas, mut delta_bytes, mut whole_bytes) = (0, 0, 0);
    for _ in 0..40 {
        let truth = s.step(&id, 1).await;
        let tick = truth["tick"].as_u64().unwrap() as u32;
        for (ws, k) in [(&mut player, 0), (&mut spectator, 1)] {
            let b = loop {
                let m = next_compact(ws).await;
                let b = if m[0] == compact::KIND_DELTA {
                    if k == 0 {
                        deltas += 1;
                        delta_bytes += m.len();
                    }
                    compact::apply_delta(&held[k], &m).expect("a delta against the last one")
                } else {
                    m
                };
                held[k] = b.clone();
                if u32::from_le_bytes([b[2], b[3], b[4], b[5]]) >= tick {
                    break b;
                }
            };
            // Kind 1, the tick, and the view: the player's (you = slot 0 + 1) or everything.
            assert_eq!(b[0], compact::KIND_WHOLE);
            assert_eq!(u32::from_le_bytes([b[2], b[3], b[4], b[5]]), tick);
            assert_eq!(b[1] & 1, k as u8, "spectator flag");
            assert_eq!(b[12], if k == 0 { 1 } else { 0 }, "you");
            if b[1] & 2 != 0 {
                with_belief += 1;
            }
            if k == 0 {
                whole_bytes += b.len();
            }
            biggest.0 = biggest.0.max(if k == 0 { b.len() } else { 0 });
            biggest.1 = biggest.1.max(if k == 1 { b.len() } else { 0 });
        }
    }
    // Between two ticks little of a player's snapshot changes: most come as deltas, at
    // under half the bytes of the whole.
    assert!(deltas >= 20, "{deltas} of 40 player snapshots were deltas");
    assert!(
        delta_bytes * 2 < whole_bytes * deltas / 40,
        "deltas {delta_bytes} B for {deltas}, whole {whole_bytes} B for 40"
    );
    // A player's snapshot is tens of bytes (about 1 KiB/s at 20 Hz); a spectator's, with
    // scans, clouds and the belief, a few KB at most.
    assert!(
        biggest.0 < 100,
        "player snapshots up to {} bytes",
        biggest.0
    );
    assert!(
        biggest.1 < 4000,
        "spectator snapshots up to {} bytes",
        biggest.1
    );
    assert!(
        with_belief >= 3,
        "{with_belief} snapshots carried the belief"
    );
    let bad = format!("ws://{}/ws/matches/{id}?format=xml", s.addr);
    match tokio_tungstenite::connect_async(bad).await {
        Err(common::WsError::Http(r)) => assert_eq!(r.status(), 400),
        other => panic!("format=xml accepted: {:?}", other.is_ok()),
    }
}
