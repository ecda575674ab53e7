//! Each client's share of the server's doors, against a real server: an export cut short
//! says so in its last line and resumes with `from_tick`, one client runs only its share
//! of exports, and one that reads nothing gives its slot to a newcomer; one address's TCP connections are capped at accept while another's
//! health request is answered; a slot held by an idle socket lapses, a client holds few
//! seats, another showcase starts while every one is full, ten addresses lock no visitor
//! out of a seat or a place to watch; a spectator that does not read makes way for a
//! newcomer.
//!
//! Clients come from several loopback addresses (127.0.0.x, all of them this machine's)
//! to be several clients.

mod common;

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::Duration;

use common::{TestServer, test_config};
use futures_util::StreamExt;
use lasertag::config::Config;
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};

fn loopback(n: u8) -> IpAddr {
    IpAddr::V4(Ipv4Addr::new(127, 0, 0, n))
}

/// A TCP connection to `to` from `127.0.0.{from}`, with a small receive buffer (so that a
/// client that does not read fills it soon).
async fn connect(from: u8, to: SocketAddr) -> TcpStream {
    let socket = TcpSocket::new_v4().unwrap();
    socket.set_recv_buffer_size(4096).unwrap();
    socket.bind(SocketAddr::new(loopback(from), 0)).unwrap();
    socket.connect(to).await.unwrap()
}

/// Sends `GET path` over HTTP/1.0 (the body ends with the connection) from
/// `127.0.0.{from}`, reading nothing yet.
async fn request(from: u8, to: SocketAddr, path: &str) -> TcpStream {
    let mut stream = connect(from, to).await;
    let head = format!("GET {path} HTTP/1.0\r\nHost: test\r\n\r\n");
    stream.write_all(head.as_bytes()).await.unwrap();
    stream
}

/// The status and body of a response to [`request`], read to its end.
async fn response(mut stream: TcpStream) -> (u16, String) {
    let mut bytes = Vec::new();
    tokio::time::timeout(Duration::from_secs(60), stream.read_to_end(&mut bytes))
        .await
        .expect("the response ends within 60 s")
        .unwrap();
    let text = String::from_utf8_lossy(&bytes).to_string();
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let status = head
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    (status, body.to_string())
}

/// A finished match of `ticks` ticks with a belief worth exporting: its replay's id.
async fn replay(s: &TestServer, ticks: u64) -> String {
    let id = s
        .create_match(json!({"map": "office", "clock": "manual", "robots": 2,
                             "opponents": 2, "opponent_control": "api", "planner": "idle"}))
        .await;
    s.step(&id, ticks).await;
    assert_eq!(s.delete(&format!("/api/matches/{id}")).await.status, 204);
    id
}

/// An export's lines as JSON.
fn lines(body: &str) -> Vec<Value> {
    body.lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l:.200}")))
        .collect()
}

#[tokio::test]
async fn an_export_cut_short_says_so_and_resumes_from_its_tick() {
    let s = TestServer::start_with(Config {
        export_stall: Duration::from_millis(200),
        ..test_config()
    })
    .await;
    let id = replay(&s, 300).await;
    let path = format!("/api/replays/{id}/export?belief=true");
    // A reader that stops for far longer than the stall: the export ends without it.
    let stream = request(1, s.addr, &path).await;
    tokio::time::sleep(Duration::from_secs(2)).await;
    let (status, body) = response(stream).await;
    assert_eq!(status, 200);
    let mut first = lines(&body);
    let end = first.pop().unwrap();
    assert_eq!(end["complete"], false, "{end}");
    assert!(
        end["reason"].as_str().unwrap().starts_with("stalled"),
        "{end}"
    );
    assert_eq!(end["lines"], first.len() as u64);
    let from_tick = end["from_tick"].as_u64().unwrap();
    assert_eq!(
        from_tick,
        first.len() as u64,
        "every tick from 0 came before it"
    );
    assert!(
        from_tick < 300,
        "the whole export fitted in the buffers: {from_tick}"
    );
    // Resumed where it stopped, it ends whole.
    let stream = request(1, s.addr, &format!("{path}&from_tick={from_tick}")).await;
    let (status, body) = response(stream).await;
    assert_eq!(status, 200);
    let mut rest = lines(&body);
    let end = rest.pop().unwrap();
    assert_eq!(end, json!({"complete": true, "lines": rest.len()}));
    assert_eq!(rest[0]["tick"], from_tick);
    let last = rest.last().unwrap()["tick"].as_u64().unwrap();
    assert_eq!(first.len() + rest.len(), last as usize + 1);
    // On the grid of `from` and `every`: resuming at 7 of every 5 from 0 starts at 10.
    let stream = request(
        1,
        s.addr,
        &format!("/api/replays/{id}/export?every=5&to=20&from_tick=7"),
    )
    .await;
    let (_, body) = response(stream).await;
    let ticks: Vec<Value> = lines(&body).iter().map(|l| l["tick"].clone()).collect();
    assert_eq!(ticks, [json!(10), json!(15), json!(20), Value::Null]);
}

#[tokio::test]
async fn from_tick_out_of_range_is_refused_naming_it() {
    let s = TestServer::start().await;
    let id = replay(&s, 20).await;
    for query in [
        "from_tick=1000",
        "from=10&from_tick=5",
        "to=5&from_tick=6",
        "from_tick=x",
    ] {
        let r = s.get(&format!("/api/replays/{id}/export?{query}")).await;
        assert_eq!(r.status, 400, "{query}: {}", r.body);
        assert!(
            r.body["error"].as_str().unwrap().starts_with("from_tick"),
            "{query}: {}",
            r.body
        );
    }
}

#[tokio::test]
async fn one_client_runs_only_its_share_of_exports() {
    let s = TestServer::start_with(Config {
        max_exports: 2,
        max_exports_per_address: 1,
        ..test_config()
    })
    .await;
    let id = replay(&s, 300).await;
    let path = format!("/api/replays/{id}/export?belief=true");
    // Readers that do not read hold their exports.
    let _first = request(1, s.addr, &path).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let (status, body) = response(request(1, s.addr, &path).await).await;
    assert_eq!(status, 429, "{body}");
    assert!(body.contains("exports"), "{body}");
    let _second = request(2, s.addr, &path).await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    let (status, body) = response(request(3, s.addr, &path).await).await;
    assert_eq!(status, 503, "{body}");
}

#[tokio::test]
async fn an_export_that_reads_nothing_gives_its_slot_to_a_newcomer() {
    let s = TestServer::start_with(Config {
        max_exports: 1,
        ..test_config()
    })
    .await;
    let id = replay(&s, 300).await;
    let path = format!("/api/replays/{id}/export?belief=true");
    // The only slot, held by a reader that stops at once.
    let idle = request(2, s.addr, &path).await;
    // A newcomer from another address gets the slot once the idle one has read nothing
    // for a second (503 until then).
    let mut got = None;
    for _ in 0..20 {
        let (status, body) = response(request(3, s.addr, &format!("{path}&to=10")).await).await;
        if status == 200 {
            got = Some(body);
            break;
        }
        assert_eq!(status, 503, "{body}");
        tokio::time::sleep(Duration::from_millis(500)).await;
    }
    let body = got.expect("the newcomer never got the slot");
    assert_eq!(lines(&body).pop().unwrap()["complete"], true);
    // The idle one ended, and its last line says why and where to resume.
    let (status, body) = response(idle).await;
    assert_eq!(status, 200);
    let end = lines(&body).pop().unwrap();
    assert_eq!(end["complete"], false, "{end}");
    assert!(
        end["reason"].as_str().unwrap().starts_with("gave way"),
        "{end}"
    );
    assert!(end["from_tick"].as_u64().is_some(), "{end}");
}

#[tokio::test]
async fn one_address_is_capped_at_accept_and_others_are_answered() {
    let s = TestServer::start_with(Config {
        max_tcp_per_address: Some(4),
        ..test_config()
    })
    .await;
    // Half-sent requests up to the cap: held until the header time-out.
    let mut held = Vec::new();
    for _ in 0..4 {
        let mut c = connect(1, s.addr).await;
        c.write_all(b"GET /api/health HTTP/1.1\r\n").await.unwrap();
        held.push(c);
    }
    // Past it, each is closed at once.
    for _ in 0..10 {
        let mut extra = connect(1, s.addr).await;
        let _ = extra.write_all(b"GET /api/health HTTP/1.0\r\n\r\n").await;
        let mut buf = [0u8; 64];
        let read = tokio::time::timeout(Duration::from_secs(5), extra.read(&mut buf))
            .await
            .expect("closed, not left waiting");
        assert!(matches!(read, Ok(0) | Err(_)), "answered past the cap");
    }
    // Another address is served meanwhile.
    let (status, _) = response(request(2, s.addr, "/api/health").await).await;
    assert_eq!(status, 200);
    let (_, metrics) = response(request(2, s.addr, "/metrics").await).await;
    let counted = metrics
        .lines()
        .find(|l| l.starts_with("lasertag_refused_total{reason=\"tcp_per_address\"}"))
        .and_then(|l| l.split_whitespace().last())
        .and_then(|n| n.parse::<u64>().ok());
    assert_eq!(counted, Some(10), "{metrics:.2000}");
    // Once one closes, the address may open another.
    held.pop();
    let mut answered = false;
    for _ in 0..50 {
        tokio::time::sleep(Duration::from_millis(100)).await;
        if response(request(1, s.addr, "/api/health").await).await.0 == 200 {
            answered = true;
            break;
        }
    }
    assert!(answered, "the address stayed at its cap after a close");
}

/// The `free_slots` of match `id` as the lobby lists it.
async fn free_slots(s: &TestServer, id: &str) -> u64 {
    let all = s.get("/api/matches").await.body;
    let found = all.as_array().unwrap().iter().find(|m| m["id"] == id);
    found.expect("listed")["free_slots"].as_u64().unwrap()
}

#[tokio::test]
async fn a_slot_held_by_an_idle_socket_lapses() {
    let s = TestServer::start_with(Config {
        join_hold: Duration::from_millis(500),
        ..test_config()
    })
    .await;
    let id = s
        .create_match(json!({"map": "office", "opponents": 3, "bots_joinable": true}))
        .await;
    let (_, token) = s.join(&id, "idle").await;
    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    // Connected, never driven: the slot is freed and the socket told why.
    let mut closed = None;
    for _ in 0..200 {
        match ws.next().await {
            common::Got::Closed { reason, .. } => {
                closed = Some(reason);
                break;
            }
            common::Got::Ended => break,
            common::Got::Json(_) => {}
        }
    }
    let reason = closed.expect("closed with a reason");
    assert!(reason.contains("lapsed"), "{reason}");
    // Told only once the slot is free and listed.
    assert_eq!(free_slots(&s, &id).await, 3);
}

#[tokio::test]
async fn a_client_holds_few_seats_over_all_matches() {
    let s = TestServer::start_with(Config {
        max_seats_per_address: 2,
        ..test_config()
    })
    .await;
    let body = json!({"map": "office", "opponents": 3, "bots_joinable": true});
    let (a, b) = (
        s.create_match(body.clone()).await,
        s.create_match(body).await,
    );
    s.join(&a, "one").await;
    s.join(&b, "two").await;
    let r = s
        .post(
            &format!("/api/matches/{b}/players"),
            &json!({"name": "three"}),
        )
        .await;
    assert_eq!(r.status, 429, "{}", r.body);
    assert!(
        r.body["error"].as_str().unwrap().contains("slot"),
        "{}",
        r.body
    );
}

#[tokio::test]
async fn another_showcase_starts_while_every_one_is_full() {
    let s = TestServer::start().await;
    tokio::spawn(lasertag::game::showcase::keep_running(s.registry.clone()));
    let showcases = async || -> Vec<Value> {
        let all = s.get("/api/matches").await.body;
        all.as_array()
            .unwrap()
            .iter()
            .filter(|m| m["id"].as_str().unwrap().starts_with("showcase-"))
            .cloned()
            .collect()
    };
    let mut first = None;
    for _ in 0..300 {
        if let Some(m) = showcases().await.into_iter().next() {
            first = Some(m);
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let first = first.expect("a showcase starts");
    let id = first["id"].as_str().unwrap().to_string();
    // People take and play every slot (until none is left: the robots may tag a bot
    // meanwhile, which frees no slot either).
    let mut players = Vec::new();
    for k in 0..first["free_slots"].as_u64().unwrap() {
        let r = s
            .post(
                &format!("/api/matches/{id}/players"),
                &json!({"name": format!("p{k}")}),
            )
            .await;
        if r.status == 409 {
            break;
        }
        assert_eq!(r.status, 201, "{}", r.body);
        let token = r.body["token"].as_str().unwrap().to_string();
        let mut ws = s.ws(&id, Some(&token)).await.unwrap();
        ws.send_json(&json!({"type": "input", "forward": 0.0, "turn": 0.0, "tag": false}))
            .await
            .unwrap();
        players.push(ws);
    }
    // A visitor finds another showcase with room.
    let mut other = None;
    for _ in 0..300 {
        other = showcases()
            .await
            .into_iter()
            .find(|m| m["id"] != id.as_str() && m["free_slots"].as_u64() > Some(0));
        if other.is_some() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let other = other.expect("another showcase starts");
    s.join(other["id"].as_str().unwrap(), "visitor").await;
}

/// A client of the HTTP API on `127.0.0.{from}`.
fn client_at(from: u8) -> reqwest::Client {
    reqwest::Client::builder()
        .local_address(loopback(from))
        .build()
        .unwrap()
}

/// `POST /api/showcase/players` from `client`: the status and body.
async fn showcase_seat(s: &TestServer, client: &reqwest::Client, name: &str) -> (u16, Value) {
    let r = client
        .post(s.url("/api/showcase/players"))
        .json(&json!({ "name": name }))
        .send()
        .await
        .unwrap();
    (r.status().as_u16(), r.json().await.unwrap_or(Value::Null))
}

/// Ten addresses take every seat they may (join-or-create) and every place to watch the
/// showcase they may; a visitor from an eleventh still finds both.
#[tokio::test]
async fn ten_hostile_addresses_lock_no_visitor_out() {
    let s = TestServer::start_with(Config {
        max_seats_per_address: 2,
        max_spectators_per_address: 10,
        ..test_config()
    })
    .await;
    tokio::spawn(lasertag::game::showcase::keep_running(s.registry.clone()));
    let hostile: Vec<u8> = (10..20).collect();
    let mut seats = 0;
    let mut watched = None;
    for &from in &hostile {
        let client = client_at(from);
        loop {
            let (status, body) = showcase_seat(&s, &client, &format!("h{from}-{seats}")).await;
            if status == 429 {
                break; // this address holds all it may
            }
            assert_eq!(status, 201, "{body}");
            watched.get_or_insert(body["match_id"].as_str().unwrap().to_string());
            seats += 1;
        }
    }
    assert_eq!(seats, 2 * hostile.len(), "each address holds its two seats");
    // Every place to watch the first showcase that each address may take.
    let id = watched.unwrap();
    let mut crowd = Vec::new();
    for &from in &hostile {
        let mut taken = 0;
        let refused = loop {
            match spectator(&s, from, &id).await {
                Ok(ws) => crowd.push(ws),
                Err(e) => break e,
            }
            taken += 1;
            assert!(taken <= 10, "127.0.0.{from} watches past its share");
        };
        assert_eq!(taken, 10);
        match refused {
            tokio_tungstenite::tungstenite::Error::Http(r) => assert_eq!(r.status(), 429),
            e => panic!("refused with {e}"),
        }
    }
    // The visitor: a seat in a showcase (another one started if need be), and a place to
    // watch the crowded one.
    let visitor = client_at(50);
    let (status, body) = showcase_seat(&s, &visitor, "visitor").await;
    assert_eq!(status, 201, "{body}");
    assert!(
        body["token"].is_string() && body["opponent_id"].is_string(),
        "{body}"
    );
    spectator(&s, 50, &id)
        .await
        .expect("the visitor watches the crowded showcase");
}

/// A spectator's WebSocket to match `id` from `127.0.0.{from}` that reads only when asked.
async fn spectator(
    s: &TestServer,
    from: u8,
    id: &str,
) -> Result<tokio_tungstenite::WebSocketStream<TcpStream>, tokio_tungstenite::tungstenite::Error> {
    let stream = connect(from, s.addr).await;
    let url = format!("ws://{}/ws/matches/{id}", s.addr);
    tokio_tungstenite::client_async(url, stream)
        .await
        .map(|(ws, _)| ws)
}

#[tokio::test]
async fn a_spectator_that_does_not_read_makes_way_for_a_newcomer() {
    let s = TestServer::start_with(Config {
        max_spectators_per_match: 2,
        ..test_config()
    })
    .await;
    // A match with a lot to show every tick.
    let id = s
        .create_match(json!({"map": "warehouse", "robots": 8, "opponents": 8}))
        .await;
    // One spectator reads all the time, one never does.
    let read = |mut ws: tokio_tungstenite::WebSocketStream<TcpStream>| {
        tokio::spawn(async move { while let Some(Ok(_)) = ws.next().await {} })
    };
    let reading = read(spectator(&s, 1, &id).await.unwrap());
    let _idle = spectator(&s, 2, &id).await.unwrap();
    // A newcomer is refused while both read; once the idle one has filled its buffers, it
    // is let in in its place.
    let mut newcomer = None;
    for _ in 0..300 {
        if let Ok(ws) = spectator(&s, 3, &id).await {
            newcomer = Some(read(ws));
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(newcomer.is_some(), "the newcomer was never let in");
    assert!(!reading.is_finished(), "the reading spectator was dropped");
    // The cap still holds: a fourth has no place.
    assert!(spectator(&s, 4, &id).await.is_err());
}

/// The showcase computes its head start (its spectators' delay of play) after it is listed:
/// a spectator who comes while that runs (seconds on a loaded machine or a debug build) is
/// told the view starts at once, as it does when the computing ends, not to wait for the
/// ticks still being computed.
#[tokio::test]
async fn a_spectator_who_comes_during_the_head_start_is_not_told_to_wait() {
    let s = TestServer::start().await;
    tokio::spawn(lasertag::game::showcase::keep_running(s.registry.clone()));
    let mut id = None;
    for _ in 0..2000 {
        let all = s.get("/api/matches").await.body;
        id = all.as_array().unwrap().iter().find_map(|m| {
            let id = m["id"].as_str()?;
            id.starts_with("showcase-").then(|| id.to_string())
        });
        if id.is_some() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let id = id.expect("a showcase starts");
    let mut ws = s.ws(&id, None).await.unwrap();
    let welcome = ws.next_of("welcome").await;
    assert_eq!(welcome["role"], "spectator", "{welcome}");
    assert_eq!(welcome["view_starts_in_s"], 0.0, "{welcome}");
}
