//! The classes that take a door's share from everyone else: slow exports, a flood of TCP
//! connections from one address, seats held from a few addresses, idle spectators filling
//! a match's cap. The attackers come from other loopback addresses (127.0.0.2 and up) than
//! the watchers (127.0.0.1), as strangers would.

use std::collections::BTreeMap;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::{Duration, Instant};

use crate::harness::{Ctx, error_text, ms_since, send};
use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};

/// What a class's requests got: the status, the main request's time, a note (the classes'
/// `Outcome`, which this file does not name: `classes.rs` dispatches here).
pub(crate) type Report = (String, Option<f64>, String);

fn loopback(n: u8) -> IpAddr {
    IpAddr::V4(Ipv4Addr::new(127, 0, 0, n))
}

/// A TCP connection from `127.0.0.{from}` with a small receive buffer.
async fn connect(from: u8, to: SocketAddr) -> std::io::Result<TcpStream> {
    let socket = TcpSocket::new_v4()?;
    socket.set_recv_buffer_size(4096)?;
    socket.bind(SocketAddr::new(loopback(from), 0))?;
    socket.connect(to).await
}

/// An HTTP client whose connections come from `127.0.0.{from}`.
pub(crate) fn client(from: u8) -> Result<reqwest::Client, String> {
    reqwest::Client::builder()
        .local_address(loopback(from))
        .timeout(Duration::from_secs(10))
        .build()
        .map_err(|e| error_text(&e))
}

pub(crate) fn tally(statuses: &BTreeMap<String, usize>) -> String {
    let parts: Vec<String> = statuses.iter().map(|(s, n)| format!("{n}×{s}")).collect();
    parts.join(", ")
}

/// A finished match of 6,000 ticks: its replay's id.
pub(crate) async fn replay(ctx: &Ctx) -> Result<String, String> {
    let (_, id, token) = ctx
        .create(
            &json!({"map": "office", "clock": "manual", "robots": 2, "opponents": 2,
                        "opponent_control": "api", "planner": "idle", "time_limit_s": 600}),
        )
        .await?;
    let step = Ctx::with_token(
        ctx.http.post(ctx.url(&format!("/api/matches/{id}/step"))),
        token.as_deref(),
    )
    .json(&json!({"ticks": 6000}));
    send(step).await?;
    send(Ctx::with_token(
        ctx.http.delete(ctx.url(&format!("/api/matches/{id}"))),
        token.as_deref(),
    ))
    .await?;
    Ok(id)
}

/// Exports whose readers stop: does the stream say it was cut, where to resume, and do
/// other clients still get an export?
pub(crate) async fn slow_export(ctx: &Ctx) -> Result<Report, String> {
    let id = replay(ctx).await?;
    let path = format!("/api/replays/{id}/export");
    let request = format!("GET {path} HTTP/1.0\r\nHost: probe\r\n\r\n");
    // Two slow readers from one address, one from another.
    let mut slow = Vec::new();
    let mut refused = BTreeMap::new();
    for from in [2u8, 2, 3] {
        let mut s = connect(from, ctx.addr).await.map_err(|e| e.to_string())?;
        s.write_all(request.as_bytes())
            .await
            .map_err(|e| e.to_string())?;
        tokio::time::sleep(Duration::from_millis(300)).await;
        // A refusal answers at once; an export streams (and fills the buffers).
        let mut head = [0u8; 12];
        match tokio::time::timeout(Duration::from_millis(500), s.read_exact(&mut head)).await {
            Ok(Ok(_)) => {
                let status = String::from_utf8_lossy(&head[9..12]).to_string();
                if status != "200" {
                    *refused.entry(format!("{status} from .{from}")).or_insert(0) += 1;
                    continue;
                }
                slow.push(s);
            }
            _ => slow.push(s),
        }
    }
    // A visitor from a third address, once the slow readers' buffers are full and they
    // have read nothing for a few seconds.
    tokio::time::sleep(Duration::from_secs(5)).await;
    let visitor = client(4)?;
    let t = Instant::now();
    let v = visitor.get(ctx.url(&format!("{path}?to=100"))).send().await;
    let visitor_status = match v {
        Ok(r) => {
            let status = r.status().as_u16();
            let _ = r.bytes().await;
            status.to_string()
        }
        Err(e) => error_text(&e),
    };
    let visitor_ms = ms_since(t);
    // The slow readers stop for longer than the stall (30 s), then read what is left.
    tokio::time::sleep(Duration::from_secs(30)).await;
    let mut ends = Vec::new();
    for mut s in slow {
        let mut bytes = Vec::new();
        let _ = tokio::time::timeout(Duration::from_secs(30), s.read_to_end(&mut bytes)).await;
        let text = String::from_utf8_lossy(&bytes);
        let lines = text.lines().filter(|l| l.starts_with('{')).count();
        let last = text
            .lines()
            .rev()
            .find(|l| l.starts_with('{'))
            .and_then(|l| serde_json::from_str::<Value>(l).ok())
            .filter(|v| v.get("complete").is_some())
            .map_or("no completion line".to_string(), |v| v.to_string());
        ends.push(format!("{lines} lines, last {last}"));
    }
    Ok((
        format!("visitor {visitor_status}"),
        Some(visitor_ms),
        format!(
            "slow readers: {}; refused: {}; a visitor's export from .4 answered {visitor_status}",
            ends.join(" | "),
            if refused.is_empty() {
                "none".into()
            } else {
                tally(&refused)
            }
        ),
    ))
}

/// One address opens far more connections than any client needs, each half a header:
/// how many the server keeps, and whether others are answered.
pub(crate) async fn conn_flood(ctx: &Ctx) -> Result<Report, String> {
    const CONNECTIONS: usize = 1000;
    let mut held = Vec::new();
    let mut failed = 0;
    for _ in 0..CONNECTIONS {
        match connect(2, ctx.addr).await {
            Ok(mut s) => {
                let _ = s
                    .write_all(b"GET /api/health HTTP/1.1\r\nHost: x\r\n")
                    .await;
                held.push(s);
            }
            Err(_) => failed += 1,
        }
    }
    tokio::time::sleep(Duration::from_secs(1)).await;
    // Which the server closed at once.
    let mut closed = 0;
    for s in &mut held {
        let mut buf = [0u8; 64];
        if let Ok(Ok(0) | Err(_)) =
            tokio::time::timeout(Duration::from_millis(2), s.read(&mut buf)).await
        {
            closed += 1;
        }
    }
    let other = client(3)?;
    let t = Instant::now();
    let health = match other.get(ctx.url("/api/health")).send().await {
        Ok(r) => r.status().as_u16().to_string(),
        Err(e) => error_text(&e),
    };
    let ms = ms_since(t);
    let refused = match other.get(ctx.url("/metrics")).send().await {
        Ok(r) => r
            .text()
            .await
            .unwrap_or_default()
            .lines()
            .find(|l| l.starts_with("lasertag_refused_total{reason=\"tcp_per_address\"}"))
            .and_then(|l| l.split_whitespace().last().map(str::to_string))
            .unwrap_or_else(|| "absent".into()),
        Err(e) => error_text(&e),
    };
    Ok((
        format!("health from .3 {health}"),
        Some(ms),
        format!(
            "{} of {CONNECTIONS} connections from .2 opened, {closed} of them closed by the server within 1 s, {failed} failed to open; tcp_per_address refusals counted: {refused}",
            held.len()
        ),
    ))
}

/// The showcases in the listing: (id, free slots).
async fn showcases(http: &reqwest::Client, ctx: &Ctx) -> Vec<(String, u64)> {
    let Ok(r) = http.get(ctx.url("/api/matches")).send().await else {
        return Vec::new();
    };
    let Ok(all) = r.json::<Value>().await else {
        return Vec::new();
    };
    all.as_array()
        .into_iter()
        .flatten()
        .filter(|m| {
            m["id"].as_str().is_some_and(|i| i.starts_with("showcase-")) && m["status"] == "running"
        })
        .map(|m| {
            (
                m["id"].as_str().unwrap_or_default().to_string(),
                m["free_slots"].as_u64().unwrap_or(0),
            )
        })
        .collect()
}

/// A player's socket that sends one input (the slot is then played) and reads nothing.
async fn sit(
    from: u8,
    ctx: &Ctx,
    id: &str,
    token: &str,
) -> Option<tokio_tungstenite::WebSocketStream<TcpStream>> {
    let stream = connect(from, ctx.addr).await.ok()?;
    let url = format!("ws://{}/ws/matches/{id}?token={token}", ctx.addr);
    let (mut ws, _) = tokio_tungstenite::client_async(url, stream).await.ok()?;
    let input = json!({"type": "input", "forward": 0.0, "turn": 0.0, "tag": false});
    ws.send(tokio_tungstenite::tungstenite::Message::Text(
        input.to_string().into(),
    ))
    .await
    .ok()?;
    Some(ws)
}

/// Ten addresses (.2 to .11) take every showcase seat they can (through the join-or-create
/// door too, where the server has it) and play each (one input), keep taking them for
/// 30 s; every 2 s a visitor (each from an address of its own, .30 and up) asks for a seat
/// as the lobby's Play now does: join-or-create, or (an older server) a showcase with room.
pub(crate) async fn seat_hold(ctx: &Ctx) -> Result<Report, String> {
    let attackers: Vec<(u8, reqwest::Client)> = (2u8..12)
        .map(|a| client(a).map(|c| (a, c)))
        .collect::<Result<_, _>>()?;
    let mut visitor_from = 30u8;
    let mut sockets = Vec::new();
    let mut taken = BTreeMap::new();
    let mut visits = BTreeMap::new();
    let mut showcases_seen = 0;
    let end = Instant::now() + Duration::from_secs(30);
    let mut next_visit = Instant::now() + Duration::from_secs(2);
    while Instant::now() < end {
        for (from, http) in &attackers {
            if let Ok(r) = (http.post(ctx.url("/api/showcase/players")))
                .json(&json!({"name": "squat"}))
                .send()
                .await
            {
                let status = r.status().as_u16();
                if status != 404 {
                    *taken.entry(status.to_string()).or_insert(0) += 1;
                }
                if status == 201
                    && let Ok(body) = r.json::<Value>().await
                    && let (Some(id), Some(token)) =
                        (body["match_id"].as_str(), body["token"].as_str())
                    && let Some(ws) = sit(*from, ctx, id, token).await
                {
                    sockets.push(ws);
                }
            }
            for (id, free) in showcases(http, ctx).await {
                if free == 0 {
                    continue;
                }
                let url = ctx.url(&format!("/api/matches/{id}/players"));
                let Ok(r) = http.post(url).json(&json!({"name": "squat"})).send().await else {
                    continue;
                };
                let status = r.status().as_u16();
                *taken.entry(status.to_string()).or_insert(0) += 1;
                if status == 201
                    && let Ok(body) = r.json::<Value>().await
                    && let Some(token) = body["token"].as_str()
                    && let Some(ws) = sit(*from, ctx, &id, token).await
                {
                    sockets.push(ws);
                }
            }
        }
        if Instant::now() >= next_visit {
            next_visit += Duration::from_secs(2);
            let visitor = client(visitor_from)?;
            visitor_from += 1;
            let list = showcases(&visitor, ctx).await;
            showcases_seen = showcases_seen.max(list.len());
            let asked = (visitor.post(ctx.url("/api/showcase/players")))
                .json(&json!({"name": "visitor"}))
                .send()
                .await;
            if let Ok(r) = &asked
                && r.status() != 404
            {
                *visits.entry(r.status().as_u16().to_string()).or_insert(0) += 1;
                tokio::time::sleep(Duration::from_millis(200)).await;
                continue;
            }
            // As the page does: a showcase with a free slot, else the first.
            let pick = list.iter().find(|(_, f)| *f > 0).or(list.first());
            let status = match pick {
                None => "no showcase".to_string(),
                Some((id, _)) => {
                    let url = ctx.url(&format!("/api/matches/{id}/players"));
                    match visitor
                        .post(url)
                        .json(&json!({"name": "visitor"}))
                        .send()
                        .await
                    {
                        Ok(r) => r.status().as_u16().to_string(),
                        Err(e) => error_text(&e),
                    }
                }
            };
            *visits.entry(status).or_insert(0) += 1;
        }
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    Ok((
        format!("visitor: {}", tally(&visits)),
        None,
        format!(
            "attackers' joins: {}; {} seats played by them at the end; at most {showcases_seen} showcases running",
            tally(&taken),
            sockets.len()
        ),
    ))
}

/// Ten addresses (.2 to .11) open 60 spectator sockets each on the showcase and read nothing; a
/// visitor tries to watch once a second for 30 s. The showcase's spectators see it 30 s
/// late, so nothing reaches them before it is that old: the class waits for one that is.
pub(crate) async fn idle_spectators(ctx: &Ctx) -> Result<Report, String> {
    let http = client(6)?;
    let mut found = None;
    while found.is_none() && Instant::now() < ctx.give_up {
        if let Ok(r) = http.get(ctx.url("/api/matches")).send().await
            && let Ok(all) = r.json::<Value>().await
        {
            found = all.as_array().into_iter().flatten().find_map(|m| {
                let id = m["id"].as_str()?;
                (id.starts_with("showcase-")
                    && m["status"] == "running"
                    && m["tick"].as_u64() >= Some(700))
                .then(|| id.to_string())
            });
        }
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
    let Some(id) = found else {
        return Err("no showcase 35 s old".into());
    };
    let url = format!("ws://{}/ws/matches/{id}", ctx.addr);
    let mut idle = Vec::new();
    let mut opened = BTreeMap::new();
    for from in 2u8..12 {
        for _ in 0..60 {
            let Ok(stream) = connect(from, ctx.addr).await else {
                *opened.entry("tcp failed".to_string()).or_insert(0) += 1;
                continue;
            };
            match tokio_tungstenite::client_async(url.clone(), stream).await {
                Ok((ws, _)) => {
                    *opened.entry("open".to_string()).or_insert(0) += 1;
                    idle.push(ws);
                }
                Err(tokio_tungstenite::tungstenite::Error::Http(r)) => {
                    *opened.entry(r.status().as_u16().to_string()).or_insert(0) += 1;
                }
                Err(_) => *opened.entry("error".to_string()).or_insert(0) += 1,
            }
        }
    }
    let start = Instant::now();
    let mut tries = BTreeMap::new();
    let mut first_in = None;
    let mut watching = Vec::new();
    while start.elapsed() < Duration::from_secs(30) {
        let status = match connect(30, ctx.addr).await {
            Err(e) => e.to_string(),
            Ok(stream) => match tokio_tungstenite::client_async(url.clone(), stream).await {
                Ok((mut ws, _)) => {
                    first_in.get_or_insert(start.elapsed());
                    // A visitor reads what it is sent.
                    watching.push(tokio::spawn(
                        async move { while ws.next().await.is_some() {} },
                    ));
                    "open".to_string()
                }
                Err(tokio_tungstenite::tungstenite::Error::Http(r)) => {
                    r.status().as_u16().to_string()
                }
                Err(e) => e.to_string(),
            },
        };
        *tries.entry(status).or_insert(0) += 1;
        tokio::time::sleep(Duration::from_secs(1)).await;
    }
    for w in watching {
        w.abort();
    }
    Ok((
        format!("visitor: {}", tally(&tries)),
        first_in.map(|d| d.as_secs_f64() * 1e3),
        format!(
            "idle sockets from .2-.11: {}; the visitor first got in after {}",
            tally(&opened),
            first_in.map_or("never".into(), |d| format!("{:.1} s", d.as_secs_f64()))
        ),
    ))
}
