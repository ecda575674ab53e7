//! What a player and a spectator cost in bytes over a whole match, in each snapshot format.
//!
//! ```sh
//! cargo run --release --example bandwidth_probe                  # one 60 s match
//! cargo run --release --example bandwidth_probe -- --seconds 120 --map warehouse
//! ```
//!
//! It starts the server in this process (loopback, an ephemeral port, no showcase) and plays
//! one real-time match: robots on the default planner against one person, who joins and
//! drives as a person would (a random key held for half a second to two seconds, a tag now
//! and then, one numbered input per tick as the page sends them) in the place of one of four
//! evading bots. The player plays the first half of the match with compact snapshots and
//! reconnects for the second half with JSON ones. A second match, the same but for a third
//! robot that is a pursuer slot, has a hunter on the robot team played the same way (their
//! own robot's scan and the team's belief come with their view). Beside the player it connects spectators with the
//! belief on and off, in both formats, all live (`spectator_delay_s` 0). At the end it prints,
//! for each client, the bytes per second the server sent it (WebSocket payloads: what the
//! page's `__lasertag.rxBytes` counts), the snapshots per second and the mean snapshot size,
//! and for compact clients how many snapshots came as deltas.

#[path = "../tests/common/in_process.rs"]
mod in_process;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Parser;
use futures_util::{SinkExt, StreamExt};
use rand::{RngExt, SeedableRng};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

#[derive(Debug, Parser)]
#[command(about = "Bytes per second to a player and to spectators over one match")]
struct Args {
    /// Length of the match in seconds (10..=600).
    #[arg(long, default_value_t = 60)]
    seconds: u64,
    /// Map of the match.
    #[arg(long, default_value = "office")]
    map: String,
    /// Seed of the player's keys (people may join the match: the server chooses its seed).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Directory of map files.
    #[arg(long, default_value = "maps")]
    maps: PathBuf,
}

/// What one client received.
#[derive(Debug, Default)]
struct Received {
    bytes: u64,
    snapshots: u64,
    snapshot_bytes: u64,
    deltas: u64,
    other: u64,
    /// The tick at which this client's player was tagged, if it was.
    tagged_at: Option<u64>,
}

#[tokio::main]
async fn main() {
    let args = Args::parse();
    if let Err(e) = run(args).await {
        eprintln!("bandwidth_probe: {e}");
        std::process::exit(1);
    }
}

async fn run(args: Args) -> Result<(), String> {
    if !(10..=600).contains(&args.seconds) {
        return Err(format!("--seconds {} must be in 10..=600", args.seconds));
    }
    let addr = in_process::start(&args.maps).await?;

    let http = reqwest::Client::new();
    let base = format!("http://{addr}");
    let created: Value = post(
        &http,
        &format!("{base}/api/matches"),
        json!({"map": args.map, "robots": 2, "opponents": 4, "opponent_control": "bot",
            "bots_joinable": true, "time_limit_s": args.seconds,
            "spectator_delay_s": 0}),
    )
    .await?;
    let id = created["id"]
        .as_str()
        .ok_or_else(|| format!("creating the match: {created}"))?
        .to_string();
    let joined = post(
        &http,
        &format!("{base}/api/matches/{id}/players"),
        json!({"name": "probe"}),
    )
    .await?;
    let token = joined["token"]
        .as_str()
        .ok_or_else(|| format!("joining: {joined}"))?
        .to_string();
    let hunted: Value = post(
        &http,
        &format!("{base}/api/matches"),
        json!({"map": args.map, "robots": 3, "pursuer_slots": 1, "opponents": 4,
            "opponent_control": "bot", "opponent_bot": "evade", "time_limit_s": args.seconds,
            "spectator_delay_s": 0}),
    )
    .await?;
    let hunted = hunted["id"]
        .as_str()
        .ok_or_else(|| format!("creating the hunters' match: {hunted}"))?
        .to_string();
    let hunter = post(
        &http,
        &format!("{base}/api/matches/{hunted}/players"),
        json!({"name": "hunter", "team": "robots"}),
    )
    .await?;
    let hunter = hunter["token"]
        .as_str()
        .ok_or_else(|| format!("joining the robot team: {hunter}"))?
        .to_string();
    let until = Instant::now() + Duration::from_secs(args.seconds + 2);
    let ws = |q: String| format!("ws://{addr}/ws/matches/{id}?{q}");
    let hunt = |q: String| format!("ws://{addr}/ws/matches/{hunted}?{q}");
    let clients = [
        ("player", "compact", true, Some(token.clone())),
        ("player", "json", true, Some(token.clone())),
        ("hunter, belief on", "compact", true, Some(hunter.clone())),
        ("hunter, belief on", "json", true, Some(hunter.clone())),
        ("spectator, belief on", "compact", true, None),
        ("spectator, belief off", "compact", false, None),
        ("spectator, belief on", "json", true, None),
        ("spectator, belief off", "json", false, None),
    ];
    let mut tasks = Vec::new();
    for (k, (who, format, belief, token)) in clients.into_iter().enumerate() {
        let q = match &token {
            Some(t) => format!("format={format}&token={t}"),
            None => format!("format={format}"),
        };
        let url = if who.starts_with("hunter") {
            hunt(q)
        } else {
            ws(q)
        };
        let seed = args.seed + k as u64;
        let half = Duration::from_secs(args.seconds / 2);
        tasks.push(tokio::spawn(async move {
            let (start, end) = match (token.is_some(), format) {
                (true, "compact") => (Instant::now(), Instant::now() + half),
                (true, _) => (Instant::now() + half, until),
                _ => (Instant::now(), until),
            };
            tokio::time::sleep_until(start.into()).await;
            let r = listen(url, belief, token.is_some(), end, seed).await;
            (who, format, end - start, r)
        }));
    }
    println!("| client | format | bytes/s | snapshots/s | mean snapshot (B) | deltas |");
    println!("|---|---|---|---|---|---|");
    for t in tasks {
        let (who, format, span, r) = t.await.map_err(|e| e.to_string())?;
        let r = r?;
        let s = span.as_secs_f64();
        println!(
            "| {who}{} | {format} | {:.2} KiB/s | {:.1} | {:.0} | {} |",
            r.tagged_at
                .map(|t| format!(" (tagged at tick {t})"))
                .unwrap_or_default(),
            r.bytes as f64 / s / 1024.0,
            r.snapshots as f64 / s,
            r.snapshot_bytes as f64 / r.snapshots.max(1) as f64,
            if format == "compact" {
                format!(
                    "{:.0}%",
                    100.0 * r.deltas as f64 / r.snapshots.max(1) as f64
                )
            } else {
                "-".into()
            },
        );
    }
    Ok(())
}

async fn post(http: &reqwest::Client, url: &str, body: Value) -> Result<Value, String> {
    http.post(url)
        .json(&body)
        .send()
        .await
        .map_err(|e| e.to_string())?
        .json()
        .await
        .map_err(|e| e.to_string())
}

/// Reads one connection until `until`; a player sends an input every tick, holding a random
/// key for 0.5–2 s.
async fn listen(
    url: String,
    belief: bool,
    player: bool,
    until: Instant,
    seed: u64,
) -> Result<Received, String> {
    let (mut ws, _) = tokio_tungstenite::connect_async(url)
        .await
        .map_err(|e| format!("connecting: {e}"))?;
    let mut r = Received::default();
    if !belief {
        let off = json!({"type": "belief", "on": false}).to_string();
        ws.send(Message::Text(off.into()))
            .await
            .map_err(|e| e.to_string())?;
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut tick = tokio::time::interval(Duration::from_millis(50));
    let (mut seq, mut keys, mut change_at) = (0u64, (0.0, 0.0), Instant::now());
    loop {
        tokio::select! {
            _ = tokio::time::sleep_until(until.into()) => break,
            _ = tick.tick(), if player => {
                if Instant::now() >= change_at {
                    keys = (rng.random_range(-1..=1) as f64, rng.random_range(-1..=1) as f64);
                    change_at = Instant::now() + Duration::from_millis(rng.random_range(500..2000));
                }
                seq += 1;
                let input = json!({"type": "input", "seq": seq, "forward": keys.0,
                    "turn": keys.1, "tag": rng.random_bool(0.05)});
                if ws.send(Message::Text(input.to_string().into())).await.is_err() {
                    break;
                }
            }
            msg = ws.next() => {
                let Some(Ok(msg)) = msg else { break };
                match msg {
                    Message::Binary(b) => {
                        r.bytes += b.len() as u64;
                        r.snapshots += 1;
                        r.snapshot_bytes += b.len() as u64;
                        r.deltas += (b.first() == Some(&2)) as u64;
                    }
                    Message::Text(t) => {
                        r.bytes += t.len() as u64;
                        if t.starts_with("{\"type\":\"snapshot\"") {
                            r.snapshots += 1;
                            r.snapshot_bytes += t.len() as u64;
                        } else {
                            r.other += 1;
                            if player && r.tagged_at.is_none() && t.contains("\"kind\":\"tag\"") {
                                let v: Value = serde_json::from_str(&t).unwrap_or_default();
                                if v["target"] == "o0" {
                                    r.tagged_at = v["tick"].as_u64();
                                }
                            }
                        }
                    }
                    _ => {}
                }
            }
        }
    }
    let _ = ws.close(None).await;
    Ok(r)
}
