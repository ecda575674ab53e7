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
//! - bytes per snapshot, with and without the belief;
//! - with `--players-per-match`, the same for the people playing (each at a bot's slot,
//!   an input every tick), and for each role the sessions by carrier: how many ended on
//!   WebTransport and on a WebSocket, refused a session or moved off one for a player.
//!
//! The matches are deleted at the end.
//!
//! `--transport webtransport` watches over WebTransport instead (compact snapshots as
//! datagrams, each spectator acknowledging what it holds as the page does, so snapshots come
//! as deltas against those): the in-process server then also serves it in UDP, and the
//! spectators open their sessions from 16 loopback addresses, 8 at a time from each (the
//! server caps an address's handshakes in progress at 8).
//! A spectator whose session is refused (past `--max-webtransport-sessions`) watches over a
//! WebSocket, as the page does; the report says how many did. The clients are in
//! `clients.rs`.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[allow(dead_code)]
#[path = "../../tests/common/wt.rs"]
mod wt;

mod clients;
use clients::{Carrier, Client, ClientStats, Published, Seat};

use clap::Parser;
use serde_json::{Value, json};

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
    /// People playing each match (0..=--opponents), each at a bot's opponent slot, sending an
    /// input every tick over the spectators' carrier (datagrams over WebTransport). They
    /// connect after the spectators, so that over WebTransport they find the sessions
    /// spectators hold (the server moves spectators off for them). A match with players is
    /// made as people's are: `bots_joinable`, a secret seed, no spectator delay. Against a
    /// server of its own, `--addr` needs `--max-seats-per-address` raised to the players.
    #[arg(long, default_value_t = 0)]
    players_per_match: usize,
    /// Over WebTransport, each client acknowledges every this many snapshots it takes (the
    /// page's cadence by default); 0 never (the server then sends wholes where it would send
    /// deltas: a measure of what reading acknowledgements costs it).
    #[arg(long, default_value_t = wt::ACK_EVERY)]
    ack_every: u64,
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
    if args.players_per_match > args.opponents {
        return Err(format!(
            "--players-per-match {} is more than the {} bot opponents a match has for people to take (--opponents)",
            args.players_per_match, args.opponents
        ));
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
                max_seats_per_address: usize::MAX,
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
            // The server takes 8 handshakes at once from one address (and 256 in all): the
            // sessions open from 16 loopback addresses, as a crowd's come from many, so that
            // the one address's cap is not what the connecting measures.
            sources: (2..18u8)
                .map(|i| {
                    let ip = std::net::IpAddr::V4(std::net::Ipv4Addr::new(127, 0, 0, i));
                    (ip, std::sync::Arc::new(tokio::sync::Semaphore::new(8)))
                })
                .collect(),
        })
    } else {
        None
    };
    let mut ids = Vec::new();
    let mut owner_tokens = Vec::new();
    for i in 0..args.matches {
        let mut body = json!({"map": args.map, "robots": 2, "opponents": args.opponents,
            "opponent_bot": "evade", "planner": args.planner,
            "seed": i,
            "time_limit_s": (args.seconds + 120) as f64});
        if args.players_per_match > 0 {
            body["bots_joinable"] = json!(true);
            body["spectator_delay_s"] = json!(0.0);
            body.as_object_mut().map(|b| b.remove("seed"));
        }
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
        "{} real-time matches on {} (2 {} robots, {} evade bots, {} of them played by people), {} spectators over {} ({}), {} s, server {addr}",
        args.matches,
        args.map,
        args.planner,
        args.opponents,
        args.players_per_match,
        args.spectators,
        args.transport,
        args.format,
        args.seconds
    );
    let (open_window, opened) = tokio::sync::watch::channel(None);
    let window = clients::Window::new(opened);
    let mut clients = Vec::new();
    let seats = (0..args.spectators)
        .map(|k| (ids[k % ids.len()].clone(), Seat::Spectator))
        .chain((0..args.matches * args.players_per_match).map(|k| {
            let (i, p) = (k / args.players_per_match, k % args.players_per_match);
            (
                ids[i].clone(),
                Seat::Player {
                    name: format!("load{i}p{p}"),
                },
            )
        }));
    for (k, (id, seat)) in seats.enumerate() {
        let client = Client {
            addr,
            id,
            seat,
            http: http.clone(),
            window: window.clone(),
            format: args.format.clone(),
            ack_every: args.ack_every,
            index: k,
        };
        let published = published.clone();
        clients.push(tokio::spawn(async move {
            match published {
                Some(at) => client.over_webtransport(&at).await,
                None => client.over_websocket().await,
            }
        }));
        if k % 50 == 49 {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }
    let match_of = |k: usize| {
        if k < args.spectators {
            k % ids.len()
        } else {
            (k - args.spectators) / args.players_per_match.max(1)
        }
    };
    // The window opens 5 s after every client is connected (or has given up), or after
    // a minute in any case.
    let total = clients.len();
    let connecting = Instant::now();
    while window.connected.load(std::sync::atomic::Ordering::Relaxed) < total
        && connecting.elapsed() < Duration::from_secs(60)
    {
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    println!(
        "({} of {total} clients connected in {:.1} s)",
        window.connected.load(std::sync::atomic::Ordering::Relaxed),
        connecting.elapsed().as_secs_f64()
    );
    let start = Instant::now() + Duration::from_secs(5);
    let until = start + Duration::from_secs(args.seconds);
    let _ = open_window.send(Some((start, until)));
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
    // A client not done when the window closes (a session still handshaking, neither opened
    // nor refused) would hold the report for ever: past a grace it is stopped and counted
    // as closed early, with that reason.
    let grace = until + Duration::from_secs(10);
    let mut stats: Vec<ClientStats> = Vec::new();
    for (k, c) in clients.into_iter().enumerate() {
        let abort = c.abort_handle();
        stats.push(match tokio::time::timeout_at(grace.into(), c).await {
            Ok(done) => done.unwrap_or_default(),
            Err(_) => {
                abort.abort();
                let mut hung = ClientStats::default();
                hung.player = k >= args.spectators;
                hung.closed_early = true;
                hung.close_reason = Some("not done 10 s after the window".into());
                hung
            }
        });
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
    // Clients, by role.
    for (role, player) in [("spectators", false), ("players", true)] {
        let of_role: Vec<(usize, &ClientStats)> = stats
            .iter()
            .enumerate()
            .filter(|(_, s)| s.player == player)
            .collect();
        if of_role.is_empty() {
            continue;
        }
        report_clients(role, &of_role, |k| finished[match_of(k)], secs);
    }
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

/// The report of one role's clients (`(index, stats)`; `finished(index)`: its match ended
/// during the window, so its snapshot rate is not counted).
fn report_clients(
    role: &str,
    clients: &[(usize, &ClientStats)],
    finished: impl Fn(usize) -> bool,
    secs: f64,
) {
    let running: Vec<&ClientStats> = clients
        .iter()
        .filter(|(k, _)| !finished(*k))
        .map(|(_, s)| *s)
        .collect();
    let mut rate: Vec<f64> = running.iter().map(|s| s.snapshots as f64 / secs).collect();
    rate.sort_by(f64::total_cmp);
    let distinct: Vec<f64> = running
        .iter()
        .map(|s| s.distinct_ticks as f64 / secs)
        .collect();
    let starved = rate.iter().filter(|r| **r < 15.0).count();
    let count = |f: &dyn Fn(&ClientStats) -> bool| clients.iter().filter(|(_, s)| f(s)).count();
    println!(
        "\n{role} ({}; {} of them on matches that ran throughout):",
        clients.len(),
        running.len()
    );
    println!(
        "  carriers         WebTransport {}, WebSocket {} ({} refused a WebTransport session, {} moved off one for a player)",
        count(&|s| s.carrier == Carrier::WebTransport),
        count(&|s| s.carrier == Carrier::WebSocket),
        count(&|s| s.refused),
        count(&|s| s.moved),
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
    println!(
        "  starved (<15/s)  {starved}; closed early {}",
        count(&|s| s.closed_early)
    );
    let mut reasons: Vec<&str> = clients
        .iter()
        .filter_map(|(_, s)| s.close_reason.as_deref())
        .collect();
    reasons.sort_unstable();
    reasons.dedup();
    for r in reasons {
        println!("    closed: {r}");
    }
    let sum = |f: fn(&ClientStats) -> u64| clients.iter().map(|(_, s)| f(s)).sum::<u64>();
    let (bb, nb, bp, np) = (
        sum(|s| s.bytes_belief),
        sum(|s| s.n_belief),
        sum(|s| s.bytes_plain),
        sum(|s| s.n_plain),
    );
    let maxb = clients.iter().map(|(_, s)| s.max_belief).max().unwrap_or(0);
    let maxp = clients.iter().map(|(_, s)| s.max_plain).max().unwrap_or(0);
    println!(
        "  bytes/snapshot   with belief: mean {:.0}, max {maxb}; without: mean {:.0}, max {maxp}; overall mean {:.0}",
        bb as f64 / nb.max(1) as f64,
        bp as f64 / np.max(1) as f64,
        (bb + bp) as f64 / (nb + np).max(1) as f64
    );
    let one = role.strip_suffix('s').unwrap_or(role);
    println!(
        "  throughput       {:.1} MB/s to all {role}; {:.1} KiB/s per {one}",
        (bb + bp) as f64 / secs / 1e6,
        (bb + bp) as f64 / secs / 1024.0 / clients.len().max(1) as f64
    );
}
