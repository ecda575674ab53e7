//! How late a player sees its own moves: key press to its own disc moving on the canvas, in
//! headless Chromium, through a proxy that adds a real network's round trip and loss.
//!
//! ```sh
//! cargo run --release --example latency_probe                 # 0, 150, 300 ms; 150 ms with 1% loss
//! cargo run --release --example latency_probe -- --trials 40 --rtt-ms 150
//! ```
//!
//! It starts the server in this process (loopback, an ephemeral port, no showcase), puts the
//! proxy of `tests/common/netem.rs` in front of it, and for each network condition opens the
//! game page through the proxy in Chromium (as `tests/browser.rs` does) as the player of a
//! match whose robots stand still far away. Each trial presses W (or S, alternately, so the
//! disc stays in the corridor) through the DevTools protocol; a hook in the page notes the
//! time of the key event and the first animation frame in which the disc it draws for the
//! player has moved. Every condition runs with the page's prediction on and off
//! (`localStorage["lasertag.predict"]`), so the table shows what prediction buys. With
//! prediction on it then drives for 10 s into walls and corners and reports the page's
//! reconciliation corrections over the whole run (how far the server's answer was from where
//! the page had put the disc).

// The browser driver and the network proxy of the tests, shared rather than copied (this
// program uses only part of the driver).
#[allow(dead_code)]
#[path = "../tests/common/cdp.rs"]
mod cdp;
#[path = "../tests/common/netem.rs"]
mod netem;

#[path = "../tests/common/in_process.rs"]
mod in_process;
#[path = "../tests/common/own_motion.rs"]
mod own_motion;

use std::path::PathBuf;
use std::time::Duration;

use clap::Parser;
use own_motion::{HOOK, percentile};
use serde_json::{Value, json};

#[derive(Debug, Parser)]
#[command(about = "Own-motion latency in the browser over a simulated network")]
struct Args {
    /// Key presses per condition and mode (1..=500).
    #[arg(long, default_value_t = 20)]
    trials: usize,
    /// Round trips to measure (ms); default 0, 150 and 300, plus 150 with 1% loss.
    #[arg(long, value_delimiter = ',')]
    rtt_ms: Vec<u64>,
    /// Packet loss for the extra lossy condition (0..1).
    #[arg(long, default_value_t = 0.01)]
    loss: f64,
    /// Directory of map files.
    #[arg(long, default_value = "maps")]
    maps: PathBuf,
}

#[tokio::main]
async fn main() {
    let args = Args::parse();
    if let Err(e) = run(args).await {
        eprintln!("latency_probe: {e}");
        std::process::exit(1);
    }
}

async fn run(args: Args) -> Result<(), String> {
    if !(1..=500).contains(&args.trials) {
        return Err(format!("--trials {} must be in 1..=500", args.trials));
    }
    let server = in_process::start(&args.maps).await?;

    let mut conditions: Vec<(u64, f64)> = if args.rtt_ms.is_empty() {
        vec![(0, 0.0), (150, 0.0), (300, 0.0), (150, args.loss)]
    } else {
        args.rtt_ms.iter().map(|r| (*r, 0.0)).collect()
    };
    conditions.dedup();
    let mut browser = cdp::Browser::launch().await;
    println!(
        "| round trip | loss | prediction | key → own disc moves, p50 / p95 / max (ms) | corrections p95 / max (cm) |"
    );
    println!("|---|---|---|---|---|");
    for (rtt, loss) in conditions {
        let net = netem::Netem::start(
            server,
            netem::Conditions {
                loss,
                jitter: Duration::from_millis(rtt / 20),
                ..netem::Conditions::rtt_ms(rtt)
            },
        )
        .await;
        for predict in [true, false] {
            let (lat, corrections) = trials(&mut browser, net.addr, predict, args.trials).await?;
            println!(
                "| {rtt} ms | {:.0}% | {} | {:.0} / {:.0} / {:.0} | {} |",
                loss * 100.0,
                if predict { "on" } else { "off" },
                percentile(&lat, 0.5),
                percentile(&lat, 0.95),
                percentile(&lat, 1.0),
                if predict && corrections.is_empty() {
                    "none".into()
                } else if predict {
                    format!(
                        "{:.1} / {:.1}",
                        percentile(&corrections, 0.95) * 100.0,
                        percentile(&corrections, 1.0) * 100.0
                    )
                } else {
                    "-".into()
                }
            );
        }
    }
    Ok(())
}

/// One condition and mode: a fresh match played through `addr`; the latencies (ms) and the
/// page's corrections (m), with prediction on over the trials and 10 s of driving along
/// walls after them.
async fn trials(
    b: &mut cdp::Browser,
    addr: std::net::SocketAddr,
    predict: bool,
    n: usize,
) -> Result<(Vec<f64>, Vec<f64>), String> {
    let base = format!("http://{addr}");
    let http = reqwest::Client::new();
    // The player's opponent in the corridor, the robots idle in far rooms.
    let body = json!({"map": "office", "robots": 2, "opponents": 1,
        "opponent_control": "human", "planner": "idle", "time_limit_s": 600,
        "robot_starts": [[22.0, 1.5, 0.0], [22.0, 14.0, 0.0]],
        "opponent_starts": [[6.0, 8.0]]});
    let created: Value = http
        .post(format!("{base}/api/matches"))
        .json(&body)
        .send()
        .await
        .map_err(|e| e.to_string())?
        .json()
        .await
        .map_err(|e| e.to_string())?;
    let id = created["id"]
        .as_str()
        .ok_or_else(|| format!("creating the match: {created}"))?
        .to_string();
    b.navigate(&format!("{base}/")).await;
    b.wait_for("document.readyState === 'complete'", 20).await;
    let mode = if predict { "on" } else { "off" };
    b.eval(&format!(
        "localStorage.setItem('lasertag.predict', '{mode}')"
    ))
    .await;
    // A new query string: a whole new page (not a hash change in the old one).
    b.navigate(&format!("{base}/?probe={id}#/play/{id}")).await;
    b.wait_for(
        &format!("__lasertag.matchId === '{id}' && __lasertag.role === 'player' && __lasertag.snapshots > 20"),
        30,
    )
    .await;
    b.eval(HOOK).await;
    for k in 0..n {
        let key = if k % 2 == 0 { "KeyW" } else { "KeyS" };
        b.key(key, true).await;
        tokio::time::sleep(Duration::from_millis(400)).await;
        b.key(key, false).await;
        // Let it come to rest (and the server's answers settle) before the next press.
        tokio::time::sleep(Duration::from_millis(600)).await;
    }
    let lat: Vec<f64> = serde_json::from_value(b.eval("window.__ownMotion.lat").await)
        .map_err(|e| e.to_string())?;
    let mut corrections: Vec<f64> =
        serde_json::from_value(b.eval("window.__lasertag.corrections || []").await)
            .unwrap_or_default();
    if predict {
        // Then into the walls: forward all the time, turning now one way, now the other,
        // so the disc keeps sliding along walls and corners (where a prediction that
        // disagreed with the server's collisions would show).
        b.key("KeyW", true).await;
        for k in 0..10 {
            let turn = if k % 3 == 2 { "KeyD" } else { "KeyA" };
            b.key(turn, true).await;
            tokio::time::sleep(Duration::from_millis(350)).await;
            b.key(turn, false).await;
            tokio::time::sleep(Duration::from_millis(650)).await;
        }
        b.key("KeyW", false).await;
        tokio::time::sleep(Duration::from_millis(800)).await;
        corrections = serde_json::from_value(b.eval("window.__lasertag.corrections || []").await)
            .unwrap_or_default();
    }
    let _ = http
        .delete(format!("{base}/api/matches/{id}"))
        .bearer_auth(created["owner_token"].as_str().unwrap_or_default())
        .send()
        .await;
    Ok((lat, corrections))
}
