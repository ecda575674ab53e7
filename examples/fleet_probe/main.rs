//! Load test of a fleet (`--fleet`): real nodes and a real Redis on one machine, every match
//! created and every spectator found through one node's lobby, and what being in a fleet
//! costs each node.
//!
//! ```sh
//! cargo build --release && cargo run --release --example fleet_probe -- \
//!     --server target/release/lasertag --nodes 3 --matches 60 --spectators 1500 --seconds 30
//! cargo run --release --example fleet_probe -- --alone …   # the same load, nodes not in a fleet
//! ```
//!
//! Bounded, self-stopping, loopback only. It starts `redis-server` on a free port and
//! `--nodes` server processes (`--fleet`, per-address limits lifted: every client is
//! 127.0.0.1), creates `--matches` real-time matches with `POST /api/matches` on node 0
//! (the fleet places them; redirects followed), reads node 0's `GET /api/matches` and
//! connects each spectator to its match's `node.url`, as the page does. After a warm-up it
//! measures for `--seconds`, then reports per node: matches, their tick rate and compute
//! (from `/api/matches/{id}/stats`), its spectators' snapshot rate, the process's CPU (from
//! `/proc`), and its Redis round trips per second (`lasertag_fleet_redis_round_trips_total`);
//! for Redis: commands, bytes and CPU per second; and the CPU a heartbeat's (de)serialisation
//! takes, timed on the records the nodes wrote. With `--alone` the nodes run without
//! `--fleet` and get their share of matches and spectators directly: the difference in CPU
//! is the fleet's cost (within the noise of a shared machine).
//!
//! Linux only (`/proc`). Everything it starts is killed at the end.

mod processes;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use processes::{cpu_seconds, metric, redis_counters, start_node, start_redis};

use clap::Parser;
use futures_util::StreamExt;
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

#[derive(Debug, Parser)]
#[command(about = "Load test of a fleet: nodes and Redis on loopback, one lobby")]
struct Args {
    /// The server binary (a release build gives the figures of docs/operations.md).
    #[arg(long, default_value = "target/release/lasertag")]
    server: PathBuf,
    /// The Redis server binary.
    #[arg(long, default_value = "redis-server")]
    redis_server: PathBuf,
    /// Nodes (1..=8).
    #[arg(long, default_value_t = 3)]
    nodes: usize,
    /// Real-time matches in all (1..=300).
    #[arg(long, default_value_t = 60)]
    matches: usize,
    /// WebSocket spectators in all (0..=5000).
    #[arg(long, default_value_t = 1500)]
    spectators: usize,
    /// Seconds to measure (1..=600).
    #[arg(long, default_value_t = 30)]
    seconds: u64,
    /// Map of the matches.
    #[arg(long, default_value = "warehouse")]
    map: String,
    /// Planner of the robots.
    #[arg(long, default_value = "coordinated")]
    planner: String,
    /// Snapshot format of the spectators (`compact` is the page's).
    #[arg(long, default_value = "compact", value_parser = ["json", "compact"])]
    format: String,
    /// Run the nodes without `--fleet` (no Redis), each given its share directly.
    #[arg(long)]
    alone: bool,
    /// The nodes' `--fleet-heartbeat-s`.
    #[arg(long, default_value_t = 1.0)]
    heartbeat_s: f64,
}

#[derive(Debug, Default, Clone)]
struct Seen {
    snapshots: u64,
    closed_early: bool,
}

async fn spectate(url: String, until: Instant, start: Instant) -> Seen {
    let mut seen = Seen::default();
    let Ok((mut ws, _)) = tokio_tungstenite::connect_async(url).await else {
        seen.closed_early = true;
        return seen;
    };
    loop {
        let now = Instant::now();
        if now >= until {
            break;
        }
        match tokio::time::timeout(until - now, ws.next()).await {
            Err(_) => break,
            Ok(Some(Ok(m))) => {
                let snapshot = match &m {
                    Message::Binary(b) => b.first().is_some_and(|k| *k == 1 || *k == 2),
                    Message::Text(t) => t.as_str().starts_with("{\"type\":\"snapshot\""),
                    _ => false,
                };
                if snapshot && Instant::now() >= start {
                    seen.snapshots += 1;
                }
            }
            Ok(_) => {
                seen.closed_early = true;
                break;
            }
        }
    }
    let _ = ws.close(None).await;
    seen
}

fn pct(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// One match as the probe knows it.
struct Placed {
    id: String,
    /// Index of its node.
    node: usize,
    token: String,
}

async fn run(args: Args) -> Result<(), String> {
    if !(1..=8).contains(&args.nodes)
        || !(1..=300).contains(&args.matches)
        || args.spectators > 5000
        || !(1..=600).contains(&args.seconds)
    {
        return Err(
            "--nodes 1..=8, --matches 1..=300, --spectators 0..=5000, --seconds 1..=600".into(),
        );
    }
    let redis = if args.alone {
        None
    } else {
        Some(start_redis(&args.redis_server)?)
    };
    let mut nodes = Vec::new();
    for k in 0..args.nodes {
        nodes.push(start_node(
            &args.server,
            args.heartbeat_s,
            k,
            redis.as_ref().map(|r| r.1),
        )?);
    }
    let http = reqwest::Client::new();
    let mut redis_con = match &redis {
        Some((_, port)) => Some(
            redis::Client::open(format!("redis://127.0.0.1:{port}/0"))
                .map_err(|e| e.to_string())?
                .get_multiplexed_async_connection()
                .await
                .map_err(|e| e.to_string())?,
        ),
        None => None,
    };
    if redis.is_some() {
        let started = Instant::now();
        while metric(&http, &nodes[0], "lasertag_fleet_nodes").await < args.nodes as f64 {
            if started.elapsed() > Duration::from_secs(20) {
                return Err("the nodes did not all join the directory within 20 s".into());
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
    }
    // The matches: through node 0's lobby in a fleet (it places them), round robin alone.
    let mut placed = Vec::new();
    let created_at = Instant::now();
    for i in 0..args.matches {
        let to = if args.alone { i % args.nodes } else { 0 };
        let body = json!({"map": args.map, "robots": 2, "opponents": 3,
            "opponent_bot": "evade", "planner": args.planner, "seed": i,
            "time_limit_s": (args.seconds + 120) as f64});
        let r = http
            .post(format!("{}/api/matches", nodes[to].url))
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
        let host = r.url().origin().ascii_serialization();
        let v: Value = r.json().await.map_err(|e| e.to_string())?;
        let node = nodes
            .iter()
            .position(|n| n.url == host)
            .ok_or_else(|| format!("created on an unknown node {host}"))?;
        placed.push(Placed {
            id: v["id"].as_str().unwrap_or_default().to_owned(),
            node,
            token: v["owner_token"].as_str().unwrap_or_default().to_owned(),
        });
    }
    let creating = created_at.elapsed();
    // The spectators find their matches in node 0's lobby (every node's, in a fleet, once
    // each node's next heartbeat has told it).
    let listed_by = Instant::now();
    loop {
        let listed: Vec<Value> = match http
            .get(format!("{}/api/matches", nodes[0].url))
            .send()
            .await
        {
            Ok(r) => r.json().await.unwrap_or_default(),
            Err(_) => Vec::new(),
        };
        if args.alone || listed.len() >= placed.len() {
            break;
        }
        if listed_by.elapsed() > Duration::from_secs(20) {
            return Err(format!(
                "node 0's lobby lists {} of {} matches after 20 s",
                listed.len(),
                placed.len()
            ));
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let lobby_started = Instant::now();
    let lobby = http
        .get(format!("{}/api/matches", nodes[0].url))
        .send()
        .await
        .map_err(|e| e.to_string())?;
    let lobby_bytes = lobby.bytes().await.map_err(|e| e.to_string())?;
    let lobby_ms = lobby_started.elapsed().as_secs_f64() * 1e3;
    let listed: Vec<Value> = serde_json::from_slice(&lobby_bytes).map_err(|e| e.to_string())?;
    let mut targets = Vec::new();
    for p in &placed {
        let url = if args.alone {
            nodes[p.node].url.clone()
        } else {
            let m = listed
                .iter()
                .find(|m| m["id"] == p.id.as_str())
                .ok_or_else(|| format!("match {} is not in node 0's lobby", p.id))?;
            m["node"]["url"].as_str().unwrap_or_default().to_owned()
        };
        targets.push(format!(
            "{}/ws/matches/{}?format={}",
            url.replacen("http", "ws", 1),
            p.id,
            args.format
        ));
    }
    println!(
        "{} nodes{} on one machine ({} cores), {} real-time matches ({}, 2 {} robots, 3 evade bots), {} spectators ({}), {} s",
        args.nodes,
        if args.alone {
            " (alone, no fleet)"
        } else {
            " in a fleet"
        },
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        args.matches,
        args.map,
        args.planner,
        args.spectators,
        args.format,
        args.seconds
    );
    println!(
        "created in {:.1} s through {}; node 0's lobby lists {} matches ({} bytes, {lobby_ms:.1} ms)",
        creating.as_secs_f64(),
        if args.alone { "each node" } else { "node 0" },
        listed.len(),
        lobby_bytes.len()
    );
    let warmup = Duration::from_secs(3);
    let start = Instant::now() + warmup;
    let until = start + Duration::from_secs(args.seconds);
    let mut clients = Vec::new();
    for k in 0..args.spectators {
        let url = targets[k % targets.len()].clone();
        clients.push(tokio::spawn(spectate(url, until, start)));
        if k % 50 == 49 {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }
    tokio::time::sleep_until(start.into()).await;
    let stats = |p: &Placed| {
        let http = http.clone();
        let url = format!("{}/api/matches/{}/stats", nodes[p.node].url, p.id);
        async move {
            let v: Value = http.get(url).send().await.ok()?.json().await.ok()?;
            // When it was read: on a loaded machine reading 60 of them takes a while.
            Some((Instant::now(), v))
        }
    };
    let mut first = Vec::new();
    for p in &placed {
        first.push(stats(p).await);
    }
    let cpu0: Vec<f64> = nodes
        .iter()
        .map(|n| cpu_seconds(n.process.0.id()))
        .collect();
    let mut trips0 = Vec::new();
    for n in &nodes {
        let v = metric(&http, n, "lasertag_fleet_redis_round_trips_total").await;
        trips0.push((Instant::now(), v));
    }
    let redis0 = match &mut redis_con {
        Some(c) => Some((redis_counters(c).await, Instant::now())),
        None => None,
    };
    let measured_from = Instant::now();
    let mut seen = Vec::new();
    for c in clients {
        seen.push(c.await.unwrap_or_default());
    }
    tokio::time::sleep_until(until.into()).await;
    let secs = measured_from.elapsed().as_secs_f64();
    let cpu1: Vec<f64> = nodes
        .iter()
        .map(|n| cpu_seconds(n.process.0.id()))
        .collect();
    let mut trips1 = Vec::new();
    for n in &nodes {
        let v = metric(&http, n, "lasertag_fleet_redis_round_trips_total").await;
        trips1.push((Instant::now(), v));
    }
    let redis1 = match &mut redis_con {
        Some(c) => Some((redis_counters(c).await, Instant::now())),
        None => None,
    };
    let mut last = Vec::new();
    for p in &placed {
        last.push(stats(p).await);
    }
    // Matches the robots won during the window stop ticking: left out of the rates.
    let mut finished = std::collections::HashSet::new();
    for n in &nodes {
        let listed: Vec<Value> = match http.get(format!("{}/api/matches", n.url)).send().await {
            Ok(r) => r.json().await.unwrap_or_default(),
            Err(_) => Vec::new(),
        };
        finished.extend(
            listed
                .iter()
                .filter(|m| m["status"] == "finished")
                .filter_map(|m| m["id"].as_str().map(String::from)),
        );
    }
    let window = args.seconds as f64;
    println!("\nper node (one process each, all on this machine):");
    for (k, node) in nodes.iter().enumerate() {
        let mine: Vec<usize> = (0..placed.len()).filter(|&i| placed[i].node == k).collect();
        let mut hz = Vec::new();
        let mut p99 = Vec::new();
        let mut late = 0;
        for &i in &mine {
            let (Some((ta, a)), Some((tb, b))) = (&first[i], &last[i]) else {
                continue;
            };
            let ticks = b["tick"].as_f64().unwrap_or(0.0) - a["tick"].as_f64().unwrap_or(0.0);
            if !finished.contains(&placed[i].id) {
                hz.push(ticks / (*tb - *ta).as_secs_f64());
            }
            p99.push(b["tick_us_p99"].as_f64().unwrap_or(0.0));
            late += b["late_ticks"].as_u64().unwrap_or(0);
        }
        hz.sort_by(f64::total_cmp);
        p99.sort_by(f64::total_cmp);
        let mut rates: Vec<f64> = (0..seen.len())
            .filter(|s| {
                let p = &placed[s % placed.len()];
                p.node == k && !finished.contains(&p.id)
            })
            .map(|s| seen[s].snapshots as f64 / window)
            .collect();
        rates.sort_by(f64::total_cmp);
        let starved = rates.iter().filter(|r| **r < 15.0).count();
        println!(
            "  node {k} ({}): {} matches ({} won by the robots during the window), tick rate min {:.2} / median {:.2} Hz, tick p99 median {:.0} µs (worst {:.0}), {late} late ticks; {} spectators at min {:.2} / median {:.2} snapshots/s, {starved} under 15/s; CPU {:.2} cores; Redis {:.2} round trips/s",
            node.addr,
            mine.len(),
            mine.iter()
                .filter(|&&i| finished.contains(&placed[i].id))
                .count(),
            pct(&hz, 0.0),
            pct(&hz, 0.5),
            pct(&p99, 0.5),
            pct(&p99, 1.0),
            rates.len(),
            pct(&rates, 0.0),
            pct(&rates, 0.5),
            (cpu1[k] - cpu0[k]) / secs,
            (trips1[k].1 - trips0[k].1) / (trips1[k].0 - trips0[k].0).as_secs_f64(),
        );
    }
    let closed = seen.iter().filter(|s| s.closed_early).count();
    println!("  spectators closed early: {closed}");
    if let (Some((a, ta)), Some((b, tb))) = (redis0, redis1) {
        let secs = (tb - ta).as_secs_f64();
        println!(
            "\nredis: {:.1} commands/s, {:.1} KB/s in, {:.1} KB/s out, CPU {:.3} cores",
            (b.0 - a.0) / secs,
            (b.1 - a.1) / secs / 1e3,
            (b.2 - a.2) / secs / 1e3,
            (b.3 - a.3) / secs
        );
    }
    // What a heartbeat's JSON costs: encoding this node's record and decoding the others'.
    if let Some(con) = &mut redis_con {
        let mut records = Vec::new();
        for k in 0..args.nodes {
            let bytes: Option<Vec<u8>> = redis::cmd("GET")
                .arg(format!("lasertag:fleet:node:n{k}"))
                .query_async(con)
                .await
                .unwrap_or(None);
            records.extend(bytes);
        }
        if let Some(record) = records.first() {
            let parsed = lasertag::protocol::fleet::NodeRecord::decode(record)
                .ok_or("a node's record does not decode")?;
            let n = 200;
            let t = Instant::now();
            for _ in 0..n {
                std::hint::black_box(lasertag::protocol::fleet::NodeRecord::decode(
                    std::hint::black_box(record),
                ));
            }
            let decode = t.elapsed().as_secs_f64() / n as f64;
            let t = Instant::now();
            for _ in 0..n {
                std::hint::black_box(serde_json::to_vec(std::hint::black_box(&parsed)).ok());
            }
            let encode = t.elapsed().as_secs_f64() / n as f64;
            let per_beat = encode + decode * (args.nodes - 1) as f64;
            println!(
                "a node's record: {} bytes ({} matches); encode {:.0} µs, decode {:.0} µs: {:.0} µs of CPU per heartbeat with {} nodes ({:.3}% of a core at one heartbeat per {} s)",
                record.len(),
                parsed.matches.len(),
                encode * 1e6,
                decode * 1e6,
                per_beat * 1e6,
                args.nodes,
                per_beat / args.heartbeat_s * 100.0,
                args.heartbeat_s
            );
        }
    }
    for p in &placed {
        let _ = http
            .delete(format!("{}/api/matches/{}", nodes[p.node].url, p.id))
            .bearer_auth(&p.token)
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
