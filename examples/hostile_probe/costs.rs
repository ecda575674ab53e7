//! Classes that cost on a match's own thread rather than at creation: robots' waypoints (a
//! path search each) and the commands a match records for its replay. Each answers its
//! statuses, its time and a note, which `classes.rs` reports as an outcome.

use std::collections::BTreeMap;
use std::time::Instant;

use crate::harness::{Ctx, ms_since};
use serde_json::json;

/// What a class's requests got: statuses, milliseconds and a note.
pub(crate) type Got = (String, f64, String);

/// Statuses as `n×status`, in order.
pub(crate) fn tally(statuses: &BTreeMap<u16, usize>) -> String {
    let s: Vec<String> = statuses.iter().map(|(s, n)| format!("{n}×{s}")).collect();
    s.join(", ")
}

/// Sixteen waypoints between the far corners of a 500 m map (400,000 grid cells), sent
/// again and again to a manual match whose robots take orders: each would search the grid
/// sixteen times.
pub(crate) async fn command_cost(ctx: &Ctx) -> Result<Got, String> {
    const TRIES: usize = 20;
    let map = json!({"name": "big", "width": 500.0, "height": 500.0, "obstacles": [],
                     "robot_spawns": [[2.0, 2.0, 0.0]], "opponent_spawns": [[498.0, 498.0]]});
    let body = json!({"map": map, "robots": 1, "opponents": 1, "planner": "api",
                      "clock": "manual"});
    let (_, id, token) = ctx.create(&body).await?;
    let points: Vec<[f64; 2]> = (0..16)
        .map(|k| {
            if k % 2 == 0 {
                [498.0, 498.0]
            } else {
                [2.0, 2.0]
            }
        })
        .collect();
    let command = json!({ "waypoints": points });
    let path = format!("/api/matches/{id}/robots/r0/command");
    let mut statuses = BTreeMap::new();
    let mut slowest: f64 = 0.0;
    let mut first_refusal = None;
    let t = Instant::now();
    for _ in 0..TRIES {
        let a = ctx.post(&path, &command, token.as_deref()).await?;
        slowest = slowest.max(a.ms);
        *statuses.entry(a.status).or_default() += 1;
        if a.status != 204 && first_refusal.is_none() {
            first_refusal = Some(a.gist());
        }
    }
    Ok((
        tally(&statuses),
        ms_since(t) / TRIES as f64,
        format!(
            "{TRIES} commands of 16 far waypoints on a 500 m map; slowest {slowest:.0} ms; first refusal: {}",
            first_refusal.unwrap_or_else(|| "none".into())
        ),
    ))
}

/// An opponent's command of 1,000 waypoints on `office` (~12 KB of JSON).
fn thousand_waypoints() -> serde_json::Value {
    let route: Vec<[f64; 2]> = (0..1000)
        .map(|k| [2.0 + (k % 20) as f64, 2.0 + (k / 100) as f64])
        .collect();
    json!({ "waypoints": route })
}

/// Commands of 1,000 waypoints to an API-driven opponent until the match refuses them (or
/// 2,000 were taken): what the match records for its replay grows with each.
pub(crate) async fn inputs_growth(ctx: &Ctx) -> Result<Got, String> {
    const MOST: usize = 2_000;
    let body = json!({"map": "office", "opponents": 1, "opponent_control": "api",
                      "clock": "manual"});
    let (_, id, token) = ctx.create(&body).await?;
    let command = thousand_waypoints();
    let path = format!("/api/matches/{id}/opponents/o0/command");
    let mut statuses = BTreeMap::new();
    let mut refusal = None;
    let t = Instant::now();
    for _ in 0..MOST {
        let a = ctx.post(&path, &command, token.as_deref()).await?;
        *statuses.entry(a.status).or_default() += 1;
        if a.status != 204 {
            refusal = Some(a.gist());
            break;
        }
    }
    Ok((
        tally(&statuses),
        ms_since(t),
        format!(
            "1,000-waypoint commands (~12 KB each); refused with: {}",
            refusal.unwrap_or_else(|| "never".into())
        ),
    ))
}

/// 4,000 commands of 1,000 waypoints (~12 KB each) to an API-driven opponent of a real-time
/// match, then the match deleted: what the live match holds of them in memory (the row's
/// peak), and what it leaves once gone (the row's RSS after).
pub(crate) async fn command_memory(ctx: &Ctx) -> Result<Got, String> {
    const COMMANDS: usize = 4_000;
    let body = json!({"map": "office", "opponents": 1, "opponent_control": "api",
                      "planner": "idle", "time_limit_s": 3600});
    let (_, id, token) = ctx.create(&body).await?;
    let command = thousand_waypoints();
    let path = format!("/api/matches/{id}/opponents/o0/command");
    let mut statuses = BTreeMap::new();
    let mut refusal = None;
    let t = Instant::now();
    // Within the server's 100 requests a second per client: the commands themselves, not
    // the rate limit, are what is measured.
    let mut pace = tokio::time::interval(std::time::Duration::from_millis(12));
    for _ in 0..COMMANDS {
        pace.tick().await;
        let a = ctx.post(&path, &command, token.as_deref()).await?;
        *statuses.entry(a.status).or_default() += 1;
        if a.status != 204 {
            refusal = Some(a.gist());
            break;
        }
    }
    let request_ms = ms_since(t);
    let taken = crate::harness::rss_kib(ctx.pid);
    pace.tick().await;
    let last = ctx.public_tick(&id).await?.saturating_sub(1);
    pace.tick().await;
    let deleted = crate::harness::send(Ctx::with_token(
        ctx.http.delete(ctx.url(&format!("/api/matches/{id}"))),
        token.as_deref(),
    ))
    .await?;
    // Its replay, read at its end and its middle: the commands come back from the store.
    let mut read = Vec::new();
    for tick in [last, last / 2] {
        pace.tick().await;
        let a = ctx
            .get(&format!("/api/replays/{id}/state?tick={tick}"))
            .await?;
        read.push(a.status);
    }
    let mib = |k: Option<u64>| k.map_or("?".into(), |k| format!("{:.0}", k as f64 / 1024.0));
    Ok((
        tally(&statuses),
        request_ms,
        format!(
            "{COMMANDS} commands of 1,000 waypoints into a real-time match; RSS {} MiB after them; refused with: {}; deleted: {}; its replay read at ticks {last} and {}: {read:?}, RSS {} MiB after",
            mib(taken),
            refusal.unwrap_or_else(|| "never".into()),
            deleted.status,
            last / 2,
            mib(crate::harness::rss_kib(ctx.pid)),
        ),
    ))
}
