//! Soak test: real-time matches with bots and people who come and go, for a long while.
//!
//! ```sh
//! cargo run --release --example soak -- --minutes 30        # the issue's acceptance run
//! cargo run --release --example soak -- --minutes 2         # a quick check
//! ```
//!
//! Bounded, loopback only, self-stopping. It starts the server in this process (127.0.0.1,
//! an ephemeral port, no showcase), keeps `--matches` real-time matches running (half with
//! bots people may take over, half with human slots; a match that ends is replaced, so the
//! server also sees matches created and cleaned up all the time), and runs `--clients`
//! WebSocket clients. Each client again and again picks a match, joins it as a player (a
//! third of the time) or spectates, reads snapshots, sends input at 10 Hz as a player, pings,
//! switches the belief on and off, and after a random while drops: half the time with a
//! close, half by cutting the TCP connection. It then comes back, as the same player within
//! or after the 30 s reconnect grace, or somewhere else. One message in 500 is deliberately
//! invalid, so the refusal path runs too (those are counted and should be all the refusals).
//!
//! Every `--sample-s` seconds it reads the server's resident memory (`/proc/self/status`:
//! the server shares this process with the clients, whose number stays the same), every
//! match's tick and stats and `/metrics`. A match stalled when it was running at two samples
//! and its tick did not advance between them. At the end it prints a summary (memory at
//! start and end, tick p99, late ticks, refused messages by reason, stalls) and exits with
//! status 1 if any match stalled or the server stopped answering.
//!
//! Long file: a measurement program, one scenario read from top to bottom.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use clap::Parser;
use futures_util::{SinkExt, StreamExt};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

#[derive(Debug, Parser)]
#[command(about = "Soak test: real-time matches and clients that come and go, on loopback")]
struct Args {
    /// Minutes to run (1..=600).
    #[arg(long, default_value_t = 30)]
    minutes: u64,
    /// Real-time matches kept running (2..=300).
    #[arg(long, default_value_t = 20)]
    matches: usize,
    /// WebSocket clients (1..=2000).
    #[arg(long, default_value_t = 200)]
    clients: usize,
    /// Seconds between samples of memory, ticks and metrics (2..=300).
    #[arg(long, default_value_t = 10)]
    sample_s: u64,
    /// Seed of the clients' choices and the matches' seeds.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Directory of map files.
    #[arg(long, default_value = "maps")]
    maps: PathBuf,
    /// Snapshot format the clients ask for: `json` or `compact` (the game page's).
    #[arg(long, default_value = "json", value_parser = ["json", "compact"])]
    format: String,
    /// The history's data directory (default: a new one under the system's temporary
    /// directory, removed at the end).
    #[arg(long)]
    data_dir: Option<PathBuf>,
    /// Megabytes of recorded matches the history keeps.
    #[arg(long, default_value_t = 1024)]
    keep_mb: u64,
}

/// The shipped maps the matches rotate over.
const MAPS: [&str; 3] = ["office", "warehouse", "maze"];
/// One client message in this many is deliberately invalid.
const JUNK_EVERY: u64 = 500;

/// Counters the clients share.
#[derive(Debug, Default)]
struct Counts {
    sessions: AtomicU64,
    player_sessions: AtomicU64,
    reconnects_same_token: AtomicU64,
    join_refused: AtomicU64,
    connect_failed: AtomicU64,
    closed_by_server: AtomicU64,
    snapshots: AtomicU64,
    messages_sent: AtomicU64,
    junk_sent: AtomicU64,
    errors_received: AtomicU64,
    /// `error` messages by text, digits left out (`input: o has been tagged`).
    error_kinds: Mutex<HashMap<String, u64>>,
}

/// The matches running now, by id (what clients pick from).
type Live = Arc<Mutex<Vec<String>>>;

fn live_ids(live: &Live) -> Vec<String> {
    live.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

fn resident_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse().ok())
        })
        .unwrap_or(0)
}

async fn create_match(
    http: &reqwest::Client,
    base: &str,
    k: u64,
    humans: bool,
) -> Result<(String, String), String> {
    let map = MAPS[(k as usize) % MAPS.len()];
    // Bots: 2 robots hunt 3 evading bots that people may take over. Humans: 4 human slots
    // (an empty slot stands still), so the robots have something to do even when nobody
    // plays. Long time limits: matches end when the robots win, not by the clock. People
    // may join both, so the server chooses their (secret) seeds.
    let body = if humans {
        json!({"map": map, "robots": 2, "opponents": 4, "opponent_control": "human",
               "planner": "coordinated", "time_limit_s": 3600.0})
    } else {
        json!({"map": map, "robots": 2, "opponents": 3, "opponent_bot": "evade",
               "bots_joinable": true, "planner": "coordinated", "time_limit_s": 3600.0})
    };
    let r = http
        .post(format!("{base}/api/matches"))
        .json(&body)
        .send()
        .await
        .map_err(|e| e.to_string())?;
    let status = r.status();
    let v: Value = r.json().await.map_err(|e| e.to_string())?;
    match (v["id"].as_str(), v["owner_token"].as_str()) {
        (Some(id), Some(token)) if status == 201 => Ok((id.to_string(), token.to_string())),
        _ => Err(format!("creating a match: {status} {v}")),
    }
}

/// One client: sessions until `until`, each on a match it picks, as player or spectator.
async fn client(
    k: usize,
    addr: SocketAddr,
    live: Live,
    until: Instant,
    seed: u64,
    counts: Arc<Counts>,
    compact: bool,
) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ (k as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15));
    let http = reqwest::Client::new();
    let base = format!("http://{addr}");
    // A player's seat to come back to: (match, token).
    let mut seat: Option<(String, String)> = None;
    // Spread the first connections over the first seconds.
    tokio::time::sleep(Duration::from_millis(rng.random_range(0..3000))).await;
    while Instant::now() < until {
        // Come back to the same seat half the time; otherwise pick anew.
        let (id, token) = match seat.take() {
            Some((id, token)) if rng.random_bool(0.5) => {
                counts.reconnects_same_token.fetch_add(1, Ordering::Relaxed);
                (id, Some(token))
            }
            _ => {
                let ids = live_ids(&live);
                if ids.is_empty() {
                    tokio::time::sleep(Duration::from_millis(500)).await;
                    continue;
                }
                let id = ids[rng.random_range(0..ids.len())].clone();
                let mut token = None;
                if rng.random_bool(1.0 / 3.0) {
                    let r = http
                        .post(format!("{base}/api/matches/{id}/players"))
                        .json(&json!({"name": format!("soak{k}")}))
                        .send()
                        .await;
                    match r {
                        Ok(r) if r.status() == 201 => {
                            let v: Value = r.json().await.unwrap_or_default();
                            token = v["token"].as_str().map(str::to_string);
                        }
                        // No free slot, or the match just ended: spectate instead.
                        _ => {
                            counts.join_refused.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                }
                (id, token)
            }
        };
        let session = Duration::from_millis(rng.random_range(2_000..60_000));
        let end = (Instant::now() + session).min(until);
        let kept = session_run(addr, &id, token.as_deref(), end, &mut rng, &counts, compact).await;
        if kept && let Some(token) = token {
            seat = Some((id, token));
        }
        // Away for a while: sometimes past the reconnect grace (30 s), so slots get freed.
        let away = if rng.random_bool(0.1) {
            rng.random_range(25_000..40_000)
        } else {
            rng.random_range(100..3_000)
        };
        tokio::time::sleep(
            Duration::from_millis(away).min(until.saturating_duration_since(Instant::now())),
        )
        .await;
    }
}

/// One connection until `end`. Returns whether the seat is worth coming back to (the match
/// had not ended and the server had not refused or closed us).
async fn session_run(
    addr: SocketAddr,
    id: &str,
    token: Option<&str>,
    end: Instant,
    rng: &mut ChaCha8Rng,
    counts: &Counts,
    compact: bool,
) -> bool {
    let format = if compact {
        "format=compact"
    } else {
        "format=json"
    };
    let url = match token {
        Some(t) => format!("ws://{addr}/ws/matches/{id}?token={t}&{format}"),
        None => format!("ws://{addr}/ws/matches/{id}?{format}"),
    };
    let Ok((ws, _)) =
        tokio_tungstenite::connect_async_with_config(url, Some(lean_client()), true).await
    else {
        counts.connect_failed.fetch_add(1, Ordering::Relaxed);
        return false;
    };
    counts.sessions.fetch_add(1, Ordering::Relaxed);
    if token.is_some() {
        counts.player_sessions.fetch_add(1, Ordering::Relaxed);
    }
    let (mut tx, mut rx) = ws.split();
    let mut every = tokio::time::interval(Duration::from_millis(100));
    let mut kept = true;
    let mut sent = 0u64;
    loop {
        tokio::select! {
            _ = tokio::time::sleep_until(end.into()) => break,
            m = rx.next() => match m {
                Some(Ok(Message::Text(t))) => {
                    let t = t.as_str();
                    if t.starts_with("{\"type\":\"snapshot\"") {
                        counts.snapshots.fetch_add(1, Ordering::Relaxed);
                    } else if t.starts_with("{\"type\":\"error\"") {
                        counts.errors_received.fetch_add(1, Ordering::Relaxed);
                        let why = serde_json::from_str::<Value>(t)
                            .ok()
                            .and_then(|v| v["error"].as_str().map(str::to_string))
                            .unwrap_or_default();
                        let kind: String = why.chars().filter(|c| !c.is_ascii_digit()).take(60).collect();
                        *counts
                            .error_kinds
                            .lock()
                            .unwrap_or_else(|e| e.into_inner())
                            .entry(kind)
                            .or_default() += 1;
                    }
                }
                // A compact snapshot (the only binary message).
                Some(Ok(Message::Binary(_))) => {
                    counts.snapshots.fetch_add(1, Ordering::Relaxed);
                }
                Some(Ok(Message::Close(_))) | None | Some(Err(_)) => {
                    counts.closed_by_server.fetch_add(1, Ordering::Relaxed);
                    kept = false;
                    break;
                }
                Some(Ok(_)) => {}
            },
            _ = every.tick() => {
                sent += 1;
                let msg = if sent.is_multiple_of(JUNK_EVERY) {
                    counts.junk_sent.fetch_add(1, Ordering::Relaxed);
                    r#"{"type":"input","forward":2,"turn":0}"#.to_string()
                } else if token.is_some() {
                    format!(
                        r#"{{"type":"input","forward":{:.2},"turn":{:.2},"tag":{}}}"#,
                        rng.random_range(-1.0..=1.0f64),
                        rng.random_range(-1.0..=1.0f64),
                        rng.random_bool(0.05)
                    )
                } else if sent.is_multiple_of(20) {
                    format!(r#"{{"type":"belief","on":{}}}"#, rng.random_bool(0.5))
                } else if sent.is_multiple_of(10) {
                    format!(r#"{{"type":"ping","t":{sent}}}"#)
                } else {
                    continue; // spectators send a message a second or so
                };
                counts.messages_sent.fetch_add(1, Ordering::Relaxed);
                if tx.send(Message::text(msg)).await.is_err() {
                    kept = false;
                    break;
                }
            }
        }
    }
    // Drop: a clean close half the time, a cut connection the other half.
    if rng.random_bool(0.5) {
        let _ = tx.send(Message::Close(None)).await;
        let _ = tokio::time::timeout(Duration::from_secs(1), rx.next()).await;
    }
    kept
}

/// What one sample reads.
#[derive(Debug, Default)]
struct Sample {
    /// Running matches and their ticks.
    ticks: HashMap<String, u64>,
    /// Each running match's p99 tick compute over its last 4,096 ticks (µs).
    p99_us: Vec<f64>,
    max_us: f64,
    refused: HashMap<String, u64>,
    late_ticks: u64,
    clients: u64,
    /// `lasertag_tick_seconds` for real-time matches, summed over planners: (le, count).
    tick_buckets: Vec<(f64, u64)>,
}

fn metric_value(line: &str) -> Option<u64> {
    line.rsplit(' ')
        .next()?
        .parse::<f64>()
        .ok()
        .map(|v| v as u64)
}

fn label<'a>(line: &'a str, name: &str) -> Option<&'a str> {
    let i = line.find(&format!("{name}=\""))? + name.len() + 2;
    let rest = &line[i..];
    Some(&rest[..rest.find('"')?])
}

async fn sample(http: &reqwest::Client, base: &str) -> Result<Sample, String> {
    let mut s = Sample::default();
    let list: Vec<Value> = http
        .get(format!("{base}/api/matches"))
        .send()
        .await
        .map_err(|e| e.to_string())?
        .json()
        .await
        .map_err(|e| e.to_string())?;
    for m in &list {
        let (Some(id), Some(tick)) = (m["id"].as_str(), m["tick"].as_u64()) else {
            continue;
        };
        if m["status"] != "running" {
            continue;
        }
        s.ticks.insert(id.to_string(), tick);
        if let Ok(r) = http
            .get(format!("{base}/api/matches/{id}/stats"))
            .send()
            .await
            && let Ok(v) = r.json::<Value>().await
        {
            s.p99_us.push(v["tick_us_p99"].as_f64().unwrap_or(0.0));
            s.max_us = s.max_us.max(v["tick_us_max"].as_f64().unwrap_or(0.0));
        }
    }
    let text = http
        .get(format!("{base}/metrics"))
        .send()
        .await
        .map_err(|e| e.to_string())?
        .text()
        .await
        .map_err(|e| e.to_string())?;
    let mut buckets: HashMap<String, u64> = HashMap::new();
    for line in text.lines() {
        if line.starts_with("lasertag_refused_total{") {
            if let (Some(reason), Some(v)) = (label(line, "reason"), metric_value(line)) {
                s.refused.insert(reason.to_string(), v);
            }
        } else if line.starts_with("lasertag_late_ticks_total ") {
            s.late_ticks = metric_value(line).unwrap_or(0);
        } else if line.starts_with("lasertag_clients{") {
            s.clients += metric_value(line).unwrap_or(0);
        } else if line.starts_with("lasertag_tick_seconds_bucket{")
            && label(line, "clock") == Some("realtime")
            && let (Some(le), Some(v)) = (label(line, "le"), metric_value(line))
        {
            *buckets.entry(le.to_string()).or_default() += v;
        }
    }
    s.tick_buckets = buckets
        .into_iter()
        .map(|(le, n)| (le.parse::<f64>().unwrap_or(f64::INFINITY), n))
        .collect();
    s.tick_buckets.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(s)
}

/// The smallest bucket bound under which `q` of the observations fall (cumulative buckets).
fn bucket_quantile(buckets: &[(f64, u64)], q: f64) -> f64 {
    let total = buckets.last().map_or(0, |b| b.1);
    let want = (total as f64 * q).ceil() as u64;
    buckets
        .iter()
        .find(|(_, n)| *n >= want)
        .map_or(f64::NAN, |b| b.0)
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

async fn run(args: Args) -> Result<bool, String> {
    if !(1..=600).contains(&args.minutes)
        || !(2..=300).contains(&args.matches)
        || !(1..=2000).contains(&args.clients)
        || !(2..=300).contains(&args.sample_s)
    {
        return Err(
            "--minutes 1..=600, --matches 2..=300, --clients 1..=2000, --sample-s 2..=300".into(),
        );
    }
    let maps =
        lasertag::maps::MapStore::load_dir(&args.maps).map_err(|e| format!("loading maps: {e}"))?;
    // Every client comes from 127.0.0.1: lift the per-address caps that would refuse a load
    // test of one machine, and the tick and memory budgets, which admission prices below
    // what the soak runs at its largest (100 matches). The rest (message rate, sizes,
    // graces) are the defaults. The allocator policy is the server's `main`'s.
    lasertag::http::trim_memory_periodically();
    let config = lasertag::config::Config {
        max_matches: 1_000,
        tick_budget_ms: 1e6,
        memory_budget_mb: 1 << 20,
        max_connections_per_address: usize::MAX,
        max_spectators_per_address: usize::MAX,
        max_seats_per_address: usize::MAX,
        max_matches_per_address: usize::MAX,
        client_budget_share: 1.0,
        requests_per_s: 1e6,
        request_burst: 1e6,
        ..lasertag::config::Config::default()
    };
    let temporary = args.data_dir.is_none();
    let data_dir = args.data_dir.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("lasertag-soak-{}", std::process::id()))
    });
    let store = lasertag::store::Store::open(
        &data_dir,
        lasertag::store::Retention {
            max_matches: 1_000_000,
            max_bytes: args.keep_mb << 20,
        },
    )
    .map_err(|e| e.to_string())?;
    let history = lasertag::game::replay::History::with_store(store);
    let registry = lasertag::game::Registry::with_history(maps, config, history);
    let app = lasertag::http::app(registry.clone(), PathBuf::from("web"))
        .into_make_service_with_connect_info::<SocketAddr>();
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .map_err(|e| e.to_string())?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    tokio::spawn(async move { axum::serve(listener, app).await });
    let base = format!("http://{addr}");
    let http = reqwest::Client::new();

    let rss_before = resident_kib();
    let live: Live = Arc::default();
    let mut next_seed = args.seed.wrapping_mul(1000);
    // Which matches have human slots (the rest have bots), so replacements keep the mix.
    // And each match's owner token, to delete it.
    let mut kinds: HashMap<String, (bool, String)> = HashMap::new();
    for i in 0..args.matches {
        let humans = i % 2 == 1;
        let (id, token) = create_match(&http, &base, next_seed, humans).await?;
        next_seed += 1;
        kinds.insert(id.clone(), (humans, token));
        live.lock().unwrap_or_else(|e| e.into_inner()).push(id);
    }
    let started = Instant::now();
    let until = started + Duration::from_secs(args.minutes * 60);
    println!(
        "soak: {} real-time matches (half with bots people may take over, half with human slots), {} clients, {} min, server {addr}",
        args.matches, args.clients, args.minutes
    );
    let counts = Arc::new(Counts::default());
    let clients: Vec<_> = (0..args.clients)
        .map(|k| {
            tokio::spawn(client(
                k,
                addr,
                live.clone(),
                until,
                args.seed,
                counts.clone(),
                args.format == "compact",
            ))
        })
        .collect();

    // Sample until the end; replace matches that finished.
    let mut prev: Option<Sample> = None;
    let mut rss_start: Option<u64> = None;
    let mut stalls: Vec<String> = Vec::new();
    let mut p99_all: Vec<f64> = Vec::new();
    let mut max_us: f64 = 0.0;
    let mut replaced = 0u64;
    let mut unanswered = 0u64;
    let mut rss_peak = 0u64;
    let mut samples = 0u64;
    loop {
        let now = Instant::now();
        if now >= until {
            break;
        }
        tokio::time::sleep(Duration::from_secs(args.sample_s).min(until - now)).await;
        let s = match sample(&http, &base).await {
            Ok(s) => s,
            Err(e) => {
                eprintln!("sample failed: {e}");
                unanswered += 1;
                continue;
            }
        };
        samples += 1;
        let rss = resident_kib();
        rss_peak = rss_peak.max(rss);
        if let Some(p) = &prev {
            for (id, tick) in &s.ticks {
                if let Some(before) = p.ticks.get(id)
                    && tick <= before
                {
                    stalls.push(format!(
                        "{id} at tick {tick} (t = {:.0} s)",
                        started.elapsed().as_secs_f64()
                    ));
                }
            }
        }
        p99_all.extend(&s.p99_us);
        max_us = max_us.max(s.max_us);
        // Matches that are no longer running (robots won, or abandoned) are replaced.
        let mut ids = live_ids(&live);
        let gone: Vec<String> = ids
            .iter()
            .filter(|id| !s.ticks.contains_key(*id))
            .cloned()
            .collect();
        for id in &gone {
            let (humans, token) = kinds.remove(id).unwrap_or_default();
            let _ = http
                .delete(format!("{base}/api/matches/{id}"))
                .bearer_auth(token)
                .send()
                .await;
            match create_match(&http, &base, next_seed, humans).await {
                Ok((new, token)) => {
                    kinds.insert(new.clone(), (humans, token));
                    ids.push(new);
                    replaced += 1;
                }
                Err(e) => eprintln!("replacing {id}: {e}"),
            }
            next_seed += 1;
        }
        ids.retain(|id| !gone.contains(id));
        *live.lock().unwrap_or_else(|e| e.into_inner()) = ids;
        println!(
            "t={:>5.0}s rss {:>7} KiB  running {:>3}  clients {:>4}  p99 median {:>6.0} µs  late {:>5}  refused {:?}",
            started.elapsed().as_secs_f64(),
            rss,
            s.ticks.len(),
            s.clients,
            median(s.p99_us.clone()),
            s.late_ticks,
            s.refused
                .iter()
                .filter(|(_, v)| **v > 0)
                .collect::<Vec<_>>()
        );
        rss_start.get_or_insert(rss);
        prev = Some(s);
    }
    for c in clients {
        let _ = c.await;
    }
    let last = sample(&http, &base).await.ok();
    let rss_end = resident_kib();
    for id in live_ids(&live) {
        let token = kinds.get(&id).map(|k| k.1.clone()).unwrap_or_default();
        let _ = http
            .delete(format!("{base}/api/matches/{id}"))
            .bearer_auth(token)
            .send()
            .await;
    }
    tokio::time::sleep(Duration::from_secs(2)).await;
    let rss_after_cleanup = resident_kib();
    let rss_start = rss_start.unwrap_or(rss_before);

    let c = &counts;
    let get = |a: &AtomicU64| a.load(Ordering::Relaxed);
    println!(
        "\nsoak summary ({} min, {} samples):",
        args.minutes, samples
    );
    println!(
        "  resident memory  before the matches {rss_before} KiB; at the first sample {rss_start} KiB; at the end {rss_end} KiB; peak {rss_peak} KiB; after deleting the matches {rss_after_cleanup} KiB"
    );
    if let Some(l) = &last {
        println!(
            "  tick compute     p99 per match (last 4,096 ticks): median over samples {:.0} µs, worst {:.0} µs; max {:.0} µs; all real-time ticks of the run: p50 ≤ {} s, p99 ≤ {} s (histogram bucket bounds)",
            median(p99_all.clone()),
            p99_all.iter().cloned().fold(0.0, f64::max),
            max_us,
            bucket_quantile(&l.tick_buckets, 0.5),
            bucket_quantile(&l.tick_buckets, 0.99)
        );
        println!(
            "  late ticks       {} (a tick more than half a period late)",
            l.late_ticks
        );
        let mut refused: Vec<_> = l.refused.iter().filter(|(_, v)| **v > 0).collect();
        refused.sort();
        println!(
            "  refused          {:?}; deliberately invalid messages sent: {}",
            refused,
            get(&c.junk_sent)
        );
    }
    println!(
        "  clients          {} sessions ({} as players, {} back on the same token), {} joins refused (no free slot), {} connections refused, {} closed by the server",
        get(&c.sessions),
        get(&c.player_sessions),
        get(&c.reconnects_same_token),
        get(&c.join_refused),
        get(&c.connect_failed),
        get(&c.closed_by_server)
    );
    println!(
        "  traffic          {} snapshots received, {} messages sent, {} errors received",
        get(&c.snapshots),
        get(&c.messages_sent),
        get(&c.errors_received)
    );
    let mut kinds: Vec<_> = c
        .error_kinds
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .map(|(k, v)| (*v, k.clone()))
        .collect();
    kinds.sort_by(|a, b| b.cmp(a));
    for (n, kind) in kinds.iter().take(6) {
        println!("    {n:>8} × error {kind:?}");
    }
    println!("  matches          {replaced} ended and were replaced");
    if let Some(store) = registry.history.store() {
        let _ = store.flush(Duration::from_secs(10));
        let (kept, bytes) = store.read(|b| b.totals()).unwrap_or_default();
        println!(
            "  history          {kept} matches stored, {:.2} MB of recordings, database files {:.2} MB",
            bytes as f64 / 1e6,
            store.file_bytes() as f64 / 1e6
        );
    }
    if temporary {
        let _ = std::fs::remove_dir_all(&data_dir);
    }
    if stalls.is_empty() && unanswered == 0 {
        println!("  stalls           none: every running match advanced in every interval");
        Ok(true)
    } else {
        println!(
            "  stalls           {} ({unanswered} samples unanswered): {:?}",
            stalls.len(),
            stalls
        );
        Ok(false)
    }
}

fn main() -> std::process::ExitCode {
    let args = Args::parse();
    let rt = match tokio::runtime::Runtime::new() {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("error: {e}");
            return std::process::ExitCode::FAILURE;
        }
    };
    match rt.block_on(run(args)) {
        Ok(true) => std::process::ExitCode::SUCCESS,
        Ok(false) => std::process::ExitCode::FAILURE,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// A client that reads 4 KiB at a time: tungstenite's default 128 KiB read buffer is zeroed
/// on every read, and thousands of clients on the server's own cores would measure that
/// rather than the server (a browser has no such cost).
fn lean_client() -> tokio_tungstenite::tungstenite::protocol::WebSocketConfig {
    tokio_tungstenite::tungstenite::protocol::WebSocketConfig::default().read_buffer_size(4 << 10)
}
