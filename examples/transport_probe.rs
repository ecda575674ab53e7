//! Snapshot stalls over both carriers under packet loss: a spectator over a WebSocket and one
//! over WebTransport watch the same match at once while nftables drops a share of the
//! packets to and from the server's port, TCP and UDP alike, each way (loopback: no delay;
//! the delay of a real link is the link emulator's). For each loss it reports, per carrier,
//! the gaps between snapshots as they arrive (p50, p99, max), the stalls (gaps over 150 ms)
//! per minute, and the bytes per second; over WebTransport also how many snapshots came as
//! datagrams and how many on the stream (too large for one: their motion also came as a
//! datagram, and a tick counts when its first piece arrives).
//!
//! ```sh
//! cargo run --release --example transport_probe                      # 0, 1, 2, 5% for 40 s each
//! cargo run --release --example transport_probe -- --loss 2 --seconds 60
//! cargo run --release --example transport_probe -- --rtt-ms 150   # through the link emulator
//! ```
//!
//! With `--rtt-ms` the server runs inside the link emulator's namespace
//! (tests/common/link.rs) and the link adds the round trip and the loss, each way, to TCP and
//! UDP alike.
//!
//! Needs root and nftables (`apt-get install nftables`). The table is removed on exit.

#[allow(dead_code)]
#[path = "../tests/common/in_process.rs"]
mod in_process;
#[allow(dead_code)]
#[path = "../tests/common/link.rs"]
mod link;
#[allow(dead_code)]
#[path = "../tests/common/nft.rs"]
mod nft;
#[allow(dead_code)]
#[path = "../tests/common/wt.rs"]
mod wt;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Parser;
use futures_util::StreamExt;
use serde_json::{Value, json};

#[derive(Debug, Parser)]
#[command(about = "Snapshot stalls over WebSocket and WebTransport under packet loss")]
struct Args {
    /// Loss each way, in percent (0..=50), one run each; default 0, 1, 2 and 5.
    #[arg(long, value_delimiter = ',')]
    loss: Vec<u32>,
    /// Round trip added by the link emulator (ms, 0..=1000); 0: loopback, loss from nftables.
    #[arg(long, default_value_t = 0)]
    rtt_ms: u64,
    /// Seconds each run watches (5..=600).
    #[arg(long, default_value_t = 40)]
    seconds: u64,
    /// Directory of map files.
    #[arg(long, default_value = "maps")]
    maps: PathBuf,
    /// Where to write the figures as CSV.
    #[arg(long)]
    csv: Option<PathBuf>,
}

/// A gap over this is a stall one sees (three frames at 20 Hz).
const STALL_MS: f64 = 150.0;

struct Watched {
    gaps_ms: Vec<f64>,
    bytes: usize,
    datagrams: usize,
    streamed: usize,
}

impl Watched {
    fn row(&self, carrier: &str, loss: u32, seconds: f64) -> String {
        let mut g = self.gaps_ms.clone();
        g.sort_by(f64::total_cmp);
        let q = |p: f64| {
            g.get(((g.len() as f64 - 1.0) * p).round() as usize)
                .copied()
                .unwrap_or(f64::NAN)
        };
        let stalls = g.iter().filter(|&&x| x > STALL_MS).count() as f64 * 60.0 / seconds;
        format!(
            "{loss},{carrier},{},{:.0},{:.0},{:.0},{stalls:.1},{:.0},{},{}",
            g.len() + 1,
            q(0.5),
            q(0.99),
            g.last().copied().unwrap_or(f64::NAN),
            self.bytes as f64 / seconds,
            self.datagrams,
            self.streamed,
        )
    }
}

fn gaps(arrivals: &[Instant]) -> Vec<f64> {
    arrivals
        .windows(2)
        .map(|w| (w[1] - w[0]).as_secs_f64() * 1000.0)
        .collect()
}

async fn over_websocket(addr: std::net::SocketAddr, id: &str, until: Instant) -> Watched {
    let url = format!("ws://{addr}/ws/matches/{id}?format=compact");
    let (mut ws, _) = tokio_tungstenite::connect_async(url)
        .await
        .expect("a WebSocket");
    let (mut arrivals, mut bytes) = (Vec::new(), 0);
    while let Ok(Some(Ok(m))) = tokio::time::timeout_at(until.into(), ws.next()).await {
        if let tokio_tungstenite::tungstenite::Message::Binary(b) = m {
            bytes += b.len();
            arrivals.push(Instant::now());
        }
    }
    Watched {
        gaps_ms: gaps(&arrivals),
        bytes,
        datagrams: 0,
        streamed: 0,
    }
}

async fn over_webtransport(addr: std::net::SocketAddr, id: &str, until: Instant) -> Watched {
    let reply: Value = reqwest::get(format!("http://{addr}/api/transport"))
        .await
        .expect("GET /api/transport")
        .json()
        .await
        .expect("JSON");
    let (url, hash) = wt::published(&reply);
    let c = wt::WtClient::connect(&format!("{url}/ws/matches/{id}?format=compact"), &hash)
        .await
        .expect("a session");
    let (mut snapshots, conn) = c.snapshots();
    let (mut arrivals, mut bytes, mut datagrams, mut streamed) = (Vec::new(), 0, 0, 0);
    // A tick's first arrival is when the page can show it (a large snapshot comes twice:
    // its motion as a datagram, the whole on the stream). The client acknowledges what it
    // holds, as the page does, so snapshots come as deltas against those.
    let mut newest = None;
    let mut held = wt::Held::default();
    while let Ok(Some(a)) = tokio::time::timeout_at(until.into(), snapshots.recv()).await {
        if a.datagram {
            bytes += a.bytes.len() + 1;
            datagrams += 1;
        } else {
            bytes += a.bytes.len() + 5;
            streamed += 1;
        }
        let tick = lasertag::protocol::compact::tick_of(&a.bytes);
        if tick > newest {
            newest = tick;
            arrivals.push(Instant::now());
        }
        if let (Ok(Some(_)), Some(ack)) = (held.take(a.bytes), held.ack_due()) {
            let _ = conn.send_datagram(ack);
        }
    }
    Watched {
        gaps_ms: gaps(&arrivals),
        bytes,
        datagrams,
        streamed,
    }
}

#[tokio::main]
async fn main() {
    let args = Args::parse();
    let losses = if args.loss.is_empty() {
        vec![0, 1, 2, 5]
    } else {
        args.loss.clone()
    };
    assert!(
        losses.iter().all(|&l| l <= 50),
        "--loss: percentages in 0..=50"
    );
    assert!((5..=600).contains(&args.seconds), "--seconds: 5..=600");
    let header = "loss_pct,carrier,snapshots,gap_p50_ms,gap_p99_ms,gap_max_ms,stalls_per_min,bytes_per_s,datagrams,streamed";
    let mut rows = vec![header.to_string()];
    println!(
        "| loss each way | carrier | snapshots | gap p50 / p99 / max (ms) | stalls > 150 ms per minute | bytes/s | datagrams / on the stream |"
    );
    println!("|---|---|---|---|---|---|---|");
    assert!(args.rtt_ms <= 1000, "--rtt-ms: 0..=1000");
    for loss in losses {
        // Through the link emulator (delay and loss both ways, the server in its namespace),
        // or on loopback with nftables' loss.
        let link = (args.rtt_ms > 0).then(|| {
            link::Link::start(link::Shape {
                rtt: Duration::from_millis(args.rtt_ms),
                loss: f64::from(loss) / 100.0,
                seed: u64::from(loss),
            })
            .expect("the link emulator starts (root, ip, nftables)")
        });
        let addr = match &link {
            None => in_process::start_with_webtransport(&args.maps)
                .await
                .expect("the server starts"),
            Some(link) => {
                let (maps, ip) = (args.maps.clone(), link.server_ip.into());
                link.serve_inside(move || async move {
                    in_process::start_with_webtransport_on(&maps, ip).await
                })
                .await
                .expect("a runtime inside the link")
                .expect("the server starts")
            }
        };
        let client = reqwest::Client::new();
        let created: Value = client
            .post(format!("http://{addr}/api/matches"))
            .json(
                &json!({"map": "office", "robots": 2, "opponents": 2, "opponent_control": "bot",
                "planner": "idle", "time_limit_s": 900}),
            )
            .send()
            .await
            .expect("POST /api/matches")
            .json()
            .await
            .expect("JSON");
        let id = created["id"].as_str().expect("a match").to_string();
        let _loss = (loss > 0 && link.is_none()).then(|| nft::Loss::udp_and_tcp(addr.port(), loss));
        let until = Instant::now() + Duration::from_secs(args.seconds);
        let (ws, wt) = tokio::join!(
            over_websocket(addr, &id, until),
            over_webtransport(addr, &id, until)
        );
        let seconds = args.seconds as f64;
        drop(link);
        for (name, w) in [("websocket", &ws), ("webtransport", &wt)] {
            let row = w.row(name, loss, seconds);
            let f: Vec<&str> = row.split(',').collect();
            println!(
                "| {loss}% | {name} | {} | {} / {} / {} | {} | {} | {} |",
                f[2],
                f[3],
                f[4],
                f[5],
                f[6],
                f[7],
                if name == "webtransport" {
                    format!("{} / {}", f[8], f[9])
                } else {
                    "–".into()
                }
            );
            rows.push(row);
        }
    }
    if let Some(path) = args.csv {
        std::fs::write(&path, rows.join("\n") + "\n").expect("the CSV is written");
        eprintln!("wrote {}", path.display());
    }
}
