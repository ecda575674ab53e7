//! Load test of the WebSocket fan-out: real-time matches watched by many spectators.
//!
//! ```sh
//! cargo run --release --example loadtest -- --matches 20 --spectators 500 --seconds 30
//! ```
//!
//! Bounded and self-stopping, loopback only. By default it starts the server in this process
//! (on 127.0.0.1, an ephemeral port, no showcase); `--addr` points it at a server already
//! running on a loopback address instead. It creates the matches (warehouse, 2 robots with the
//! default planner and tracker against 3 evading bots, so that few matches end within the
//! window), spreads the spectators over them round-robin (belief on,
//! as spectators have it by default), reads for `--seconds`, then reports:
//! - each match's tick rate (its ticks over the time between its two reads of its stats, each
//!   timed at the middle of its round trip) and per-tick compute time (p50/p99/max, measured
//!   inside the match task: the step plus building the published frame; from
//!   `/api/matches/{id}/stats`) and its late ticks;
//! - snapshots per second per client (min, 1st percentile, median) and clients starved
//!   (under 15 Hz);
//! - bytes per snapshot, with and without the belief.
//!
//! The matches are deleted at the end.
//!
//! `--transport webtransport` watches over WebTransport instead (compact snapshots as
//! datagrams, each spectator acknowledging what it holds as the page does, so snapshots come
//! as deltas against those): the in-process server then also serves it in UDP, and the
//! spectators open their sessions 8 at a time (a client's handshakes in progress are capped).
//! A spectator whose session is refused (past `--max-webtransport-sessions`) watches over a
//! WebSocket, as the page does; the report says how many did.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[allow(dead_code)]
#[path = "../tests/common/wt.rs"]
mod wt;

use clap::Parser;
use futures_util::StreamExt;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

#[derive(Debug, Parser)]
#[command(about = "Load test: real-time matches and WebSocket spectators on loopback")]
struct Args {
    /// Real-time matches to run (1..=500).
    #[arg(long, default_value_t = 20)]
    matches: usize,
    /// WebSocket spectators, spread over the matches (0..=5000).
    #[arg(long, default_value_t = 500)]
    spectators: usize,
    /// Seconds to measure (1..=600).
    #[arg(long, default_value_t = 30)]
    seconds: u64,
    /// A running server to test (a loopback address); by default one is started in-process.
    #[arg(long)]
    addr: Option<SocketAddr>,
    /// Map of the matches (warehouse: big enough that few matches end within the window).
    #[arg(long, default_value = "warehouse")]
    map: String,
    /// Planner of the robots (coordinated, baseline or idle).
    #[arg(long, default_value = "coordinated")]
    planner: String,
    /// Bot opponents per match (evading bots, so that matches last).
    #[arg(long, default_value_t = 3)]
    opponents: usize,
    /// Snapshot format the spectators ask for: `json` or `compact` (the game page's).
    #[arg(long, default_value = "json", value_parser = ["json", "compact"])]
    format: String,
    /// Directory of map files (in-process server).
    #[arg(long, default_value = "maps")]
    maps: PathBuf,
    /// WebTransport sessions the in-process server takes (its `--max-webtransport-sessions`).
    #[arg(long, default_value_t = lasertag::config::defaults::MAX_WEBTRANSPORT_SESSIONS)]
    max_webtransport_sessions: usize,
    /// What the spectators watch over: `websocket` or `webtransport` (compact only).
    #[arg(long, default_value = "websocket", value_parser = ["websocket", "webtransport"])]
    transport: String,
}

/// Where WebTransport sessions open, and the hash to pin (`GET /api/transport`).
#[derive(Clone)]
struct Published {
    url: String,
    hash: wtransport::tls::Sha256Digest,
    /// Handshakes in progress at once (a client's are capped at 8 on the server).
    handshakes: std::sync::Arc<tokio::sync::Semaphore>,
    /// Spectators whose session was refused, watching over a WebSocket.
    fell_back: std::sync::Arc<std::sync::atomic::AtomicUsize>,
}

/// [`spectate`] over WebTransport: compact snapshots by datagram or on the stream, what is
/// held acknowledged every second one, as the page does; a session refused (the server's
/// sessions full) watches over a WebSocket instead, as the page does.
async fn spectate_webtransport(
    addr: SocketAddr,
    at: Published,
    id: String,
    until: Instant,
    start: Instant,
) -> ClientStats {
    let mut st = ClientStats::default();
    let url = format!("{}/ws/matches/{id}?format=compact", at.url);
    let connected = {
        let _permit = at.handshakes.acquire().await;
        wt::WtClient::connect(&url, &at.hash).await
    };
    let Ok(client) = connected else {
        at.fell_back
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        return spectate(addr, id, until, start, "compact").await;
    };
    let (mut snapshots, conn) = client.snapshots();
    let mut held = wt::Held::default();
    let mut last_tick = None;
    loop {
        let now = Instant::now();
        if now >= until {
            break;
        }
        let a = match tokio::time::timeout(until - now, snapshots.recv()).await {
            Err(_) => break,
            Ok(Some(a)) => a,
            Ok(None) => {
                st.closed_early = true;
                break;
            }
        };
        let (kind, flags, len) = (a.bytes[0], a.bytes.get(1).copied(), a.bytes.len() as u64);
        let tick = lasertag::protocol::compact::tick_of(&a.bytes);
        if let (Ok(Some(_)), Some(ack)) = (held.take(a.bytes), held.ack_due()) {
            let _ = conn.send_datagram(ack);
        }
        // Wholes and deltas (a motion part is followed by its whole).
        if Instant::now() >= start
            && matches!(kind, 1 | 2)
            && let (Some(t), Some(f)) = (tick, flags)
        {
            st.count(u64::from(t), &mut last_tick, f & 2 != 0, len);
        }
    }
    conn.close(0u32.into(), b"done");
    st
}

#[derive(Debug, Default, Clone)]
struct ClientStats {
    snapshots: u64,
    distinct_ticks: u64,
    bytes_plain: u64,
    n_plain: u64,
    bytes_belief: u64,
    n_belief: u64,
    max_belief: u64,
    max_plain: u64,
    events: u64,
    closed_early: bool,
}

fn tick_of(text: &str) -> Option<u64> {
    let i = text.find("\"tick\":")? + 7;
    let rest = &text[i..];
    let end = rest
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(rest.len());
    rest[..end].parse().ok()
}

async fn spectate(
    addr: SocketAddr,
    id: String,
    until: Instant,
    start: Instant,
    format: &str,
) -> ClientStats {
    let mut st = ClientStats::default();
    let url = format!("ws://{addr}/ws/matches/{id}?format={format}");
    let Ok((mut ws, _)) =
        tokio_tungstenite::connect_async_with_config(url, Some(lean_client()), true).await
    else {
        st.closed_early = true;
        return st;
    };
    let mut last_tick = None;
    loop {
        let now = Instant::now();
        if now >= until {
            break;
        }
        let msg = match tokio::time::timeout(until - now, ws.next()).await {
            Err(_) => break,
            Ok(Some(Ok(m))) => m,
            Ok(_) => {
                st.closed_early = true;
                break;
            }
        };
        if Instant::now() < start {
            continue; // warm-up: connecting clients
        }
        if let Message::Binary(b) = &msg {
            // A compact snapshot, whole (kind 1) or a delta (2): flags (2: with the
            // belief), the tick.
            if let (Some(1 | 2), Some(tick)) = (b.first(), lasertag::protocol::compact::tick_of(b))
            {
                st.count(
                    u64::from(tick),
                    &mut last_tick,
                    b[1] & 2 != 0,
                    b.len() as u64,
                );
            }
            continue;
        }
        let Message::Text(t) = msg else { continue };
        let text = t.as_str();
        if text.starts_with("{\"type\":\"snapshot\"") {
            if let Some(tick) = tick_of(text) {
                let belief = text.contains("\"belief\":");
                st.count(tick, &mut last_tick, belief, text.len() as u64);
            }
        } else if text.starts_with("{\"type\":\"event\"") {
            st.events += 1;
        }
    }
    let _ = ws.close(None).await;
    st
}

impl ClientStats {
    /// One snapshot of `len` bytes for `tick`.
    fn count(&mut self, tick: u64, last_tick: &mut Option<u64>, belief: bool, len: u64) {
        self.snapshots += 1;
        if *last_tick != Some(tick) {
            self.distinct_ticks += 1;
            *last_tick = Some(tick);
        }
        if belief {
            self.bytes_belief += len;
            self.n_belief += 1;
            self.max_belief = self.max_belief.max(len);
        } else {
            self.bytes_plain += len;
            self.n_plain += 1;
            self.max_plain = self.max_plain.max(len);
        }
    }
}

fn pct(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

async fn run(args: Args) -> Result<(), String> {
    if !(1..=500).contains(&args.matches)
        || args.spectators > 5000
        || !(1..=600).contains(&args.seconds)
    {
        return Err("--matches 1..=500, --spectators 0..=5000, --seconds 1..=600".into());
    }
    let addr = match args.addr {
        Some(a) if a.ip().is_loopback() => a,
        Some(a) => {
            return Err(format!(
                "{a} is not a loopback address: this test stays local"
            ));
        }
        None => {
            let maps = lasertag::maps::MapStore::load_dir(&args.maps)
                .map_err(|e| format!("loading maps: {e}"))?;
            // Every spectator comes from 127.0.0.1: lift the per-address and per-match caps
            // that would otherwise refuse a load test of one machine. The tick and memory
            // budgets are lifted too: admission would refuse matches past what it prices the
            // box at, and finding what the box really runs is this test's point.
            let config = lasertag::config::Config {
                max_matches: 1_000,
                tick_budget_ms: 1e6,
                memory_budget_mb: 1 << 20,
                max_connections_per_address: usize::MAX,
                max_spectators_per_match: usize::MAX,
                max_spectators_per_address: usize::MAX,
                max_matches_per_address: usize::MAX,
                client_budget_share: 1.0,
                requests_per_s: 1e6,
                request_burst: 1e6,
                max_webtransport_sessions: args.max_webtransport_sessions,
                ..lasertag::config::Config::default()
            };
            // The allocator policy the server's `main` sets.
            lasertag::http::trim_memory_periodically();
            let registry = lasertag::game::Registry::with_config(maps, config);
            let (app, state) = lasertag::http::app_and_state(registry, PathBuf::from("web"), None);
            let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
                .await
                .map_err(|e| e.to_string())?;
            let addr = listener.local_addr().map_err(|e| e.to_string())?;
            if args.transport == "webtransport" {
                let source = lasertag::http::transport::Source::SelfSigned;
                lasertag::http::transport::start(state, addr, source)
                    .await
                    .map_err(|e| e.to_string())?;
            }
            let app = app.into_make_service_with_connect_info::<std::net::SocketAddr>();
            tokio::spawn(async move { axum::serve(listener, app).await });
            addr
        }
    };
    let http = reqwest::Client::new();
    let base = format!("http://{addr}");
    let published = if args.transport == "webtransport" {
        if args.format != "compact" {
            return Err(
                "--transport webtransport watches compact snapshots: add --format compact".into(),
            );
        }
        let reply: Value = http
            .get(format!("{base}/api/transport"))
            .send()
            .await
            .map_err(|e| e.to_string())?
            .json()
            .await
            .map_err(|e| e.to_string())?;
        if reply["webtransport"].is_null() {
            return Err(format!("{base} offers no WebTransport"));
        }
        let (url, hash) = wt::published(&reply);
        Some(Published {
            url,
            hash,
            handshakes: std::sync::Arc::new(tokio::sync::Semaphore::new(8)),
            fell_back: Default::default(),
        })
    } else {
        None
    };
    let mut ids = Vec::new();
    let mut owner_tokens = Vec::new();
    for i in 0..args.matches {
        let body = json!({"map": args.map, "robots": 2, "opponents": args.opponents,
            "opponent_bot": "evade", "planner": args.planner,
            "seed": i,
            "time_limit_s": (args.seconds + 120) as f64});
        let r = http
            .post(format!("{base}/api/matches"))
            .json(&body)
            .send()
            .await
            .map_err(|e| e.to_string())?;
        if r.status() != 201 {
            return Err(format!(
                "creating a match: {}",
                r.text().await.unwrap_or_default()
            ));
        }
        let v: Value = r.json().await.map_err(|e| e.to_string())?;
        ids.push(v["id"].as_str().unwrap_or_default().to_string());
        owner_tokens.push(v["owner_token"].as_str().unwrap_or_default().to_string());
    }
    println!(
        "{} real-time matches on {} (2 {} robots, {} evade bots), {} spectators over {} ({}), {} s, server {addr}",
        args.matches,
        args.map,
        args.planner,
        args.opponents,
        args.spectators,
        args.transport,
        args.format,
        args.seconds
    );
    let warmup = Duration::from_secs(3);
    let start = Instant::now() + warmup;
    let until = start + Duration::from_secs(args.seconds);
    let mut clients = Vec::new();
    for k in 0..args.spectators {
        let id = ids[k % ids.len()].clone();
        let format = args.format.clone();
        let published = published.clone();
        clients.push(tokio::spawn(async move {
            match published {
                Some(at) => spectate_webtransport(addr, at, id, until, start).await,
                None => spectate(addr, id, until, start, &format).await,
            }
        }));
        if k % 50 == 49 {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }
    // Ticks at the start and end of the measured window.
    tokio::time::sleep_until(start.into()).await;
    // Each read is timed at the middle of its round trip: the reads are sequential and, at
    // this load, tens of milliseconds each, so the last match's first read comes seconds
    // after the window opens; dividing by the window instead of by the time between a
    // match's own two reads would count those seconds as ticks the match never ran.
    let tick_at = |id: String| {
        let http = http.clone();
        let base = base.clone();
        async move {
            let sent = Instant::now();
            let v: Value = http
                .get(format!("{base}/api/matches/{id}/stats"))
                .send()
                .await
                .ok()?
                .json()
                .await
                .ok()?;
            Some((sent + sent.elapsed() / 2, v))
        }
    };
    let mut first = Vec::new();
    for id in &ids {
        first.push(tick_at(id.clone()).await);
    }
    let first_reads = start.elapsed();
    let mut stats: Vec<ClientStats> = Vec::new();
    for c in clients {
        stats.push(c.await.unwrap_or_default());
    }
    tokio::time::sleep_until(until.into()).await; // (when there are no spectators to wait for)
    let secs = args.seconds as f64;
    let mut last = Vec::new();
    let last_from = Instant::now();
    for id in &ids {
        last.push(tick_at(id.clone()).await);
    }
    let last_reads = last_from.elapsed();
    // Matches that ended during the window (robots tagged every bot) stop ticking: their tick
    // rate and their spectators' snapshot rate are not counted below.
    let summaries: Vec<Value> = match http.get(format!("{base}/api/matches")).send().await {
        Ok(r) => r.json().await.unwrap_or_default(),
        Err(_) => Vec::new(),
    };
    let finished: Vec<bool> = ids
        .iter()
        .map(|id| {
            summaries
                .iter()
                .any(|m| m["id"] == id.as_str() && m["status"] == "finished")
        })
        .collect();
    // Matches.
    let mut hz = Vec::new();
    let mut p50 = Vec::new();
    let mut p99 = Vec::new();
    let mut max = Vec::new();
    let mut late = 0;
    let mut lines = Vec::new();
    for ((a, b), done) in first.iter().zip(&last).zip(&finished) {
        let (Some((at_a, a)), Some((at_b, b))) = (a, b) else {
            continue;
        };
        let ticks = b["tick"].as_f64().unwrap_or(0.0) - a["tick"].as_f64().unwrap_or(0.0);
        let rate = ticks / at_b.duration_since(*at_a).as_secs_f64().max(1e-3);
        lines.push(format!(
            "{rate:.1} Hz p50 {} p99 {} µs",
            b["tick_us_p50"], b["tick_us_p99"]
        ));
        if *done {
            lines.push("  (finished during the window)".into());
        } else {
            hz.push(rate);
        }
        p50.push(b["tick_us_p50"].as_f64().unwrap_or(0.0));
        p99.push(b["tick_us_p99"].as_f64().unwrap_or(0.0));
        max.push(b["tick_us_max"].as_f64().unwrap_or(0.0));
        late += b["late_ticks"].as_u64().unwrap_or(0);
    }
    for v in [&mut hz, &mut p50, &mut p99, &mut max] {
        v.sort_by(f64::total_cmp);
    }
    println!(
        "\nmatches ({} ran throughout, {} finished during the window):",
        hz.len(),
        finished.iter().filter(|f| **f).count()
    );
    println!(
        "  tick rate        min {:.2} Hz, median {:.2} Hz (target 20)",
        pct(&hz, 0.0),
        pct(&hz, 0.5)
    );
    println!(
        "                   (a match's ticks between its two reads of its stats; the reads of all matches took {:.1} s at the window's start, {:.1} s at its end)",
        first_reads.as_secs_f64(),
        last_reads.as_secs_f64()
    );
    println!(
        "  tick compute     p50 {:.0} µs (median over matches), p99 {:.0} µs (worst match {:.0} µs), max {:.0} µs",
        pct(&p50, 0.5),
        pct(&p99, 0.5),
        pct(&p99, 1.0),
        pct(&max, 1.0)
    );
    if std::env::var("LOADTEST_VERBOSE").is_ok() {
        for l in &lines {
            println!("    {l}");
        }
    }
    println!("  late ticks       {late} in all (a tick more than 1.5 periods after the previous)");
    // Clients.
    let running: Vec<&ClientStats> = stats
        .iter()
        .enumerate()
        .filter(|(k, _)| !finished[k % ids.len()])
        .map(|(_, s)| s)
        .collect();
    let mut rate: Vec<f64> = running.iter().map(|s| s.snapshots as f64 / secs).collect();
    rate.sort_by(f64::total_cmp);
    let distinct: Vec<f64> = running
        .iter()
        .map(|s| s.distinct_ticks as f64 / secs)
        .collect();
    let starved = rate.iter().filter(|r| **r < 15.0).count();
    let closed = stats.iter().filter(|s| s.closed_early).count();
    println!(
        "\nspectators ({}; {} of them on matches that ran throughout):",
        stats.len(),
        running.len()
    );
    println!(
        "  snapshots/s      min {:.2}, p1 {:.2}, median {:.2}, mean {:.2}",
        pct(&rate, 0.0),
        pct(&rate, 0.01),
        pct(&rate, 0.5),
        rate.iter().sum::<f64>() / rate.len().max(1) as f64
    );
    println!(
        "  distinct ticks/s mean {:.2}",
        distinct.iter().sum::<f64>() / distinct.len().max(1) as f64
    );
    println!("  starved (<15/s)  {starved}; closed early {closed}");
    if let Some(at) = &published {
        println!(
            "  over WebSockets  {} (their WebTransport session refused: the server's sessions full)",
            at.fell_back.load(std::sync::atomic::Ordering::Relaxed)
        );
    }
    let sum = |f: fn(&ClientStats) -> u64| stats.iter().map(f).sum::<u64>();
    let (bb, nb, bp, np) = (
        sum(|s| s.bytes_belief),
        sum(|s| s.n_belief),
        sum(|s| s.bytes_plain),
        sum(|s| s.n_plain),
    );
    let maxb = stats.iter().map(|s| s.max_belief).max().unwrap_or(0);
    let maxp = stats.iter().map(|s| s.max_plain).max().unwrap_or(0);
    println!(
        "  bytes/snapshot   with belief: mean {:.0}, max {maxb}; without: mean {:.0}, max {maxp}; overall mean {:.0}",
        bb as f64 / nb.max(1) as f64,
        bp as f64 / np.max(1) as f64,
        (bb + bp) as f64 / (nb + np).max(1) as f64
    );
    println!(
        "  throughput       {:.1} MB/s to all spectators; {:.1} KiB/s per spectator",
        (bb + bp) as f64 / secs / 1e6,
        (bb + bp) as f64 / secs / 1024.0 / stats.len().max(1) as f64
    );
    for (id, token) in ids.iter().zip(&owner_tokens) {
        let _ = http
            .delete(format!("{base}/api/matches/{id}"))
            .bearer_auth(token)
            .send()
            .await;
    }
    Ok(())
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
        Ok(()) => std::process::ExitCode::SUCCESS,
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
