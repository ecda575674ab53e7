//! The classes of the history's doors: replays re-simulated by strangers while a visitor
//! creates a match, a replay of a big match read once, and a stream of matches with large
//! maps against a small history (`--keep-mb 1`).

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use crate::costs::tally;
use crate::doors::{Report, client, replay};
use crate::harness::{Ctx, dir_bytes, empty_map, ms_since, r3, rss_kib, send};
use serde_json::{Value, json};

/// Ends the match `id` (its owner's `DELETE`), which puts it in the history.
async fn end(ctx: &Ctx, id: &str, token: Option<&str>) -> Result<(), String> {
    let a = send(Ctx::with_token(
        ctx.http.delete(ctx.url(&format!("/api/matches/{id}"))),
        token,
    ))
    .await?;
    match a.status {
        200..=299 => Ok(()),
        s => Err(format!("DELETE /api/matches/{id}: {s} {}", a.gist())),
    }
}

/// Two finished matches of 6,000 ticks, then strangers (127.0.0.2 and .3) read each replay
/// at its end and its middle, every read a re-simulation, while a visitor from 127.0.0.1
/// creates (and ends) a small match every 300 ms: how long creation waits behind replays.
pub(crate) async fn replay_cost(ctx: &Ctx) -> Result<Report, String> {
    let ids = [replay(ctx).await?, replay(ctx).await?];
    let mut reads = Vec::new();
    for (k, id) in ids.iter().enumerate() {
        for (from, tick) in [(2u8, 6000), (3, 3000)] {
            let stranger = client(from + k as u8 * 2)?;
            let url = ctx.url(&format!("/api/replays/{id}/state?tick={tick}"));
            reads.push(tokio::spawn(async move {
                let t = Instant::now();
                let status = match stranger.get(url).send().await {
                    Ok(r) => r.status().as_u16(),
                    Err(_) => 0,
                };
                (status, ms_since(t))
            }));
        }
    }
    let mut creations = Vec::new();
    while !reads.iter().all(|r| r.is_finished()) && Instant::now() < ctx.give_up {
        let (a, id, token) = ctx
            .create(&json!({"map": "office", "planner": "idle"}))
            .await?;
        creations.push(a.ms);
        end(ctx, &id, token.as_deref()).await?;
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    let mut statuses = BTreeMap::new();
    let mut slowest_read: f64 = 0.0;
    for r in reads {
        let (status, ms) = r.await.map_err(|e| e.to_string())?;
        *statuses.entry(status).or_insert(0) += 1;
        slowest_read = slowest_read.max(ms);
    }
    let slowest_creation = creations.iter().copied().fold(0.0, f64::max);
    Ok((
        tally(&statuses),
        Some(slowest_creation),
        format!(
            "4 replay reads of 6,000-tick matches from strangers, slowest {slowest_read:.0} ms; \
             {} creations meanwhile, slowest {slowest_creation:.0} ms (the request ms)",
            creations.len()
        ),
    ))
}

/// The biggest of a few matches the server admits (a large open map, many agents, a lossy
/// radio: a tracker per robot, a fine merge grid), stepped 1,000 ticks and ended, then read
/// once at its end and once at its middle by a stranger: what the reads cost in memory, and
/// what they leave behind (the row's RSS after).
pub(crate) async fn replay_memory(ctx: &Ctx) -> Result<Report, String> {
    const TICKS: u64 = 1000;
    let candidates = [
        (200.0, 8, 8, 0.1),
        (100.0, 8, 8, 0.25),
        (60.0, 6, 6, 0.5),
        (60.0, 4, 4, 0.5),
        (60.0, 4, 4, 1.0),
    ];
    let mut made = None;
    let mut refusals = Vec::new();
    for (side, robots, opponents, cell) in candidates {
        let what = format!("{side} m, {robots}+{opponents}, {cell} m grid");
        let map = empty_map(side);
        let body = json!({"map": map, "robots": robots, "opponents": opponents,
                          "opponent_control": "api", "clock": "manual",
                          "radio": {"loss": 0.5}, "tracker": {"grid_cell": cell},
                          "time_limit_s": 600});
        let a = ctx.post("/api/matches", &body, None).await?;
        match a.body["id"].as_str() {
            Some(id) if a.status == 201 => {
                let token = a.body["owner_token"].as_str().map(str::to_string);
                made = Some((id.to_string(), token, what));
                break;
            }
            _ => refusals.push(format!("{what}: {}", a.status)),
        }
    }
    let Some((id, token, what)) = made else {
        return Ok((
            "refused".into(),
            None,
            format!("no big match admitted: {}", refusals.join("; ")),
        ));
    };
    let step = Ctx::with_token(
        ctx.http.post(ctx.url(&format!("/api/matches/{id}/step"))),
        token.as_deref(),
    )
    .json(&json!({ "ticks": TICKS }));
    let stepped = send(step).await?;
    if stepped.status != 200 {
        return Err(format!("stepping: {} {}", stepped.status, stepped.gist()));
    }
    end(ctx, &id, token.as_deref()).await?;
    let before = rss_kib(ctx.pid);
    let stranger = client(2)?;
    let mut statuses = BTreeMap::new();
    let t = Instant::now();
    for tick in [TICKS, TICKS / 2] {
        let r = stranger
            .get(ctx.url(&format!("/api/replays/{id}/state?tick={tick}")))
            .send()
            .await;
        let status = match r {
            Ok(r) => {
                let s = r.status().as_u16();
                let _ = r.bytes().await;
                s
            }
            Err(_) => 0,
        };
        *statuses.entry(status).or_insert(0) += 1;
    }
    let ms = ms_since(t);
    let mib = |k: Option<u64>| k.map_or("?".into(), |k| format!("{:.0}", k as f64 / 1024.0));
    Ok((
        tally(&statuses),
        Some(ms),
        format!(
            "a {TICKS}-tick match ({what}{}) read at ticks {TICKS} and {}; RSS {} MiB before the reads, {} just after",
            if refusals.is_empty() {
                String::new()
            } else {
                format!("; bigger ones refused: {}", refusals.join("; "))
            },
            TICKS / 2,
            mib(before),
            mib(rss_kib(ctx.pid)),
        ),
    ))
}

/// Thirty matches, each on an inline map of about 185 KB (a 200 m floor of 2,400 small
/// squares, each match's a little apart from the last's), created, stepped a little and ended, against a server started with `--keep-mb 1`: the
/// data directory's size after each (the writer commits about once a second), its largest
/// and its last.
pub(crate) async fn disk_maps(ctx: &Ctx) -> Result<Report, String> {
    const MATCHES: usize = 30;
    const KEEP_BYTES: f64 = 1024.0 * 1024.0;
    let mut map_bytes = 0;
    let mut statuses = BTreeMap::new();
    let mut largest = 0u64;
    let t = Instant::now();
    for k in 0..MATCHES {
        if Instant::now() > ctx.give_up {
            break;
        }
        // A map of its own: the same map twice could be stored once.
        let map = squares(2400, k);
        map_bytes = map.to_string().len();
        let body = json!({"map": map, "clock": "manual", "planner": "idle"});
        let a = ctx.post("/api/matches", &body, None).await?;
        *statuses.entry(a.status).or_insert(0) += 1;
        if a.status != 201 {
            continue;
        }
        let (Some(id), token) = (a.body["id"].as_str(), a.body["owner_token"].as_str()) else {
            continue;
        };
        let step = Ctx::with_token(
            ctx.http.post(ctx.url(&format!("/api/matches/{id}/step"))),
            token,
        )
        .json(&json!({"ticks": 20}));
        send(step).await?;
        end(ctx, id, token).await?;
        tokio::time::sleep(Duration::from_millis(1200)).await;
        largest = largest.max(dir_bytes(&ctx.data_dir));
    }
    let ms = ms_since(t);
    let last = dir_bytes(&ctx.data_dir);
    Ok((
        tally(&statuses),
        Some(ms),
        format!(
            "{MATCHES} matches with {:.0} KB inline maps at --keep-mb 1: data directory at most {:.0} KiB ({:.0}% of 1 MiB), {:.0} KiB at the end",
            map_bytes as f64 / 1000.0,
            largest as f64 / 1024.0,
            100.0 * largest as f64 / KEEP_BYTES,
            last as f64 / 1024.0,
        ),
    ))
}

/// A 200 m floor of `n` squares of 0.25 m on a lattice, shifted by `k` millimetres, with
/// coordinates to the millimetre: about 70 bytes a square.
fn squares(n: usize, k: usize) -> Value {
    let shift = k as f64 * 0.001;
    let k = (n as f64).sqrt().ceil() as usize;
    let s = 200.0 / k as f64;
    let obstacles: Vec<Value> = (0..n)
        .map(|i| {
            let (cx, cy) = (
                (i % k) as f64 * s + s / 2.0 + shift,
                (i / k) as f64 * s + s / 2.0,
            );
            let (x0, x1, y0, y1) = (
                r3(cx - 0.123),
                r3(cx + 0.123),
                r3(cy - 0.123),
                r3(cy + 0.123),
            );
            json!([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        })
        .collect();
    json!({"name": format!("squares-{k}"), "width": 200.0, "height": 200.0,
           "obstacles": obstacles, "robot_spawns": [[s, s / 2.0, 0.0]],
           "opponent_spawns": [[200.0 - s, 200.0 - s / 2.0]]})
}
