//! WebTransport over the real server (UDP on the HTTP port, its own certificate pinned by the
//! hash `GET /api/transport` publishes): a spectator gets `welcome` on the reliable stream and
//! snapshots as datagrams, deltas against the ones it acknowledged; a player's input datagrams, each repeating the ones before it,
//! move its body; bad sessions are refused as a WebSocket's upgrade is, and bad messages
//! struck and closed with the WebSocket's codes.

mod common;
#[path = "common/process.rs"]
mod process;
#[path = "common/wt.rs"]
#[allow(dead_code)]
mod wt;

use std::time::Duration;

use common::TestServer;
use lasertag::config::Config;
use serde_json::{Value, json};
use wt::{BINARY, TEXT, WtClient};

async fn server() -> TestServer {
    TestServer::with_webtransport(common::test_config()).await
}

/// The published URL and hash, and the URL of `path` there.
async fn at(s: &TestServer, path: &str) -> (String, wtransport::tls::Sha256Digest) {
    let r = s.get("/api/transport").await;
    assert_eq!(r.status, 200, "{}", r.body);
    let (url, hash) = wt::published(&r.body);
    (format!("{url}{path}"), hash)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_transport_is_published_with_the_servers_port_and_hash() {
    let s = server().await;
    let r = s.get("/api/transport").await;
    let url = r.body["webtransport"]["url"].as_str().unwrap();
    assert_eq!(url, format!("https://127.0.0.1:{}", s.addr.port()));
    let hash = &r.body["webtransport"]["certificate_hashes"][0];
    assert_eq!(hash["algorithm"], "sha-256");
    assert_eq!(hash["value"].as_str().unwrap().len(), 64);
    // A server without it says so.
    let plain = TestServer::start().await;
    assert_eq!(
        plain.get("/api/transport").await.body,
        json!({"webtransport": null})
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_spectator_gets_welcome_on_the_stream_and_snapshots_as_datagrams() {
    let s = server().await;
    // Four robots: their scans pass a datagram's 1,024 bytes (three robots' fit, as does a
    // belief), so those snapshots go on the stream.
    let id = s
        .create_match(json!({"map": "office", "opponent_control": "bot", "robots": 4}))
        .await;
    let (url, hash) = at(&s, &format!("/ws/matches/{id}?format=compact")).await;
    let mut c = WtClient::connect(&url, &hash).await.expect("connects");
    let welcome = c.json().await;
    assert_eq!(welcome["type"], "welcome", "{welcome}");
    assert_eq!(welcome["role"], "spectator");
    assert_eq!(welcome["format"], "compact");
    let mut ticks = Vec::new();
    while ticks.len() < 40 {
        let (kind, payload) = c.datagram().await;
        assert_eq!(kind, BINARY);
        // Each stands on its own to a client that acknowledges none: a whole compact
        // snapshot, or the motion part of one (kind 3) whose whole comes on the stream.
        assert!(
            matches!(payload[0], 1 | 3),
            "a whole snapshot: {}",
            payload[0]
        );
        ticks.push(lasertag::protocol::compact::tick_of(&payload).expect("a tick"));
        assert!(payload.len() < 1024);
    }
    // Every tick's motion as a datagram, those with scans or a belief too large for one
    // included (they also come whole on the stream).
    assert!(ticks.windows(2).all(|w| w[1] == w[0] + 1), "{ticks:?}");
    let streamed = loop {
        let (kind, payload) = c.frame().await.expect("the stream");
        if kind == BINARY {
            break payload;
        }
    };
    assert!(
        streamed.len() >= 1023,
        "only what a datagram cannot hold is streamed"
    );
    // It counts as its address's spectator, as a WebSocket does.
    let listed = s.get("/api/matches").await.body;
    assert_eq!(listed[0]["spectators"], 1, "{listed}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_that_acknowledges_gets_deltas_against_what_it_holds() {
    use lasertag::protocol::compact;
    use std::collections::HashMap;
    let s = server().await;
    let id = s
        .create_match(json!({"map": "office", "opponent_control": "bot"}))
        .await;
    let (url, hash) = at(&s, &format!("/ws/matches/{id}?format=compact")).await;
    // Two spectators of one match are sent the same snapshot each tick: one acknowledges
    // and gets deltas, the other none and gets wholes to check them against.
    let (mut acking, conn) = WtClient::connect(&url, &hash)
        .await
        .expect("connects")
        .snapshots();
    let (mut plain, _plain_conn) = WtClient::connect(&url, &hash)
        .await
        .expect("connects")
        .snapshots();
    let mut held = wt::Held::default();
    let (mut decoded, mut deltas, mut delta_bytes, mut whole_bytes) =
        (HashMap::new(), 0, 0usize, 0usize);
    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    while deltas < 30 {
        let a = tokio::time::timeout_at(deadline, acking.recv())
            .await
            .expect("30 deltas within 20 s")
            .expect("the session is open");
        let (kind, len) = (a.bytes[0], a.bytes.len());
        // A delta only against a tick acknowledged (held), and it applies.
        let Some(whole) = held.take(a.bytes).expect("a snapshot the client can read") else {
            continue;
        };
        if kind == compact::KIND_DELTA {
            deltas += 1;
            delta_bytes += len;
        } else {
            whole_bytes += len;
        }
        decoded.insert(compact::tick_of(&whole).unwrap(), whole);
        conn.send_datagram(held.ack())
            .expect("an acknowledgement goes");
    }
    // What the deltas stand for is, byte for byte, what the other spectator got whole (on
    // the ticks whose snapshots carry the same parts).
    let mut compared = 0;
    let last = *decoded.keys().max().unwrap();
    while let Ok(Some(a)) = tokio::time::timeout(Duration::from_secs(5), plain.recv()).await {
        let tick = compact::tick_of(&a.bytes).unwrap();
        if tick > last {
            break;
        }
        if a.bytes[0] != compact::KIND_WHOLE {
            continue;
        }
        // The same parts (scans, belief: each spectator on its own schedule).
        if let Some(d) = decoded.get(&tick).filter(|d| d[1] == a.bytes[1]) {
            assert_eq!(d, &a.bytes, "tick {:?}", compact::tick_of(&a.bytes));
            compared += 1;
        }
    }
    assert!(compared >= 10, "compared {compared} ticks");
    let mean = |bytes: usize, n: usize| bytes as f64 / n.max(1) as f64;
    assert!(
        mean(delta_bytes, deltas) < mean(whole_bytes, decoded.len() - deltas),
        "deltas average {} bytes, wholes {}",
        mean(delta_bytes, deltas),
        mean(whole_bytes, decoded.len() - deltas)
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn past_the_servers_sessions_a_new_one_is_refused_at_once() {
    let s = TestServer::with_webtransport(Config {
        max_webtransport_sessions: 1,
        ..common::test_config()
    })
    .await;
    let id = s
        .create_match(json!({"map": "office", "opponent_control": "bot"}))
        .await;
    let (url, hash) = at(&s, &format!("/ws/matches/{id}?format=compact")).await;
    let mut first = WtClient::connect(&url, &hash).await.expect("the first");
    assert_eq!(first.json().await["type"], "welcome");
    let started = std::time::Instant::now();
    let second = WtClient::connect(&url, &hash).await;
    assert!(second.is_err(), "a second session past the cap");
    // Refused at its first packet, not left to time out (a page then takes its WebSocket).
    assert!(started.elapsed() < Duration::from_secs(5));
    let text = s
        .client
        .get(s.url("/metrics"))
        .send()
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(
        text.contains("reason=\"webtransport_full\"} 1"),
        "{}",
        &text[..text.len().min(400)]
    );
    // The first one goes on.
    let (kind, _) = first.datagram().await;
    assert_eq!(kind, BINARY);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_player_takes_a_spectators_session_when_all_are_held() {
    let s = TestServer::with_webtransport(Config {
        max_webtransport_sessions: 1,
        ..common::test_config()
    })
    .await;
    let id = s
        .create_match(
            json!({"map": "office", "opponents": 2, "opponent_control": "human", "planner": "idle"}),
        )
        .await;
    let (spectate, hash) = at(&s, &format!("/ws/matches/{id}?format=compact")).await;
    let mut spectator = WtClient::connect(&spectate, &hash)
        .await
        .expect("a spectator");
    assert_eq!(spectator.json().await["type"], "welcome");
    // A second spectator finds every session held.
    assert!(WtClient::connect(&spectate, &hash).await.is_err());
    // A player does not: the spectator is moved off, told to come back (1012), and its page
    // then takes the WebSocket.
    let (_, token) = s.join(&id, "late").await;
    let (play, _) = at(
        &s,
        &format!("/ws/matches/{id}?token={token}&format=compact"),
    )
    .await;
    let mut player = WtClient::connect(&play, &hash).await.expect("the player");
    let welcome = player.json().await;
    assert_eq!(welcome["role"], "player", "{welcome}");
    let close = spectator.next_of("close").await;
    assert_eq!(close["code"], 1012, "{close}");
    assert!(
        close["reason"].as_str().unwrap().contains("WebSocket"),
        "{close}"
    );
    // Players hold every session: the next player is refused, and plays on its WebSocket.
    let (_, token) = s.join(&id, "later").await;
    let (second, _) = at(
        &s,
        &format!("/ws/matches/{id}?token={token}&format=compact"),
    )
    .await;
    assert!(WtClient::connect(&second, &hash).await.is_err());
    let (kind, _) = player.datagram().await;
    assert_eq!(kind, BINARY, "the player goes on over datagrams");
}

/// Where opponent `oid` is in the truth.
async fn position(s: &TestServer, id: &str, oid: &str) -> (f64, f64) {
    let state = s.get(&format!("/api/matches/{id}")).await.body;
    let o = state["opponents"]
        .as_array()
        .unwrap()
        .iter()
        .find(|o| o["id"] == oid)
        .cloned()
        .unwrap_or(Value::Null);
    (o["x"].as_f64().unwrap(), o["y"].as_f64().unwrap())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_players_input_datagrams_move_it_and_repeats_are_harmless() {
    let s = server().await;
    let id = s
        .create_match(json!({"map": "office", "opponent_control": "human", "planner": "idle"}))
        .await;
    let (oid, token) = s.join(&id, "udp").await;
    let (url, hash) = at(
        &s,
        &format!("/ws/matches/{id}?token={token}&format=compact"),
    )
    .await;
    let mut c = WtClient::connect(&url, &hash).await.expect("connects");
    let welcome = c.json().await;
    assert_eq!(welcome["role"], "player", "{welcome}");
    let start = position(&s, &id, &oid).await;
    // Forward, each datagram with the two inputs before it.
    let input =
        |seq: u64| json!({"type": "input", "forward": 1.0, "turn": 0.0, "tag": false, "seq": seq});
    for seq in 1..=30u64 {
        let batch: Vec<Value> = (seq.saturating_sub(2).max(1)..=seq).map(input).collect();
        c.send_datagram(TEXT, json!(batch).to_string().as_bytes());
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let end = position(&s, &id, &oid).await;
    let moved = ((end.0 - start.0).powi(2) + (end.1 - start.1).powi(2)).sqrt();
    assert!(moved > 0.5, "moved {moved} m");
    // Each input once: 30 ticks of walking at most (with repeats applied again it would be
    // more), at the opponent's speed (1.4 m/s).
    assert!(moved <= 30.0 * 0.05 * 1.4 + 0.05, "moved {moved} m");
    // The snapshots it gets are its own view, as datagrams.
    let (kind, _) = c.datagram().await;
    assert_eq!(kind, BINARY);
    // No error came for any of it.
    c.send_frame(TEXT, br#"{"type":"ping","t":1}"#, None).await;
    let pong = c.next_of("pong").await;
    assert_eq!(pong["t"], 1.0, "{pong}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_sessions_are_refused_as_websockets_are() {
    let s = TestServer::with_webtransport(Config {
        max_connections_per_address: 2,
        ..common::test_config()
    })
    .await;
    let id = s
        .create_match(json!({"map": "office", "opponent_control": "human"}))
        .await;
    let refused = |r: Result<WtClient, wtransport::error::ConnectingError>| match r {
        Err(wtransport::error::ConnectingError::SessionRejected) => {}
        Err(e) => panic!("refused otherwise: {e}"),
        Ok(_) => panic!("admitted"),
    };
    let (url, hash) = at(&s, "/ws/matches/nope").await;
    refused(WtClient::connect(&url, &hash).await);
    let (url, hash) = at(&s, &format!("/ws/matches/{id}?token=forged")).await;
    refused(WtClient::connect(&url, &hash).await);
    let (url, hash) = at(&s, &format!("/ws/matches/{id}?colour=red")).await;
    refused(WtClient::connect(&url, &hash).await);
    let (url, hash) = at(&s, "/elsewhere").await;
    refused(WtClient::connect(&url, &hash).await);
    // The address's sockets: a WebSocket and a session, then no third of either kind.
    let _ws = s.ws(&id, None).await.expect("a WebSocket");
    let (url, hash) = at(&s, &format!("/ws/matches/{id}")).await;
    let mut first = WtClient::connect(&url, &hash).await.expect("a session");
    assert_eq!(first.json().await["type"], "welcome");
    refused(WtClient::connect(&url, &hash).await);
    assert!(s.ws(&id, None).await.is_err(), "a third socket");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_messages_are_struck_then_closed_with_the_websockets_codes() {
    let s = server().await;
    let id = s
        .create_match(json!({"map": "office", "opponent_control": "human"}))
        .await;
    let (url, hash) = at(&s, &format!("/ws/matches/{id}")).await;
    let mut c = WtClient::connect(&url, &hash).await.expect("connects");
    assert_eq!(c.json().await["type"], "welcome");
    c.send_datagram(TEXT, b"{not json");
    let error = c.next_of("error").await;
    assert!(error["error"].as_str().is_some(), "{error}");
    c.send_datagram(BINARY, &[1, 2, 3]);
    let error = c.next_of("error").await;
    assert!(
        error["error"].as_str().unwrap().contains("binary"),
        "{error}"
    );
    // Too many bad ones: closed, 1008, the reason named in the last frame.
    for _ in 0..20 {
        c.send_datagram(TEXT, b"[1,2,3]");
    }
    let close = c.next_of("close").await;
    assert_eq!(close["code"], 1008, "{close}");
    assert!(
        close["reason"]
            .as_str()
            .unwrap()
            .contains("too many bad messages")
    );

    // A frame over the hard cap on the client's stream: 1009 at once.
    let mut big = WtClient::connect(&url, &hash).await.expect("connects");
    assert_eq!(big.json().await["type"], "welcome");
    big.send_frame(TEXT, b"{}", Some(64 << 20)).await;
    let close = big.next_of("close").await;
    assert_eq!(close["code"], 1009, "{close}");
}

/// `method path` (with a JSON `body` when not null) over HTTPS at `addr`, trusting `cert`
/// alone for `localhost`: status and body.
async fn https(
    addr: std::net::SocketAddr,
    cert: &[u8],
    method: &str,
    path: &str,
    body: Value,
) -> (u16, Value) {
    use rustls::pki_types::{CertificateDer, ServerName};
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut roots = rustls::RootCertStore::empty();
    roots
        .add(CertificateDer::from(cert.to_vec()))
        .expect("the certificate is a root");
    let config = rustls::ClientConfig::builder()
        .with_root_certificates(roots)
        .with_no_client_auth();
    let connector = tokio_rustls::TlsConnector::from(std::sync::Arc::new(config));
    let tcp = tokio::net::TcpStream::connect(addr)
        .await
        .expect("connects");
    let name = ServerName::try_from("localhost").expect("a name");
    let mut tls = connector.connect(name, tcp).await.expect("a TLS handshake");
    let body = if body.is_null() {
        String::new()
    } else {
        body.to_string()
    };
    let request = format!(
        "{method} {path} HTTP/1.1\r\nHost: localhost:{}\r\nConnection: close\r\n\
         Content-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        addr.port(),
        body.len()
    );
    tls.write_all(request.as_bytes()).await.expect("sent");
    let mut reply = String::new();
    tls.read_to_string(&mut reply).await.expect("a reply");
    let status = reply
        .split(' ')
        .nth(1)
        .and_then(|s| s.parse().ok())
        .expect("a status line");
    let body = reply.split("\r\n\r\n").nth(1).unwrap_or_default();
    (status, serde_json::from_str(body).unwrap_or(Value::Null))
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_operators_certificate_serves_https_and_webtransport() {
    let dir = common::temp_dir("tls");
    let identity = wtransport::Identity::self_signed(["localhost"]).expect("an identity");
    let (cert, key) = (dir.join("cert.pem"), dir.join("key.pem"));
    identity
        .certificate_chain()
        .store_pemfile(&cert)
        .await
        .expect("cert written");
    identity
        .private_key()
        .store_secret_pemfile(&key)
        .await
        .expect("key written");
    let leaf = &identity.certificate_chain().as_slice()[0];
    let s = process::Server::start(&[
        "--no-showcase",
        "--tls-cert",
        cert.to_str().unwrap(),
        "--tls-key",
        key.to_str().unwrap(),
    ]);
    // The API over HTTPS; WebTransport published with no hash to pin (the certificate is
    // trusted as any HTTPS one).
    let get = |path: &'static str| https(s.addr, leaf.der(), "GET", path, Value::Null);
    let (status, transport) = get("/api/transport").await;
    assert_eq!(status, 200, "{transport}");
    assert_eq!(
        transport["webtransport"]["url"],
        format!("https://localhost:{}", s.addr.port())
    );
    assert_eq!(transport["webtransport"]["certificate_hashes"], json!([]));
    let (status, health) = get("/api/health").await;
    assert_eq!(status, 200, "{health}");
    // Plain HTTP on that port gets no answer it can read.
    let plain = reqwest::get(format!("http://{}/api/health", s.addr)).await;
    assert!(plain.is_err(), "plain HTTP answered: {plain:?}");
    // A match made over HTTPS, watched over WebTransport with the same certificate.
    let body = json!({"map": "office", "opponent_control": "bot"});
    let (status, created) = https(s.addr, leaf.der(), "POST", "/api/matches", body).await;
    assert_eq!(status, 201, "{created}");
    let url = format!(
        "https://127.0.0.1:{}/ws/matches/{}?format=compact",
        s.addr.port(),
        created["id"].as_str().unwrap()
    );
    let mut c = WtClient::connect(&url, &leaf.hash())
        .await
        .expect("a session with the operator's certificate");
    assert_eq!(c.json().await["type"], "welcome");
}
