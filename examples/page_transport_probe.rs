//! The page over each carrier through a lossy, long link, as a player sees it: headless
//! Chromium plays a match through the link emulator (tests/common/link.rs: a round trip and
//! a share of packets lost each way, TCP and UDP alike) once over the WebSocket and once over
//! WebTransport, for each loss. For each run it reports the other agents' motion stalls (gaps
//! over 150 ms between the snapshots the page draws, per minute), own-motion latency (key to
//! own disc moving, as `latency_probe`) and the bytes per second the page receives.
//!
//! ```sh
//! cargo run --release --example page_transport_probe                    # 150 ms; 0, 1, 2, 5%
//! cargo run --release --example page_transport_probe -- --loss 2 --seconds 60
//! cargo run --release --example page_transport_probe -- --csv docs/results/page_transport.csv \
//!     --plot docs/results/page_transport_stalls.svg
//! ```
//!
//! The server runs inside the link's namespace, on 198.18.x.2; Chromium in this one reaches it
//! through the link. A page from a plain-http origin other than localhost is not a secure
//! context and has no WebTransport, so Chromium is told to treat that one origin as secure
//! (`--unsafely-treat-insecure-origin-as-secure`), as an HTTPS page would be.
//!
//! The match: 8 evading bots about the office, two robots hunting them from the far side;
//! the page takes over one of the bots (a `bots_joinable` match, as the showcase) and plays
//! it. Stalls are counted over the time from the first tick drawn to the last (a match whose
//! robots tagged every opponent stops ticking: the rest of the run is not counted). Over the first part of the run the page presses W and S in
//! turn once a second (own-motion latency, with the page's prediction on); all the while a
//! hook notes the time of every animation frame that draws a newer tick than the last.
//!
//! Needs root, `ip` and nftables, and Chromium.

#[allow(dead_code)]
#[path = "../tests/common/cdp.rs"]
mod cdp;
#[allow(dead_code)]
#[path = "../tests/common/in_process.rs"]
mod in_process;
#[allow(dead_code)]
#[path = "../tests/common/link.rs"]
mod link;
#[path = "../tests/common/own_motion.rs"]
mod own_motion;

use std::path::PathBuf;
use std::time::Duration;

use clap::Parser;
use own_motion::percentile;
use serde_json::{Value, json};

#[derive(Debug, Parser)]
#[command(about = "Stalls, own-motion latency and bytes in Chromium over each carrier")]
struct Args {
    /// Loss each way, in percent (0..=50), one run per carrier each; default 0, 1, 2 and 5.
    #[arg(long, value_delimiter = ',')]
    loss: Vec<u32>,
    /// Round trip the link adds (ms, 1..=1000).
    #[arg(long, default_value_t = 150)]
    rtt_ms: u64,
    /// Seconds each run plays (10..=600).
    #[arg(long, default_value_t = 40)]
    seconds: u64,
    /// Directory of map files.
    #[arg(long, default_value = "maps")]
    maps: PathBuf,
    /// Where to write the figures as CSV.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Where to draw stalls per minute against loss, one line per carrier (SVG).
    #[arg(long)]
    plot: Option<PathBuf>,
}

/// A gap over this between drawn ticks is a stall one sees (three frames at 20 Hz).
const STALL_MS: f64 = 150.0;
/// Key presses for own-motion latency (one a second from the start of the run).
const PRESSES: usize = 15;

/// The page-side hook for the stalls: the time of every frame that draws a newer tick (and
/// the bytes received so far). Own motion is `own_motion::HOOK`'s.
const DRAWN_HOOK: &str = r#"(() => {
  const p = window.__probe = { drawn: [], tick: null, rx0: window.__lasertag.rxBytes || 0 };
  const loop = () => requestAnimationFrame(() => {
    const d = window.__lasertag;
    if (d.lastTick !== p.tick) { p.tick = d.lastTick; p.drawn.push(performance.now()); }
    loop();
  });
  loop();
  return true;
})()"#;

/// What one run measured.
struct Run {
    gaps_ms: Vec<f64>,
    latencies_ms: Vec<f64>,
    bytes_per_s: f64,
    seconds: f64,
}

impl Run {
    fn stalls_per_min(&self) -> f64 {
        self.gaps_ms.iter().filter(|&&g| g > STALL_MS).count() as f64 * 60.0 / self.seconds
    }
}

#[tokio::main]
async fn main() {
    let args = Args::parse();
    if let Err(e) = run(args).await {
        eprintln!("page_transport_probe: {e}");
        std::process::exit(1);
    }
}

async fn run(args: Args) -> Result<(), String> {
    let losses = if args.loss.is_empty() {
        vec![0, 1, 2, 5]
    } else {
        args.loss.clone()
    };
    if losses.iter().any(|&l| l > 50) {
        return Err("--loss: percentages in 0..=50".into());
    }
    if !(1..=1000).contains(&args.rtt_ms) {
        return Err(format!("--rtt-ms {} must be in 1..=1000", args.rtt_ms));
    }
    if !(10..=600).contains(&args.seconds) {
        return Err(format!("--seconds {} must be in 10..=600", args.seconds));
    }
    println!(
        "| loss each way | carrier | drawn ticks (s) | gap p50 / p99 / max (ms) | stalls > 150 ms per minute | key → own disc moves, p50 / max (ms) | bytes/s received |"
    );
    println!("|---|---|---|---|---|---|---|");
    let mut rows = vec![
        "rtt_ms,loss_pct,carrier,drawn,seconds,gap_p50_ms,gap_p99_ms,gap_max_ms,stalls_per_min,own_p50_ms,own_max_ms,presses_seen,bytes_per_s".to_string(),
    ];
    let mut curves: Vec<(&str, Vec<(f64, f64)>)> =
        vec![("WebSocket", Vec::new()), ("WebTransport", Vec::new())];
    for &loss in &losses {
        let link = link::Link::start(link::Shape {
            rtt: Duration::from_millis(args.rtt_ms),
            loss: f64::from(loss) / 100.0,
            seed: u64::from(loss) + 1,
        })
        .map_err(|e| format!("the link emulator: {e} (needs root, ip and nftables)"))?;
        let (maps, ip) = (args.maps.clone(), link.server_ip.into());
        let addr = link
            .serve_inside(
                move || async move { in_process::start_with_webtransport_on(&maps, ip).await },
            )
            .await
            .map_err(|e| e.to_string())??;
        let origin = format!("http://{addr}");
        for (c, carrier) in ["websocket", "webtransport"].into_iter().enumerate() {
            let mut browser = cdp::Browser::launch_with(&[format!(
                "--unsafely-treat-insecure-origin-as-secure={origin}"
            )])
            .await;
            let r = play(&mut browser, &origin, carrier, args.seconds).await?;
            // The figures once, then as a CSV row and as a table row.
            let f = [
                (r.gaps_ms.len() + 1) as f64,
                r.seconds,
                percentile(&r.gaps_ms, 0.5),
                percentile(&r.gaps_ms, 0.99),
                percentile(&r.gaps_ms, 1.0),
                r.stalls_per_min(),
                percentile(&r.latencies_ms, 0.5),
                percentile(&r.latencies_ms, 1.0),
                r.latencies_ms.len() as f64,
                r.bytes_per_s,
            ];
            let row = format!(
                "{},{loss},{carrier},{:.0},{:.1},{:.0},{:.0},{:.0},{:.1},{:.0},{:.0},{:.0},{:.0}",
                args.rtt_ms, f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], f[8], f[9]
            );
            println!(
                "| {loss}% | {carrier} | {:.0} ({:.0}) | {:.0} / {:.0} / {:.0} | {:.1} | {:.0} / {:.0} ({:.0} presses) | {:.0} |",
                f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], f[8], f[9]
            );
            rows.push(row);
            curves[c].1.push((f64::from(loss), r.stalls_per_min()));
        }
    }
    if let Some(path) = &args.csv {
        std::fs::write(path, rows.join("\n") + "\n")
            .map_err(|e| format!("writing {}: {e}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(path) = &args.plot {
        let series: Vec<lasertag_lab::plot::Series> = curves
            .into_iter()
            .map(|(name, points)| lasertag_lab::plot::Series { name, points })
            .collect();
        lasertag_lab::plot::lines(
            path,
            &format!(
                "Stalls in Chromium at {} ms round trip (gaps > 150 ms between drawn ticks)",
                args.rtt_ms
            ),
            "loss each way (%)",
            "stalls per minute",
            &series,
        )
        .map_err(|e| e.to_string())?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}

/// One run: a fresh match played from the page over `carrier` for `seconds`.
async fn play(
    b: &mut cdp::Browser,
    origin: &str,
    carrier: &str,
    seconds: u64,
) -> Result<Run, String> {
    let http = reqwest::Client::new();
    let body = json!({"map": "office", "robots": 2, "opponents": 8,
        "opponent_control": "bot", "opponent_bot": "evade", "bots_joinable": true,
        "time_limit_s": 900,
        "robot_starts": [[22.0, 1.5, 0.0], [22.0, 14.0, 0.0]],
        "opponent_starts": [[6.0, 8.0], [10.0, 14.5], [14.0, 1.5], [14.0, 15.2], [2.0, 5.2],
            [3.0, 12.5], [21.5, 10.8], [23.0, 8.0]]});
    let created: Value = http
        .post(format!("{origin}/api/matches"))
        .json(&body)
        .send()
        .await
        .map_err(|e| format!("creating the match: {e}"))?
        .json()
        .await
        .map_err(|e| e.to_string())?;
    let id = created["id"]
        .as_str()
        .ok_or_else(|| format!("creating the match: {created}"))?
        .to_string();
    b.navigate(&format!("{origin}/")).await;
    b.wait_for("document.readyState === 'complete'", 30).await;
    b.eval(&format!(
        "localStorage.setItem('lasertag.transport', '{carrier}'); localStorage.setItem('lasertag.predict', 'on')"
    ))
    .await;
    b.navigate(&format!("{origin}/?probe={id}#/play/{id}"))
        .await;
    b.wait_for(
        &format!(
            "__lasertag.matchId === '{id}' && __lasertag.role === 'player' && __lasertag.transport === '{carrier}' && __lasertag.snapshots > 20"
        ),
        30,
    )
    .await;
    b.eval(DRAWN_HOOK).await;
    b.eval(own_motion::HOOK).await;
    let started = std::time::Instant::now();
    for k in 0..PRESSES {
        let key = if k % 2 == 0 { "KeyW" } else { "KeyS" };
        b.tap(key, Duration::from_millis(400)).await;
        tokio::time::sleep(Duration::from_millis(600)).await;
    }
    let rest = Duration::from_secs(seconds).saturating_sub(started.elapsed());
    tokio::time::sleep(rest).await;
    let probe = b
        .eval(
            "(() => { const p = window.__probe; \
             return { lat: window.__ownMotion.lat, drawn: p.drawn, \
             bytes: (window.__lasertag.rxBytes || 0) - p.rx0, \
             transport: window.__lasertag.transport }; })()",
        )
        .await;
    if probe["transport"] != carrier {
        return Err(format!(
            "the page left {carrier} for {}",
            probe["transport"]
        ));
    }
    let drawn: Vec<f64> =
        serde_json::from_value(probe["drawn"].clone()).map_err(|e| e.to_string())?;
    let latencies_ms: Vec<f64> =
        serde_json::from_value(probe["lat"].clone()).map_err(|e| e.to_string())?;
    // Over the span drawn: a match that ended draws no more ticks.
    let seconds = match (drawn.first(), drawn.last()) {
        (Some(a), Some(b)) if b > a => (b - a) / 1000.0,
        _ => return Err(format!("the page drew {} ticks", drawn.len())),
    };
    let _ = http
        .delete(format!("{origin}/api/matches/{id}"))
        .bearer_auth(created["owner_token"].as_str().unwrap_or_default())
        .send()
        .await;
    Ok(Run {
        gaps_ms: drawn.windows(2).map(|w| w[1] - w[0]).collect(),
        latencies_ms,
        bytes_per_s: probe["bytes"].as_f64().unwrap_or(0.0) / seconds,
        seconds,
    })
}
