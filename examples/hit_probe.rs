//! Hit registration over a real network: how often a person's shot at a robot crossing their
//! view at top speed counts, with and without lag compensation.
//!
//! ```sh
//! cargo run --release --example hit_probe                         # 150 ms, robots 2 and 3 m away
//! cargo run --release --example hit_probe -- --rtt-ms 300 --shots 40 --distances 2,4
//! ```
//!
//! It starts the server in this process and puts the network proxy of the tests
//! (`tests/common/netem.rs`) in front of it. For each distance a fresh match: one robot
//! driven from outside (`"planner": "api"`) sweeps back and forth at top speed along a line
//! that distance in front of a player, who plays through the proxy as the game page does:
//! it draws the robot between the last two snapshots a tick behind the newest (the page's
//! adaptive delay on a steady link), notices the frame in which the drawn robot crosses its
//! line of fire, latches the tick it was drawing, and sends the tag with the next 50 ms
//! input. Shots alternate between sending that `view_tick` (the server judges the shot where
//! the robot was drawn) and leaving it out (judged where the robot is when the input
//! arrives). A hit freezes the robot for 10 s; the sweep resumes after. The robot never
//! fires. The table gives hits per shots for each.

#[path = "../tests/common/netem.rs"]
mod netem;

#[path = "../tests/common/in_process.rs"]
mod in_process;

use std::collections::VecDeque;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Parser;
use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

#[derive(Debug, Parser)]
#[command(about = "Hit rates with and without lag compensation over a simulated network")]
struct Args {
    /// Round trip the proxy adds (ms).
    #[arg(long, default_value_t = 150)]
    rtt_ms: u64,
    /// Shots per distance and mode (1..=200).
    #[arg(long, default_value_t = 30)]
    shots: usize,
    /// Distances from the player to the robot's line (m), each in 1..=5.5.
    #[arg(long, value_delimiter = ',', default_values_t = [2.0, 3.0])]
    distances: Vec<f64>,
    /// Directory of map files.
    #[arg(long, default_value = "maps")]
    maps: PathBuf,
}

/// A snapshot as the player keeps it: its tick, when it arrived, and where the robot was.
type Snapshot = (u64, Instant, Option<(f64, f64)>);

const TICK: Duration = Duration::from_millis(50);
/// How far behind the newest snapshot the robot is drawn (ticks).
const DRAW_DELAY_TICKS: f64 = 1.0;
/// Half the sweep: the robot drives this far each side of the line of fire (m).
const HALF_SWEEP_S: f64 = 1.2;

#[tokio::main]
async fn main() {
    let args = Args::parse();
    if let Err(e) = run(args).await {
        eprintln!("hit_probe: {e}");
        std::process::exit(1);
    }
}

async fn run(args: Args) -> Result<(), String> {
    if !(1..=200).contains(&args.shots) {
        return Err(format!("--shots {} must be in 1..=200", args.shots));
    }
    if let Some(d) = args.distances.iter().find(|d| !(1.0..=5.5).contains(*d)) {
        return Err(format!("--distances: {d} must be in 1..=5.5"));
    }
    let server = in_process::start(&args.maps).await?;
    let net = netem::Netem::start(
        server,
        netem::Conditions {
            jitter: Duration::from_millis(args.rtt_ms / 20),
            ..netem::Conditions::rtt_ms(args.rtt_ms)
        },
    )
    .await;
    println!("| round trip | distance | tolerance either side | with lag compensation | without |");
    println!("|---|---|---|---|---|");
    for d in &args.distances {
        let (with, without) = one_distance(server, net.addr, *d, args.shots).await?;
        let pct = |(h, n): (usize, usize)| format!("{h}/{n} ({:.0}%)", 100.0 * h as f64 / n as f64);
        println!(
            "| {} ms | {d} m | {:.2} m | {} | {} |",
            args.rtt_ms,
            d * 5f64.to_radians().tan(),
            pct(with),
            pct(without)
        );
    }
    Ok(())
}

/// (hits, shots) with and without `view_tick` at one distance.
async fn one_distance(
    server: SocketAddr,
    proxy: SocketAddr,
    d: f64,
    shots: usize,
) -> Result<((usize, usize), (usize, usize)), String> {
    let http = reqwest::Client::new();
    let base = format!("http://{server}");
    let (px, py) = (10.0, 2.0);
    let map = json!({"name": "range", "width": 20.0, "height": 10.0, "obstacles": [],
        "robot_spawns": [[px - HALF_SWEEP_S, py + d, 0.0]], "opponent_spawns": [[px, py]]});
    let created: Value = http
        .post(format!("{base}/api/matches"))
        .json(
            &json!({"map": map, "robots": 1, "opponents": 1, "planner": "api",
            "opponent_control": "human", "spectator_delay_s": 0, "time_limit_s": 3600}),
        )
        .send()
        .await
        .map_err(|e| e.to_string())?
        .json()
        .await
        .map_err(|e| e.to_string())?;
    let id = created["id"]
        .as_str()
        .ok_or(format!("creating: {created}"))?
        .to_string();
    let owner = created["owner_token"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    let joined: Value = http
        .post(format!("{base}/api/matches/{id}/players"))
        .json(&json!({"name": "marksman"}))
        .send()
        .await
        .map_err(|e| e.to_string())?
        .json()
        .await
        .map_err(|e| e.to_string())?;
    let token = joined["token"]
        .as_str()
        .ok_or(format!("joining: {joined}"))?;
    let (mut ws, _) =
        tokio_tungstenite::connect_async(format!("ws://{proxy}/ws/matches/{id}?token={token}"))
            .await
            .map_err(|e| format!("connecting: {e}"))?;

    // The robot's sweep, driven over loopback (the robot's brain is not the player): it
    // turns back past either end, read from the truth, so a freeze does not shift it.
    let sweep = {
        let (http, base, id, owner) = (http.clone(), base.clone(), id.clone(), owner.clone());
        tokio::spawn(async move {
            let mut forward = 0.0;
            loop {
                let state: Value = match http
                    .get(format!("{base}/api/matches/{id}"))
                    .bearer_auth(&owner)
                    .send()
                    .await
                {
                    Ok(r) => r.json().await.unwrap_or_default(),
                    Err(_) => break,
                };
                let x = state["robots"][0]["x"].as_f64().unwrap_or(px);
                let want = if x >= px + HALF_SWEEP_S {
                    -1.0
                } else if x <= px - HALF_SWEEP_S || forward == 0.0 {
                    1.0
                } else {
                    forward
                };
                if want != forward {
                    forward = want;
                    let _ = http
                        .post(format!("{base}/api/matches/{id}/robots/r0/command"))
                        .bearer_auth(&owner)
                        .json(&json!({"forward": forward}))
                        .send()
                        .await;
                }
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
        })
    };

    // What the player has received: (tick, arrival, robot x, y) and its own pose.
    let mut snaps: VecDeque<Snapshot> = VecDeque::new();
    let mut own: Option<(f64, f64, f64)> = None;
    let mut frame = tokio::time::interval(Duration::from_millis(16));
    let mut input = tokio::time::interval(TICK);
    let (mut seq, mut last_side, mut latched): (u64, Option<f64>, Option<u64>) = (0, None, None);
    let mut shot_modes: VecDeque<(bool, Instant, u64)> = VecDeque::new();
    // How far back each compensated shot was judged (ticks from the view to the shot).
    let mut rewound: Vec<u64> = Vec::new();
    let (mut with, mut without) = ((0, 0), (0, 0));
    let mut next_with = true;
    let deadline = Instant::now() + Duration::from_secs(60 + shots as u64 * 30);
    while (with.1 < shots || without.1 < shots) && Instant::now() < deadline {
        tokio::select! {
            msg = ws.next() => {
                let Some(Ok(Message::Text(t))) = msg else { continue };
                let v: Value = serde_json::from_str(&t).unwrap_or_default();
                match v["type"].as_str() {
                    Some("snapshot") => {
                        let tick = v["tick"].as_u64().unwrap_or(0);
                        let robot = v["robots"].as_array().and_then(|r| r.first())
                            .and_then(|r| Some((r["x"].as_f64()?, r["y"].as_f64()?)));
                        if let Some(me) = v["opponents"].as_array().and_then(|o| o.iter().find(|o| o["id"] == "o0")) {
                            own = Some((me["x"].as_f64().unwrap_or(px), me["y"].as_f64().unwrap_or(py), me["theta"].as_f64().unwrap_or(0.0)));
                        }
                        snaps.push_back((tick, Instant::now(), robot));
                        if snaps.len() > 20 { snaps.pop_front(); }
                    }
                    Some("event") => {
                        let e = &v;
                        if e["kind"] == "shot" && e["by"] == "o0"
                            && let Some((mode, _, view)) = shot_modes.pop_front() {
                                let hit = e["hit"] == "r0";
                                if let (true, Some(t)) = (mode, e["tick"].as_u64()) {
                                    rewound.push(t.saturating_sub(view));
                                }
                                let slot = if mode { &mut with } else { &mut without };
                                slot.0 += hit as usize;
                                slot.1 += 1;
                        }
                    }
                    _ => {}
                }
            }
            _ = frame.tick() => {
                let (Some((ox, oy, theta)), Some(drawn)) = (own, draw(&snaps)) else { continue };
                let ((rx, ry), tick) = drawn;
                let bearing = wrap((ry - oy).atan2(rx - ox) - theta);
                if let Some(prev) = last_side
                    && prev.signum() != bearing.signum()
                    && bearing.abs() < 0.3
                    && latched.is_none()
                    && shot_modes.is_empty()
                {
                    latched = Some(tick);
                }
                last_side = Some(bearing);
            }
            _ = input.tick() => {
                seq += 1;
                // Face the robot's line (+y) first; then stand still and shoot.
                let turn = own.map_or(0.0, |(_, _, th)| (wrap(std::f64::consts::FRAC_PI_2 - th) * 2.0).clamp(-1.0, 1.0));
                let turn = if turn.abs() < 0.02 { 0.0 } else { turn };
                let mut msg = json!({"type": "input", "seq": seq, "forward": 0.0, "turn": turn, "tag": false});
                if let Some(view) = latched.take() {
                    msg["tag"] = json!(true);
                    if next_with {
                        msg["view_tick"] = json!(view);
                    }
                    shot_modes.push_back((next_with, Instant::now(), view));
                    next_with = !next_with;
                }
                if ws.send(Message::Text(msg.to_string().into())).await.is_err() {
                    break;
                }
                // A shot whose event never came (the match ended) is not waited for forever.
                while shot_modes.front().is_some_and(|(_, t, _)| t.elapsed() > Duration::from_secs(3)) {
                    shot_modes.pop_front();
                }
            }
        }
    }
    sweep.abort();
    rewound.sort_unstable();
    if let (Some(lo), Some(hi)) = (rewound.first(), rewound.last()) {
        eprintln!(
            "{d} m: compensated shots judged {lo} to {hi} ticks back (median {})",
            rewound[rewound.len() / 2]
        );
    }
    let _ = http
        .delete(format!("{base}/api/matches/{id}"))
        .bearer_auth(&owner)
        .send()
        .await;
    Ok((with, without))
}

/// The robot as the page draws it now, and the tick it is drawing (rounded).
fn draw(snaps: &VecDeque<Snapshot>) -> Option<((f64, f64), u64)> {
    let &(newest, at, _) = snaps.back()?;
    let render = (newest as f64 + at.elapsed().as_secs_f64() / TICK.as_secs_f64()
        - DRAW_DELAY_TICKS)
        .min(newest as f64);
    let before = snaps.iter().rev().find(|s| s.0 as f64 <= render)?;
    let after = snaps.iter().find(|s| s.0 as f64 >= render)?;
    let (a, b) = (before.2?, after.2?);
    let span = (after.0 - before.0) as f64;
    let f = if span > 0.0 {
        (render - before.0 as f64) / span
    } else {
        0.0
    };
    Some((
        (a.0 + (b.0 - a.0) * f, a.1 + (b.1 - a.1) * f),
        render.round() as u64,
    ))
}

fn wrap(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    (a + std::f64::consts::PI).rem_euclid(t) - std::f64::consts::PI
}
