//! The classes of the doors priced last: a search planner's settings, belief reads and name
//! claims, each from one address (127.0.0.2) doing its worst.

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use serde_json::json;

use crate::doors::{Report, client, tally};
use crate::harness::{Ctx, error_text, ms_since};

/// The status of a request, or why it got none.
fn status_of(r: Result<reqwest::Response, reqwest::Error>) -> String {
    match r {
        Ok(r) => r.status().as_u16().to_string(),
        Err(e) => error_text(&e),
    }
}

/// A real-time search planner past its price (depth 6, branching 12, a round every tick),
/// then as many at the deepest setting admission prices in (depth 5, branching 6) as the
/// server admits from one address, left running for 10 s while the watchers watch.
pub(crate) async fn search_planner(ctx: &Ctx) -> Result<Report, String> {
    let http = client(2)?;
    let mut statuses = BTreeMap::new();
    let t = Instant::now();
    let mut sent = vec![(6, 12)];
    sent.extend([(5, 6); 4]);
    for (depth, branching) in sent {
        let body = json!({"map": "office", "planner": "search", "opponents": 2,
            "coordination": {"search_depth": depth, "search_branching": branching,
                             "round_ticks": 1}});
        let status = status_of(http.post(ctx.url("/api/matches")).json(&body).send().await);
        *statuses
            .entry(format!("depth {depth} branching {branching}: {status}"))
            .or_insert(0) += 1;
    }
    let ms = ms_since(t);
    tokio::time::sleep(Duration::from_secs(10)).await;
    Ok((tally(&statuses), Some(ms), "then 10 s of their play".into()))
}

/// Four parallel loops of `GET /belief` (gzip'd, the dearer encoding to make) of a role of
/// 100,000 particles, for 5 s.
pub(crate) async fn belief_loop(ctx: &Ctx) -> Result<Report, String> {
    let (_, id, _) = ctx
        .create(&json!({"map": "office", "opponents": 1, "planner": "idle",
                        "tracker": {"particles_per_role": 100000}}))
        .await?;
    let http = client(2)?;
    let statuses: Arc<Mutex<BTreeMap<String, usize>>> = Arc::default();
    let bytes = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let end = Instant::now() + Duration::from_secs(5);
    let url = ctx.url(&format!("/api/matches/{id}/belief"));
    let loops: Vec<_> = (0..4)
        .map(|_| {
            let (http, url, statuses, bytes) =
                (http.clone(), url.clone(), statuses.clone(), bytes.clone());
            tokio::spawn(async move {
                while Instant::now() < end {
                    let r = http
                        .get(&url)
                        .header("accept-encoding", "gzip")
                        .send()
                        .await;
                    let status = match r {
                        Ok(r) => {
                            let s = r.status().as_u16().to_string();
                            if let Ok(b) = r.bytes().await {
                                bytes.fetch_add(
                                    b.len() as u64,
                                    std::sync::atomic::Ordering::Relaxed,
                                );
                            }
                            s
                        }
                        Err(e) => error_text(&e),
                    };
                    *statuses
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .entry(status)
                        .or_insert(0) += 1;
                }
            })
        })
        .collect();
    for l in loops {
        let _ = l.await;
    }
    let statuses = statuses.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let read = bytes.load(std::sync::atomic::Ordering::Relaxed);
    Ok((
        tally(&statuses),
        None,
        format!("{:.1} MB read in 5 s by four loops", read as f64 / 1e6),
    ))
}

/// Claims of fresh names as fast as one address can send them, for 10 s.
pub(crate) async fn name_claims(ctx: &Ctx) -> Result<Report, String> {
    let http = client(2)?;
    let mut statuses = BTreeMap::new();
    let t = Instant::now();
    let mut k = 0u64;
    while t.elapsed() < Duration::from_secs(10) {
        let body = json!({"name": format!("claim{k}")});
        k += 1;
        let status = status_of(http.post(ctx.url("/api/names")).json(&body).send().await);
        *statuses.entry(status).or_insert(0) += 1;
    }
    Ok((tally(&statuses), None, format!("{k} claims sent")))
}
