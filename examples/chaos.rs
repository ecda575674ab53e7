//! Chaos: a server killed with SIGKILL again and again while it plays, every match compared
//! with its twin on a server that is never killed (docs/operations.md, "Matches survive their
//! server").
//!
//! ```sh
//! cargo build --release
//! cargo run --release --example chaos -- --minutes 10 --kill-every-s 30   # the issue's run
//! cargo run --release --example chaos -- --minutes 2                      # a quick look
//! ```
//!
//! Bounded, loopback only, self-stopping. Two release servers on loopback, each on a store of
//! its own: *chaos*, killed with SIGKILL every `--kill-every-s` seconds (at a random moment
//! within the second, so some kills land in the middle of a store write) and started again
//! at once on the same address and data directory; and *twin*, never killed. On chaos run:
//!
//! - `--bots` real-time matches of bots against the coordinated team, each with a seed of its
//!   own and a time limit of 1 to 3 minutes (one that ends is replaced); its twin is the same
//!   match on the twin server, stepped by hand to its end: winner and last tick must agree.
//! - `--api` manual matches driven over HTTP at 20 steps a second (`act`, one tick, 8
//!   robots' commands a function of the tick); the client reads the tick the match answers
//!   and goes on from there after a restart. Its twin gets each tick's commands once; at the
//!   end both are read at the same tick: state, belief and events must agree.
//! - `--players` real-time matches with a person's WebSocket each (keys changing every
//!   100 ms; the robots there stand idle, so that the person is still playing at every kill) and `--spectators` spectators on the bots' matches: each reconnects after a
//!   crash with its token, as the page does (growing waits, up to 30 s). A person's match has
//!   no twin (its inputs follow the wall clock): it counts as lost if it does not come back.
//!
//! Per crash it measures how long the server took to answer every running match again (from
//! its spawn) and how much play each real-time match lost (its tick just before the kill
//! against the tick it was resumed at, from the server's log). At the end: matches lost,
//! matches that differ from their twins, time to resume p50 and max, seconds of play lost
//! per crash p50 and max, and people's seats regained. Exit status 1 if any match was lost
//! or differs.
//!
//! Long file: a measurement program, one scenario read from top to bottom.

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use clap::Parser;
use futures_util::{SinkExt, StreamExt};
use rand::{RngExt, SeedableRng};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;

#[derive(Debug, Parser)]
#[command(about = "Chaos: SIGKILL a server again and again; compare every match with its twin")]
struct Args {
    /// Minutes to run (1..=120).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..=120))]
    minutes: u64,
    /// Seconds between kills (5..=600).
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u64).range(5..=600))]
    kill_every_s: u64,
    /// Real-time bots matches kept running (0..=100).
    #[arg(long, default_value_t = 12, value_parser = clap::value_parser!(u64).range(0..=100))]
    bots: u64,
    /// Manual matches driven over HTTP (0..=20).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(0..=20))]
    api: u64,
    /// Real-time matches with a person's WebSocket each (0..=50).
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u64).range(0..=50))]
    players: u64,
    /// Spectators' WebSockets on the bots' matches (0..=500).
    #[arg(long, default_value_t = 40, value_parser = clap::value_parser!(u64).range(0..=500))]
    spectators: u64,
    /// Seed of the matches and of the kills' moments.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// A server process on a fixed address, its log read for the ticks it resumed matches at.
struct Server {
    child: Child,
    addr: String,
    /// Match id → the tick it was resumed at, by the server's log.
    resumed: Arc<Mutex<BTreeMap<String, u64>>>,
}

impl Server {
    fn start(bin: &Path, addr: &str, data: &Path) -> Server {
        let mut child = Command::new(bin)
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(["serve", "--no-showcase", "--addr", addr])
            .arg("--data-dir")
            .arg(data)
            .env(
                "RUST_LOG",
                "info,lasertag::game::task=warn,lasertag::http=warn",
            )
            .env("NO_COLOR", "1")
            .env("LASERTAG_REQUESTS_PER_S", "1000000")
            .env("LASERTAG_REQUEST_BURST", "1000000")
            .env("LASERTAG_MAX_MATCHES_PER_ADDRESS", "1000")
            .env("LASERTAG_MAX_SEATS_PER_ADDRESS", "1000")
            .env("LASERTAG_MAX_HOLDS_PER_ADDRESS", "1000")
            .env("LASERTAG_CLIENT_BUDGET_SHARE", "1")
            .env("LASERTAG_IDLE_MANUAL_AFTER_S", "86400")
            .env("LASERTAG_MAX_CONNECTIONS_PER_ADDRESS", "100000")
            .env("LASERTAG_MAX_TCP_PER_ADDRESS", "100000")
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("the server starts");
        let resumed = Arc::new(Mutex::new(BTreeMap::new()));
        let stdout = child.stdout.take().expect("piped stdout");
        let log = resumed.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if line.contains("match rebuilt") {
                    let field = |name: &str| {
                        line.split(&format!("{name}=")).nth(1).map(|r| {
                            r.split_whitespace()
                                .next()
                                .unwrap_or("")
                                .trim_matches('"')
                                .to_string()
                        })
                    };
                    if let (Some(id), Some(tick)) =
                        (field("id"), field("tick").and_then(|t| t.parse().ok()))
                    {
                        log.lock().unwrap().insert(id, tick);
                    }
                }
            }
        });
        Server {
            child,
            addr: addr.to_string(),
            resumed,
        }
    }

    fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn free_addr() -> String {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("a free port");
    l.local_addr().expect("its address").to_string()
}

/// `method path` with an optional token and body: (status, body), or `None` while the server
/// is down.
async fn call(
    http: &reqwest::Client,
    method: reqwest::Method,
    url: String,
    token: Option<&str>,
    body: Option<&Value>,
) -> Option<(u16, Value)> {
    let mut r = http.request(method, url).timeout(Duration::from_secs(10));
    if let Some(t) = token {
        r = r.bearer_auth(t);
    }
    if let Some(b) = body {
        r = r.json(b);
    }
    let r = r.send().await.ok()?;
    let status = r.status().as_u16();
    Some((status, r.json().await.unwrap_or(Value::Null)))
}

/// `GET url`: (status, body), or `None` while the server is down.
async fn get(http: &reqwest::Client, url: String) -> Option<(u16, Value)> {
    call(http, reqwest::Method::GET, url, None, None).await
}

/// Like [`call`], but waits out a server that is down or still resuming the match (503).
async fn patient(
    http: &reqwest::Client,
    method: reqwest::Method,
    url: String,
    token: Option<&str>,
    body: Option<&Value>,
) -> (u16, Value) {
    for _ in 0..1200 {
        match call(http, method.clone(), url.clone(), token, body).await {
            Some((503, _)) | None => tokio::time::sleep(Duration::from_millis(50)).await,
            Some(answer) => return answer,
        }
    }
    panic!("{url}: no answer within a minute");
}

async fn create(http: &reqwest::Client, base: &str, body: &Value) -> (String, String) {
    let (status, r) = patient(
        http,
        reqwest::Method::POST,
        format!("{base}/api/matches"),
        None,
        Some(body),
    )
    .await;
    assert_eq!(status, 201, "{r}");
    (
        r["id"].as_str().unwrap().into(),
        r["owner_token"].as_str().unwrap().into(),
    )
}

/// The commands an API match's robots get at `tick`.
fn commands_at(tick: u64) -> Value {
    let robots: serde_json::Map<String, Value> = (0..8)
        .map(|r| {
            let phase = (tick / 40 + r) % 4;
            let turn = [0.0, 0.6, -0.6, 0.2][phase as usize];
            (format!("r{r}"), json!({"forward": 0.8, "turn": turn}))
        })
        .collect();
    json!({"commands": robots, "ticks": 1})
}

/// State, belief and events of a match as its owner reads them, without what names it.
async fn reading(http: &reqwest::Client, base: &str, id: &str, token: &str) -> Value {
    let get = |path: String| async move {
        patient(
            http,
            reqwest::Method::GET,
            format!("{base}{path}"),
            Some(token),
            None,
        )
        .await
        .1
    };
    let mut state = get(format!("/api/matches/{id}")).await;
    if let Some(o) = state.as_object_mut() {
        o.remove("id");
    }
    json!({
        "state": state,
        "belief": get(format!("/api/matches/{id}/belief")).await,
        "events": get(format!("/api/matches/{id}/events")).await["events"],
    })
}

#[derive(Default)]
struct Tally {
    lost: Vec<String>,
    differing: Vec<String>,
    compared: u64,
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let args = Args::parse();
    let exe = std::env::current_exe().expect("this program's path");
    let bin = exe
        .parent()
        .and_then(Path::parent)
        .map(|d| d.join("lasertag"))
        .filter(|b| b.exists())
        .expect("the release binary next to the examples: run `cargo build --release` first");
    let tmp: PathBuf = std::env::temp_dir().join(format!("lasertag-chaos-{}", std::process::id()));
    let (chaos_dir, twin_dir) = (tmp.join("chaos"), tmp.join("twin"));
    let _ = std::fs::remove_dir_all(&tmp);
    let chaos_addr = free_addr();
    let chaos = Arc::new(Mutex::new(Server::start(&bin, &chaos_addr, &chaos_dir)));
    let twin = Server::start(&bin, &free_addr(), &twin_dir);
    let (base, twin_base) = (
        format!("http://{chaos_addr}"),
        format!("http://{}", twin.addr),
    );
    let http = reqwest::Client::new();
    patient(
        &http,
        reqwest::Method::GET,
        format!("{base}/api/health"),
        None,
        None,
    )
    .await;
    patient(
        &http,
        reqwest::Method::GET,
        format!("{twin_base}/api/health"),
        None,
        None,
    )
    .await;
    let stop = Arc::new(AtomicBool::new(false));
    let run_until = Instant::now() + Duration::from_secs(args.minutes * 60);
    let tally = Arc::new(Mutex::new(Tally::default()));
    let mut tasks = Vec::new();

    // Bots' matches, each replaced when it ends; its twin stepped to its end on the twin.
    let next_seed = Arc::new(AtomicU64::new(args.seed * 100_000));
    let bots_ids = Arc::new(Mutex::new(Vec::<String>::new()));
    for _ in 0..args.bots {
        let (http, base, twin_base, stop, tally, next_seed, ids) = (
            http.clone(),
            base.clone(),
            twin_base.clone(),
            stop.clone(),
            tally.clone(),
            next_seed.clone(),
            bots_ids.clone(),
        );
        tasks.push(tokio::spawn(async move {
            while !stop.load(Ordering::Relaxed) {
                let seed = next_seed.fetch_add(1, Ordering::Relaxed);
                let body = json!({"map": "office", "robots": 2, "opponents": 2, "opponent_bot": "evade",
                    "seed": seed, "time_limit_s": 60 + (seed % 3) * 60});
                let (id, _) = create(&http, &base, &body).await;
                ids.lock().unwrap().push(id.clone());
                // Its end, from the history once it is over.
                let end = loop {
                    tokio::time::sleep(Duration::from_millis(500)).await;
                    if stop.load(Ordering::Relaxed) {
                        break None;
                    }
                    match get(&http, format!("{base}/api/replays/{id}")).await {
                        Some((200, r)) => break Some(r),
                        Some((404, _)) => {
                            // Not ended: it must be running (or being resumed).
                            if let Some((404, _)) = get(&http, format!("{base}/api/matches/{id}")).await
                                && get(&http, format!("{base}/api/replays/{id}")).await.is_some_and(|(s, _)| s == 404)
                            {
                                tally.lock().unwrap().lost.push(id.clone());
                                break None;
                            }
                        }
                        _ => {}
                    }
                };
                ids.lock().unwrap().retain(|x| *x != id);
                let Some(end) = end else { continue };
                let mut twin_body = body.clone();
                twin_body["clock"] = json!("manual");
                let (twin_id, twin_token) = create(&http, &twin_base, &twin_body).await;
                let (_, twin_end) = patient(&http, reqwest::Method::POST, format!("{twin_base}/api/matches/{twin_id}/step"),
                    Some(&twin_token), Some(&json!({"ticks": 100_000}))).await;
                let mut t = tally.lock().unwrap();
                t.compared += 1;
                if end["complete"] != true || end["winner"] != twin_end["winner"] || end["ticks"] != twin_end["tick"] {
                    eprintln!("bots match {id} differs: {} at {} (complete {}) against its twin's {} at {}",
                        end["winner"], end["ticks"], end["complete"], twin_end["winner"], twin_end["tick"]);
                    t.differing.push(id.clone());
                }
            }
        }));
    }

    // API-driven manual matches, and their twins stepped once per tick.
    let mut api_matches = Vec::new();
    for k in 0..args.api {
        let body = json!({"map": "office", "clock": "manual", "seed": args.seed * 1000 + k, "robots": 8,
            "opponents": 1, "planner": "api", "localisation": false, "time_limit_s": 86400});
        let (id, token) = create(&http, &base, &body).await;
        let (twin_id, twin_token) = create(&http, &twin_base, &body).await;
        api_matches.push((id.clone(), token.clone(), twin_id, twin_token));
        let (http, base, stop) = (http.clone(), base.clone(), stop.clone());
        tasks.push(tokio::spawn(async move {
            let mut tick = 0;
            // Twenty steps a second, as a match in real time: a client that steps as fast as
            // it can runs hours of play in minutes (and reaches its record's bound).
            let mut pace = tokio::time::interval(Duration::from_millis(50));
            while !stop.load(Ordering::Relaxed) {
                pace.tick().await;
                let act = call(
                    &http,
                    reqwest::Method::POST,
                    format!("{base}/api/matches/{id}/act"),
                    Some(&token),
                    Some(&commands_at(tick)),
                )
                .await;
                match act {
                    Some((200, r)) => tick = r["tick"].as_u64().expect("a tick"),
                    Some((503, _)) | None => {
                        // A restart: the match goes on from its last stored tick, which the
                        // next commands must follow (they are a function of the tick).
                        let (status, r) = patient(
                            &http,
                            reqwest::Method::GET,
                            format!("{base}/api/matches/{id}"),
                            Some(&token),
                            None,
                        )
                        .await;
                        assert_eq!(status, 200, "{id}: {r}");
                        tick = r["tick"].as_u64().expect("a tick");
                    }
                    Some((status, r)) => panic!("act on {id}: {status} {r}"),
                }
            }
        }));
    }

    // People: a WebSocket each that sends keys and reconnects with its token.
    let seats_regained = Arc::new(AtomicU64::new(0));
    let player_matches = Arc::new(Mutex::new(Vec::<String>::new()));
    for k in 0..args.players {
        let body = json!({"map": "office", "opponent_control": "human", "opponents": 1, "robots": 2,
            "planner": "idle", "time_limit_s": 3600});
        let (id, _) = create(&http, &base, &body).await;
        let (status, joined) = patient(
            &http,
            reqwest::Method::POST,
            format!("{base}/api/matches/{id}/players"),
            None,
            Some(&json!({"name": format!("chaos{k}")})),
        )
        .await;
        assert_eq!(status, 201, "{joined}");
        player_matches.lock().unwrap().push(id.clone());
        let token = joined["token"].as_str().unwrap().to_string();
        let (stop, regained, addr) = (stop.clone(), seats_regained.clone(), chaos_addr.clone());
        tasks.push(tokio::spawn(async move {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(k);
            let mut connections = 0u64;
            while !stop.load(Ordering::Relaxed) {
                let url = format!("ws://{addr}/ws/matches/{id}?token={token}");
                let Ok((mut ws, _)) = tokio_tungstenite::connect_async(url).await else {
                    tokio::time::sleep(Duration::from_millis(250)).await;
                    continue;
                };
                connections += 1;
                if connections > 1 {
                    regained.fetch_add(1, Ordering::Relaxed);
                }
                let mut seq = 0u64;
                let mut keys = tokio::time::interval(Duration::from_millis(100));
                loop {
                    tokio::select! {
                        msg = ws.next() => match msg {
                            Some(Ok(Message::Close(_))) | Some(Err(_)) | None => break,
                            _ => {}
                        },
                        _ = keys.tick() => {
                            seq += 1;
                            let input = json!({"type": "input", "seq": seq, "forward": rng.random_range(-1.0..1.0),
                                "turn": rng.random_range(-1.0..1.0), "tag": false});
                            if ws.send(Message::Text(input.to_string().into())).await.is_err() {
                                break;
                            }
                        }
                    }
                    if stop.load(Ordering::Relaxed) {
                        return;
                    }
                }
            }
        }));
    }

    // Spectators on the bots' matches, reconnecting as the page does.
    for k in 0..args.spectators {
        let (stop, ids, addr) = (stop.clone(), bots_ids.clone(), chaos_addr.clone());
        tasks.push(tokio::spawn(async move {
            while !stop.load(Ordering::Relaxed) {
                let id = {
                    let ids = ids.lock().unwrap();
                    if ids.is_empty() {
                        None
                    } else {
                        Some(ids[k as usize % ids.len()].clone())
                    }
                };
                let Some(id) = id else {
                    tokio::time::sleep(Duration::from_millis(250)).await;
                    continue;
                };
                let url = format!("ws://{addr}/ws/matches/{id}?format=compact");
                let Ok((mut ws, _)) = tokio_tungstenite::connect_async(url).await else {
                    tokio::time::sleep(Duration::from_millis(250)).await;
                    continue;
                };
                while let Some(Ok(m)) = ws.next().await {
                    if matches!(m, Message::Close(_)) || stop.load(Ordering::Relaxed) {
                        break;
                    }
                }
            }
        }));
    }

    // The kills.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let mut resume_s = Vec::new();
    let mut lost_play_s: Vec<f64> = Vec::new();
    let mut crashes = 0;
    loop {
        let wait = Duration::from_secs(args.kill_every_s)
            + Duration::from_millis(rng.random_range(0..1000));
        if Instant::now() + wait >= run_until {
            break;
        }
        tokio::time::sleep(wait).await;
        // Each real-time match's live tick just before the kill.
        let mut ticks: BTreeMap<String, u64> = BTreeMap::new();
        let live: Vec<String> = bots_ids
            .lock()
            .unwrap()
            .iter()
            .chain(player_matches.lock().unwrap().iter())
            .cloned()
            .collect();
        if let Some((200, all)) = get(&http, format!("{base}/api/matches")).await {
            for m in all.as_array().into_iter().flatten() {
                if let (Some(id), Some(t)) = (m["id"].as_str(), m["tick"].as_u64())
                    && live.iter().any(|l| l == id)
                {
                    ticks.insert(id.to_string(), t);
                }
            }
        }
        let spawned = {
            let mut s = chaos.lock().unwrap();
            s.kill();
            crashes += 1;
            *s = Server::start(&bin, &chaos_addr, &chaos_dir);
            Instant::now()
        };
        // Back: every match that was running answers again.
        let mut waiting: Vec<String> = ticks.keys().cloned().collect();
        waiting.extend(api_matches.iter().map(|m| m.0.clone()));
        while !waiting.is_empty() {
            let mut still = Vec::new();
            for id in waiting {
                match get(&http, format!("{base}/api/matches/{id}")).await {
                    Some((200, _)) => {}
                    // Ended meanwhile (its replay says so) or not yet back.
                    Some((404, _)) => {
                        let ended = get(&http, format!("{base}/api/replays/{id}")).await;
                        if !matches!(ended, Some((200, _))) {
                            still.push(id)
                        }
                    }
                    _ => still.push(id),
                }
            }
            waiting = still;
            if spawned.elapsed() > Duration::from_secs(120) {
                eprintln!("not back 120 s after the restart: {waiting:?}");
                tally.lock().unwrap().lost.extend(waiting);
                break;
            }
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        let took = spawned.elapsed().as_secs_f64();
        resume_s.push(took);
        let resumed = chaos.lock().unwrap().resumed.lock().unwrap().clone();
        for (id, before) in &ticks {
            if let Some(at) = resumed.get(id) {
                lost_play_s.push(before.saturating_sub(*at) as f64 / 20.0);
            }
        }
        eprintln!(
            "crash {crashes}: {} matches back in {took:.2} s",
            ticks.len() + api_matches.len()
        );
    }
    stop.store(true, Ordering::Relaxed);
    for t in tasks {
        let _ = tokio::time::timeout(Duration::from_secs(120), t).await;
    }

    // API matches against their twins, at the chaos match's tick.
    for (id, token, twin_id, twin_token) in &api_matches {
        let state = reading(&http, &base, id, token).await;
        let tick = state["state"]["tick"].as_u64().unwrap_or(0);
        let mut twin_tick = 0;
        while twin_tick < tick {
            let (status, r) = patient(
                &http,
                reqwest::Method::POST,
                format!("{twin_base}/api/matches/{twin_id}/act"),
                Some(twin_token),
                Some(&commands_at(twin_tick)),
            )
            .await;
            assert_eq!(status, 200, "{r}");
            twin_tick = r["tick"].as_u64().unwrap_or(tick);
        }
        let twin_state = reading(&http, &twin_base, twin_id, twin_token).await;
        let mut t = tally.lock().unwrap();
        t.compared += 1;
        if state != twin_state {
            eprintln!("API match {id} differs from its twin at tick {tick}");
            t.differing.push(id.clone());
        }
    }
    // People's matches: each still there (running, or ended into the history).
    let people: Vec<String> = player_matches.lock().unwrap().clone();
    for id in &people {
        let running = get(&http, format!("{base}/api/matches/{id}")).await;
        let ended = get(&http, format!("{base}/api/replays/{id}")).await;
        if !matches!(running, Some((200, _))) && !matches!(ended, Some((200, _))) {
            tally.lock().unwrap().lost.push(id.clone());
        }
    }
    chaos.lock().unwrap().kill();
    let mut twin = twin;
    twin.kill();
    let _ = std::fs::remove_dir_all(&tmp);

    let pct = |v: &mut Vec<f64>, p: f64| {
        v.sort_by(f64::total_cmp);
        if v.is_empty() {
            0.0
        } else {
            v[((v.len() - 1) as f64 * p).round() as usize]
        }
    };
    let t = tally.lock().unwrap();
    println!(
        "{} min, {crashes} SIGKILLs every {} s: matches lost {}, differing from their twins {} (of {} compared); \
         time to resume p50 {:.2} s, max {:.2} s; play lost per crash and match p50 {:.2} s, max {:.2} s; \
         people's seats regained {}",
        args.minutes,
        args.kill_every_s,
        t.lost.len(),
        t.differing.len(),
        t.compared,
        pct(&mut resume_s, 0.5),
        pct(&mut resume_s, 1.0),
        pct(&mut lost_play_s, 0.5),
        pct(&mut lost_play_s, 1.0),
        seats_regained.load(Ordering::Relaxed),
    );
    if !t.lost.is_empty() || !t.differing.is_empty() {
        eprintln!("lost: {:?}\ndiffering: {:?}", t.lost, t.differing);
        std::process::exit(1);
    }
}
