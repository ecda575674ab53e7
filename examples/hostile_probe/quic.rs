//! The classes of the WebTransport door (UDP, the server's port), from one address
//! (127.0.0.2): datagrams of every bad kind as fast as it sends them beside a session that
//! never reads, and more sessions than an address may open.

use std::collections::BTreeMap;
use std::net::{IpAddr, Ipv4Addr};
use std::time::{Duration, Instant};

use serde_json::{Value, json};

use crate::doors::{Report, tally};
use crate::harness::{Ctx, ms_since};
use crate::wt::{BINARY, TEXT, WtClient};

const FROM: IpAddr = IpAddr::V4(Ipv4Addr::new(127, 0, 0, 2));

/// The published URL of `path` and the hash to pin.
async fn at(ctx: &Ctx, path: &str) -> Result<(String, wtransport::tls::Sha256Digest), String> {
    let reply: Value = ctx
        .http
        .get(ctx.url("/api/transport"))
        .send()
        .await
        .map_err(|e| e.to_string())?
        .json()
        .await
        .map_err(|e| e.to_string())?;
    if reply["webtransport"].is_null() {
        return Err("the server offers no WebTransport".into());
    }
    let (url, hash) = crate::wt::published(&reply);
    Ok((format!("{url}{path}"), hash))
}

/// For 5 s, one session sends datagrams as fast as it can (malformed JSON, binary, 1,100
/// bytes of text, arrays of 50 inputs), while a second session on the same match reads
/// nothing at all; what the flooding one got back.
pub(crate) async fn datagrams(ctx: &Ctx) -> Result<Report, String> {
    let (url, hash) = at(ctx, &format!("/ws/matches/{}", ctx.bystander)).await?;
    let _deaf = WtClient::connect_from(&url, &hash, Some(FROM))
        .await
        .map_err(|e| e.to_string())?;
    let mut c = WtClient::connect_from(&url, &hash, Some(FROM))
        .await
        .map_err(|e| e.to_string())?;
    let many = json!(vec![
        json!({"type": "input", "forward": 1, "turn": 0, "tag": false});
        50
    ])
    .to_string();
    let long = "x".repeat(1100);
    let bad: [(u8, &[u8]); 4] = [
        (TEXT, b"{not json"),
        (BINARY, &[1, 2, 3, 4]),
        (TEXT, long.as_bytes()),
        (TEXT, many.as_bytes()),
    ];
    let t = Instant::now();
    let mut sent = 0u64;
    let mut refused = 0u64;
    while t.elapsed() < Duration::from_secs(5) {
        for (kind, payload) in bad {
            let mut d = vec![kind];
            d.extend_from_slice(payload);
            match c.conn.send_datagram(d) {
                Ok(()) => sent += 1,
                Err(_) => refused += 1,
            }
        }
        tokio::task::yield_now().await;
    }
    let ms = ms_since(t);
    let mut statuses = BTreeMap::new();
    let end = Instant::now() + Duration::from_secs(3);
    while Instant::now() < end {
        let got = tokio::time::timeout(Duration::from_millis(500), c.frame()).await;
        let Ok(Some((TEXT, payload))) = got else {
            if matches!(got, Ok(None)) {
                *statuses.entry("stream ended".to_string()).or_insert(0) += 1;
                break;
            }
            continue;
        };
        let v: Value = serde_json::from_slice(&payload).unwrap_or(Value::Null);
        let key = match v["type"].as_str() {
            Some("close") => format!("close {}", v["code"]),
            Some(t) => t.to_string(),
            None => "?".into(),
        };
        *statuses.entry(key).or_insert(0) += 1;
    }
    Ok((
        tally(&statuses),
        Some(ms),
        format!(
            "{sent} datagrams sent in 5 s ({refused} refused by the client's own QUIC), a second session reading nothing"
        ),
    ))
}

/// 40 sessions on the bystander match from one address, held 5 s: how many the server
/// admits (its per-address connections, WebSockets and sessions together).
pub(crate) async fn sessions(ctx: &Ctx) -> Result<Report, String> {
    let (url, hash) = at(ctx, &format!("/ws/matches/{}", ctx.bystander)).await?;
    let mut statuses = BTreeMap::new();
    let mut held = Vec::new();
    let t = Instant::now();
    for _ in 0..40 {
        match WtClient::connect_from(&url, &hash, Some(FROM)).await {
            Ok(c) => {
                *statuses.entry("admitted".to_string()).or_insert(0) += 1;
                held.push(c);
            }
            Err(wtransport::error::ConnectingError::SessionRejected) => {
                *statuses.entry("refused".to_string()).or_insert(0) += 1;
            }
            Err(e) => *statuses.entry(e.to_string()).or_insert(0) += 1,
        }
    }
    let ms = ms_since(t);
    tokio::time::sleep(Duration::from_secs(5)).await;
    Ok((tally(&statuses), Some(ms), "held 5 s".into()))
}
