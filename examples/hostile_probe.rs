//! Hostile requests against a real server process, measured from outside: what each class of
//! expensive or unauthorised request gets, and what it costs the server and its other users.
//!
//! ```sh
//! cargo build --release
//! cargo run --release --example hostile_probe -- --server target/release/lasertag
//! cargo run --release --example hostile_probe -- --server target/release/lasertag --only slowloris,lobby
//! cargo run --release --example hostile_probe -- --server target/release/lasertag --json
//! ```
//!
//! For each class it starts a fresh server process, `<server> serve --addr 127.0.0.1:0 --maps
//! maps --web web`, with every other setting at its default (the showcase runs; `LASERTAG_*`
//! variables are cleared so that the defaults really are the defaults), and reads the port from
//! the server's `serving http://…` log line. It creates a bystander (a real-time match with idle
//! robots on `office`), then sends the class's requests while it watches from outside:
//! - the server's resident memory (`VmRSS` in `/proc/<pid>/status`): before the attack, the
//!   peak (sampled every 50 ms) and after it (2 s after its last answer);
//! - the bystander's tick (`GET /api/matches/{id}` every 100 ms): whether it advanced, its
//!   ticks per second, and the longest time it did not advance (the sampling alone makes that
//!   100–150 ms);
//! - `GET /api/health` every 100 ms: the slowest answer, and answers that never came.
//!
//! Each class is bounded by `--timeout-s` (60 s): a class that takes longer is reported as
//! hung, with whether the server still answers. The server is killed after every class, so one
//! class's memory never pollutes the next. Older builds of the server (no owner tokens, no
//! quotas, no spectator delay) work too: a token is sent only when the server handed one out,
//! and whatever status comes back is reported.
//!
//! The classes (valid requests, each chosen to be expensive):
//! - `map-64-slivers`, `map-256-slivers`: `POST /api/maps` of a 500 m map of thin diagonal
//!   obstacles running corner to corner (a few KB whose long walls cost the most to build);
//! - `expensive-match`: an inline empty 500 m map, 8 robots, 8 opponents, a lossy radio (a
//!   tracker per robot) and a 0.1 m merge grid;
//! - `landmarks`: a match on `office` with 100,000 landmarks (whole metres, 700 KB); if
//!   admitted, its own and the bystander's ticks per second over the next 5 s, and its tick
//!   times (`/stats`);
//! - `spawns-obstacles`: a 200 m map of 2,000 spawns among 2,000 small squares (a validator
//!   that compares every spawn with every edge takes seconds over it);
//! - `slowloris`: 300 connections that send half a request header, then nothing; after 15 s,
//!   whether a new request is answered and how many of them the server closed;
//! - `match-table`: 100 cheap manual matches from one address;
//! - `stranger-delete`: `DELETE` of someone else's match without `Authorization`;
//! - `wallhack`: the public state of a match a person plays, against its live tick;
//! - `lobby-stall`: `GET /api/matches` timed again and again while a manual match (8 idle
//!   robots, 8 bots, warehouse) steps 20,000 ticks in one request.
//!
//! "request ms" is the wall time of the class's main request (for `match-table`, all 100; for
//! `slowloris`, the newcomer's request after 15 s; for `wallhack`, the first public read).
//!
//! Output: a Markdown table on stdout (one row per class), or JSON with `--json`; progress on
//! stderr.
//!
//! Long file: a measurement program, the server harness, the watchers and the classes, read
//! from top to bottom.

use std::collections::{BTreeMap, VecDeque};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::Stdio;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use clap::Parser;
use serde_json::{Value, json};
use tokio::io::{AsyncBufRead, AsyncBufReadExt, AsyncReadExt, AsyncWriteExt, BufReader, Lines};
use tokio::net::TcpStream;
use tokio::process::{Child, Command};

#[derive(Debug, Parser)]
#[command(about = "Hostile requests against a real server process: status, time, memory, others")]
struct Args {
    /// The server binary to start for each class (this tree's `lasertag` or an older build).
    #[arg(long)]
    server: PathBuf,
    /// Directory of map files handed to the server.
    #[arg(long, default_value = "maps")]
    maps: PathBuf,
    /// Directory of the browser client handed to the server.
    #[arg(long, default_value = "web")]
    web: PathBuf,
    /// Seconds one class may take before it is reported as hung (10..=600).
    #[arg(long, default_value_t = 60)]
    timeout_s: u64,
    /// Run only the classes whose names contain one of these (comma-separated).
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// Print the rows as JSON instead of a Markdown table.
    #[arg(long)]
    json: bool,
}

/// How long the watchers keep watching after a class's last answer: memory a request left
/// behind, and a bystander slowed by what was admitted.
const SETTLE: Duration = Duration::from_secs(2);

// ---------------------------------------------------------------------------------------
// The server process.
// ---------------------------------------------------------------------------------------

/// Lines of the server's log kept, to say why it failed to start.
const LOG_TAIL: usize = 20;

type Tail = Arc<Mutex<VecDeque<String>>>;

struct Server {
    child: Child,
    pid: u32,
    addr: SocketAddr,
    version: String,
}

fn remember(tail: &Tail, line: String) {
    let mut t = tail.lock().unwrap_or_else(|e| e.into_inner());
    if t.len() == LOG_TAIL {
        t.pop_front();
    }
    t.push_back(line);
}

/// Reads a pipe of the server's to its end. It must be drained: a server whose log pipe is
/// full blocks on its next log line, which would look like a hang this program caused.
async fn drain<R: AsyncBufRead + Unpin>(mut lines: Lines<R>, tail: Tail) {
    while let Ok(Some(line)) = lines.next_line().await {
        remember(&tail, line);
    }
}

/// The address in a `serving http://127.0.0.1:41234` log line (the server logs it once it
/// listens; `--addr 127.0.0.1:0` lets the kernel choose a free port, so there is no race).
fn serving_addr(line: &str) -> Option<SocketAddr> {
    let at = line.find("serving http://")? + "serving http://".len();
    line[at..].split_whitespace().next()?.parse().ok()
}

impl Server {
    async fn start(args: &Args) -> Result<Server, String> {
        let mut cmd = Command::new(&args.server);
        cmd.arg("serve")
            .args(["--addr", "127.0.0.1:0", "--maps"])
            .arg(&args.maps)
            .arg("--web")
            .arg(&args.web);
        for (key, _) in std::env::vars_os() {
            if key.to_string_lossy().starts_with("LASERTAG_") {
                cmd.env_remove(key);
            }
        }
        // The log level that prints the `serving` line, and no colour codes in it.
        cmd.env("RUST_LOG", "info,tower_http=warn")
            .env("NO_COLOR", "1")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .kill_on_drop(true);
        let mut child = cmd
            .spawn()
            .map_err(|e| format!("starting {}: {e}", args.server.display()))?;
        let pid = child.id().ok_or("the server exited at once")?;
        let tail: Tail = Arc::default();
        let (Some(stdout), Some(stderr)) = (child.stdout.take(), child.stderr.take()) else {
            return Err("the server's output is not piped".into());
        };
        tokio::spawn(drain(BufReader::new(stderr).lines(), tail.clone()));
        let mut lines = BufReader::new(stdout).lines();
        let found = tokio::time::timeout(Duration::from_secs(30), async {
            while let Ok(Some(line)) = lines.next_line().await {
                let addr = serving_addr(&line);
                remember(&tail, line);
                if addr.is_some() {
                    return addr;
                }
            }
            None
        })
        .await;
        tokio::spawn(drain(lines, tail.clone()));
        let why = || {
            let t = tail.lock().unwrap_or_else(|e| e.into_inner());
            t.iter().cloned().collect::<Vec<_>>().join(" / ")
        };
        let Ok(Some(addr)) = found else {
            return Err(format!("the server never said where it listens: {}", why()));
        };
        let mut server = Server {
            child,
            pid,
            addr,
            version: String::new(),
        };
        let http = reqwest::Client::new();
        let deadline = Instant::now() + Duration::from_secs(10);
        while Instant::now() < deadline {
            if let Ok(a) = send(http.get(format!("http://{addr}/api/health"))).await
                && a.status == 200
            {
                server.version = a.body["version"].as_str().unwrap_or("?").to_string();
                return Ok(server);
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        server.kill().await;
        Err(format!("no healthy answer within 10 s: {}", why()))
    }

    /// How the process ended, if it has (killed by the kernel for memory, say).
    fn exited(&mut self) -> Option<String> {
        match self.child.try_wait() {
            Ok(Some(status)) => Some(status.to_string()),
            _ => None,
        }
    }

    /// Kills the process by its id (SIGKILL: nothing of it needs to survive) and reaps it.
    async fn kill(&mut self) {
        let _ = self.child.start_kill();
        let _ = tokio::time::timeout(Duration::from_secs(5), self.child.wait()).await;
    }
}

/// Resident memory of a process, KiB.
fn rss_kib(pid: u32) -> Option<u64> {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()?
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".into())
}

// ---------------------------------------------------------------------------------------
// HTTP.
// ---------------------------------------------------------------------------------------

/// One answer: status, body (JSON, or the text as a JSON string) and wall time.
struct Answer {
    status: u16,
    body: Value,
    ms: f64,
}

impl Answer {
    /// What the answer says, short: the error text of a refusal, or what was created.
    fn gist(&self) -> String {
        if let Some(e) = self.body["error"].as_str() {
            return shorten(e, 110);
        }
        match self.status {
            201 if self.body.get("owner_token").is_some() => "created (with an owner_token)",
            201 => "created (no owner_token)",
            _ => "",
        }
        .to_string()
    }
}

fn shorten(s: &str, n: usize) -> String {
    if s.chars().count() <= n {
        s.to_string()
    } else {
        format!("{}…", s.chars().take(n).collect::<String>())
    }
}

/// Notes joined with "; ", the empty ones left out.
fn joined(parts: &[&str]) -> String {
    parts
        .iter()
        .filter(|p| !p.is_empty())
        .copied()
        .collect::<Vec<_>>()
        .join("; ")
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// reqwest's error with its causes ("error sending request: connection closed …").
fn error_text(e: &reqwest::Error) -> String {
    let mut text = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(s) = source {
        text = format!("{text}: {s}");
        source = s.source();
    }
    text
}

async fn send(request: reqwest::RequestBuilder) -> Result<Answer, String> {
    let t = Instant::now();
    let r = request.send().await.map_err(|e| error_text(&e))?;
    let status = r.status().as_u16();
    let text = r.text().await.map_err(|e| error_text(&e))?;
    let ms = ms_since(t);
    let body = serde_json::from_str(&text).unwrap_or(Value::String(text));
    Ok(Answer { status, body, ms })
}

/// What a class talks to.
struct Ctx {
    http: reqwest::Client,
    addr: SocketAddr,
    bystander: String,
    /// When a class that runs until something happens gives up and reports what it saw.
    give_up: Instant,
}

impl Ctx {
    fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    async fn get(&self, path: &str) -> Result<Answer, String> {
        send(self.http.get(self.url(path))).await
    }

    /// A request with the owner's token when there is one (older builds hand out none).
    fn with_token(rb: reqwest::RequestBuilder, token: Option<&str>) -> reqwest::RequestBuilder {
        match token {
            Some(t) => rb.bearer_auth(t),
            None => rb,
        }
    }

    async fn post(&self, path: &str, body: &Value, token: Option<&str>) -> Result<Answer, String> {
        send(Self::with_token(self.http.post(self.url(path)), token).json(body)).await
    }

    async fn create(&self, body: &Value) -> Result<(Answer, String, Option<String>), String> {
        let a = self.post("/api/matches", body, None).await?;
        let id = a.body["id"].as_str().map(str::to_string);
        let token = a.body["owner_token"].as_str().map(str::to_string);
        match id {
            Some(id) if a.status == 201 => Ok((a, id, token)),
            _ => Err(format!("creating {body}: {} {}", a.status, a.gist())),
        }
    }

    /// The tick of a match's state as an anonymous client sees it.
    async fn public_tick(&self, id: &str) -> Result<u64, String> {
        let a = self.get(&format!("/api/matches/{id}")).await?;
        a.body["tick"]
            .as_u64()
            .ok_or_else(|| format!("GET /api/matches/{id}: {} {}", a.status, a.gist()))
    }

    /// The tick of a match in the listing, which is live for every match.
    async fn listed_tick(&self, id: &str) -> Result<u64, String> {
        let a = self.get("/api/matches").await?;
        a.body
            .as_array()
            .and_then(|l| l.iter().find(|m| m["id"] == id))
            .and_then(|m| m["tick"].as_u64())
            .ok_or_else(|| format!("match {id} is not listed: {}", a.status))
    }
}

// ---------------------------------------------------------------------------------------
// The watchers: memory, health and the bystander, from the start of a class to its end.
// ---------------------------------------------------------------------------------------

#[derive(Debug, Default, Clone)]
struct Watch {
    rss_peak_kib: u64,
    health_max_ms: f64,
    health_failed: u32,
    /// A health request sent and not answered yet, so that a hang shows at the end too.
    health_since: Option<Instant>,
    ticks: Vec<(Instant, u64)>,
}

struct Watchers {
    data: Arc<Mutex<Watch>>,
    tasks: Vec<tokio::task::JoinHandle<()>>,
}

fn with<T>(data: &Mutex<Watch>, f: impl FnOnce(&mut Watch) -> T) -> T {
    f(&mut data.lock().unwrap_or_else(|e| e.into_inner()))
}

impl Watchers {
    fn start(addr: SocketAddr, pid: u32, bystander: &str) -> Watchers {
        let data: Arc<Mutex<Watch>> = Arc::default();
        // Their own client: the attack's connections must not queue the watchers'.
        let http = reqwest::Client::builder()
            .timeout(Duration::from_secs(30))
            .pool_idle_timeout(Duration::from_secs(5))
            .build()
            .unwrap_or_default();
        let memory = {
            let data = data.clone();
            tokio::spawn(async move {
                loop {
                    if let Some(kib) = rss_kib(pid) {
                        with(&data, |w| w.rss_peak_kib = w.rss_peak_kib.max(kib));
                    }
                    tokio::time::sleep(Duration::from_millis(50)).await;
                }
            })
        };
        let health = {
            let (data, http) = (data.clone(), http.clone());
            tokio::spawn(async move {
                loop {
                    let t = Instant::now();
                    with(&data, |w| w.health_since = Some(t));
                    let r = send(http.get(format!("http://{addr}/api/health"))).await;
                    with(&data, |w| {
                        w.health_since = None;
                        match r {
                            Ok(a) if a.status == 200 => w.health_max_ms = w.health_max_ms.max(a.ms),
                            _ => w.health_failed += 1,
                        }
                    });
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            })
        };
        let ticks = {
            let data = data.clone();
            let url = format!("http://{addr}/api/matches/{bystander}");
            tokio::spawn(async move {
                loop {
                    if let Ok(a) = send(http.get(&url)).await
                        && let Some(tick) = a.body["tick"].as_u64()
                    {
                        with(&data, |w| w.ticks.push((Instant::now(), tick)));
                    }
                    tokio::time::sleep(Duration::from_millis(100)).await;
                }
            })
        };
        Watchers {
            data,
            tasks: vec![memory, health, ticks],
        }
    }

    fn stop(self) -> Watch {
        for t in &self.tasks {
            t.abort();
        }
        let mut w = with(&self.data, |w| w.clone());
        // A request still in flight when the watch ends is at least this slow; over a
        // second it counts as unanswered (a shorter one was just unlucky in its timing).
        if let Some(t) = w.health_since.take() {
            w.health_max_ms = w.health_max_ms.max(ms_since(t));
            if t.elapsed() > Duration::from_secs(1) {
                w.health_failed += 1;
            }
        }
        w
    }
}

/// The bystander over `[from, to]`: whether it advanced, its ticks per second, and the
/// longest time between two observed advances (window ends included).
fn bystander_figures(
    first: Option<(Instant, u64)>,
    ticks: &[(Instant, u64)],
    from: Instant,
    to: Instant,
) -> (Option<bool>, Option<f64>, Option<f64>) {
    let samples: Vec<(Instant, u64)> = first
        .into_iter()
        .chain(
            ticks
                .iter()
                .copied()
                .filter(|(t, _)| *t >= from && *t <= to),
        )
        .collect();
    let (Some(a), Some(b)) = (samples.first(), samples.last()) else {
        return (None, None, None);
    };
    let span = b.0.duration_since(a.0).as_secs_f64();
    let rate = (span > 0.0).then(|| (b.1.saturating_sub(a.1)) as f64 / span);
    let (mut last_advance, mut last_tick, mut gap) = (from, a.1, Duration::ZERO);
    for &(t, tick) in &samples[1..] {
        if tick > last_tick {
            gap = gap.max(t.duration_since(last_advance));
            last_advance = t;
            last_tick = tick;
        }
    }
    gap = gap.max(to.duration_since(last_advance));
    (Some(b.1 > a.1), rate, Some(gap.as_secs_f64() * 1e3))
}

// ---------------------------------------------------------------------------------------
// The classes.
// ---------------------------------------------------------------------------------------

#[derive(Debug, Clone, Copy)]
enum Class {
    Slivers(usize),
    ExpensiveMatch,
    Landmarks,
    SpawnsAndObstacles,
    Slowloris,
    MatchTable,
    StrangerDelete,
    Wallhack,
    LobbyStall,
}

const CLASSES: [Class; 10] = [
    Class::Slivers(64),
    Class::Slivers(256),
    Class::ExpensiveMatch,
    Class::Landmarks,
    Class::SpawnsAndObstacles,
    Class::Slowloris,
    Class::MatchTable,
    Class::StrangerDelete,
    Class::Wallhack,
    Class::LobbyStall,
];

impl Class {
    fn name(self) -> String {
        match self {
            Class::Slivers(n) => format!("map-{n}-slivers"),
            Class::ExpensiveMatch => "expensive-match".into(),
            Class::Landmarks => "landmarks".into(),
            Class::SpawnsAndObstacles => "spawns-obstacles".into(),
            Class::Slowloris => "slowloris".into(),
            Class::MatchTable => "match-table".into(),
            Class::StrangerDelete => "stranger-delete".into(),
            Class::Wallhack => "wallhack".into(),
            Class::LobbyStall => "lobby-stall".into(),
        }
    }
}

/// What a class's requests got.
#[derive(Debug, Default)]
struct Outcome {
    status: String,
    request_ms: Option<f64>,
    note: String,
}

async fn attack(class: Class, ctx: &Ctx) -> Result<Outcome, String> {
    match class {
        Class::Slivers(n) => one_post(ctx, "/api/maps", &slivers(n)).await,
        Class::ExpensiveMatch => {
            let body = json!({"map": empty_map(500.0), "robots": 8, "opponents": 8,
                              "radio": {"loss": 0.5}, "tracker": {"grid_cell": 0.1}});
            one_post(ctx, "/api/matches", &body).await
        }
        Class::Landmarks => landmarks(ctx).await,
        Class::SpawnsAndObstacles => one_post(ctx, "/api/maps", &crowded(2000, 2000)).await,
        Class::Slowloris => slowloris(ctx).await,
        Class::MatchTable => match_table(ctx).await,
        Class::StrangerDelete => stranger_delete(ctx).await,
        Class::Wallhack => wallhack(ctx).await,
        Class::LobbyStall => lobby_stall(ctx).await,
    }
}

/// Rounds to a millimetre, as a map author writes coordinates.
fn r3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// 500 m, `n` thin obstacles from near (10, 20) to (470, 480): the shape `tests/hostile.rs`
/// sends, a few KB whose long diagonal walls cost the most to build.
fn slivers(n: usize) -> Value {
    let obstacles: Vec<Value> = (0..n)
        .map(|k| {
            let y = r3(20.0 + k as f64 * 0.02);
            json!([
                [10.0, y],
                [470.0, r3(y + 460.0)],
                [470.5, r3(y + 460.0)],
                [10.5, y]
            ])
        })
        .collect();
    json!({"name": "slivers", "width": 500.0, "height": 500.0, "obstacles": obstacles,
           "robot_spawns": [[2.0, 2.0, 0.0]], "opponent_spawns": [[498.0, 2.0]]})
}

fn empty_map(side: f64) -> Value {
    json!({"name": "big", "width": side, "height": side, "obstacles": [],
           "robot_spawns": [[2.0, 2.0, 0.0]], "opponent_spawns": [[side - 2.0, side - 2.0]]})
}

/// The shipped office with `n` landmarks spread over it (the R2 low-discrepancy sequence),
/// at whole metres so that 100,000 of them fit in a body under 1 MiB.
fn office_with_landmarks(n: usize) -> Result<Value, String> {
    let mut m: Value = serde_json::from_str(include_str!("../maps/office.json"))
        .map_err(|e| format!("maps/office.json: {e}"))?;
    let (w, h) = (
        m["width"].as_f64().unwrap_or(24.0),
        m["height"].as_f64().unwrap_or(16.0),
    );
    let (a1, a2) = (0.754_877_666_246_692_8, 0.569_840_290_998_053_3);
    // Whole metres as JSON integers (`12`, not `12.0`): 7 bytes a landmark.
    let landmarks: Vec<[u32; 2]> = (1..=n)
        .map(|k| {
            let k = k as f64;
            let at = |a: f64, side: f64| ((k * a).fract() * side).round() as u32;
            [at(a1, w), at(a2, h)]
        })
        .collect();
    m["name"] = json!("landmarks");
    m["landmarks"] = json!(landmarks);
    Ok(m)
}

/// 200 m with `squares` 0.5 m squares on a lattice and `spawns` spawns between them (half
/// for robots, half for opponents), each about 2 m from the nearest square.
fn crowded(spawns: usize, squares: usize) -> Value {
    let k = (squares as f64).sqrt().ceil() as usize;
    let s = 200.0 / k as f64;
    let obstacles: Vec<Value> = (0..squares)
        .map(|i| {
            let (cx, cy) = ((i % k) as f64 * s + s / 2.0, (i / k) as f64 * s + s / 2.0);
            let (x0, x1, y0, y1) = (r3(cx - 0.25), r3(cx + 0.25), r3(cy - 0.25), r3(cy + 0.25));
            json!([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        })
        .collect();
    // Between two rows of squares, above a column's centre; then between two columns.
    let between_rows =
        (0..k - 1).flat_map(|j| (0..k).map(move |i| ((i as f64 + 0.5) * s, (j + 1) as f64 * s)));
    let between_columns =
        (0..k).flat_map(|j| (0..k - 1).map(move |i| ((i + 1) as f64 * s, (j as f64 + 0.5) * s)));
    let points: Vec<(f64, f64)> = between_rows.chain(between_columns).take(spawns).collect();
    let (robots, opponents) = points.split_at(points.len() / 2);
    json!({"name": "crowded", "width": 200.0, "height": 200.0, "obstacles": obstacles,
           "robot_spawns": robots.iter().map(|&(x, y)| [r3(x), r3(y), 0.0]).collect::<Vec<_>>(),
           "opponent_spawns": opponents.iter().map(|&(x, y)| [r3(x), r3(y)]).collect::<Vec<_>>()})
}

fn body_size(body: &Value) -> String {
    let n = serde_json::to_vec(body).map_or(0, |b| b.len());
    if n >= 10_000 {
        format!("{} KB body", n / 1000)
    } else {
        format!("{n} B body")
    }
}

/// One request: its status, time and what it said.
async fn one_post(ctx: &Ctx, path: &str, body: &Value) -> Result<Outcome, String> {
    let a = ctx.post(path, body, None).await?;
    Ok(Outcome {
        status: a.status.to_string(),
        request_ms: Some(a.ms),
        note: joined(&[&body_size(body), &a.gist()]),
    })
}

/// Ticks per second over `d` of the bystander and of another match (read from the listing,
/// which is live for every match).
async fn tick_rates(ctx: &Ctx, other: &str, d: Duration) -> Result<(f64, f64), String> {
    let t0 = Instant::now();
    let (b0, o0) = (
        ctx.public_tick(&ctx.bystander).await?,
        ctx.listed_tick(other).await?,
    );
    tokio::time::sleep(d).await;
    let (b1, o1) = (
        ctx.public_tick(&ctx.bystander).await?,
        ctx.listed_tick(other).await?,
    );
    let s = t0.elapsed().as_secs_f64();
    Ok((
        b1.saturating_sub(b0) as f64 / s,
        o1.saturating_sub(o0) as f64 / s,
    ))
}

async fn landmarks(ctx: &Ctx) -> Result<Outcome, String> {
    let body = json!({"map": office_with_landmarks(100_000)?});
    let a = ctx.post("/api/matches", &body, None).await?;
    let mut note = joined(&[&body_size(&body), &a.gist()]);
    if a.status == 201
        && let Some(id) = a.body["id"].as_str()
    {
        // What admitting it did to everyone else: the bystander's rate over the next 5 s,
        // and what the match's own ticks cost (its task's stats).
        let (bystander, own) = tick_rates(ctx, id, Duration::from_secs(5)).await?;
        note += &format!(
            "; over the 5 s after admission the bystander ran {bystander:.1} ticks/s, this match {own:.1}"
        );
        if let Ok(s) = ctx.get(&format!("/api/matches/{id}/stats")).await {
            let f = |k: &str| {
                s.body[k]
                    .as_f64()
                    .map_or("?".into(), |us| format!("{:.0}", us / 1e3))
            };
            note += &format!(
                "; its ticks: mean {} ms, p99 {} ms, max {} ms, {} late",
                f("tick_us_mean"),
                f("tick_us_p99"),
                f("tick_us_max"),
                s.body["late_ticks"]
            );
        }
    }
    Ok(Outcome {
        status: a.status.to_string(),
        request_ms: Some(a.ms),
        note,
    })
}

/// Connections that send half a header, how long the server keeps them, and whether it
/// still answers others meanwhile.
async fn slowloris(ctx: &Ctx) -> Result<Outcome, String> {
    const CONNECTIONS: usize = 300;
    const WAIT: Duration = Duration::from_secs(15);
    let opened = Instant::now();
    let mut held = Vec::new();
    let mut failed = 0;
    for _ in 0..CONNECTIONS {
        let Ok(mut stream) = TcpStream::connect(ctx.addr).await else {
            failed += 1;
            continue;
        };
        if stream
            .write_all(b"GET /api/health HTTP/1.1\r\nHost: probe\r\n")
            .await
            .is_err()
        {
            failed += 1;
            continue;
        }
        // Reads until the server closes (a 408 or the like may come first): when it did.
        held.push(tokio::spawn(async move {
            let mut buf = [0u8; 512];
            loop {
                match stream.read(&mut buf).await {
                    Ok(0) | Err(_) => return opened.elapsed(),
                    Ok(_) => {}
                }
            }
        }));
    }
    tokio::time::sleep_until((opened + WAIT).into()).await;
    // A newcomer on a connection of its own.
    let fresh = reqwest::Client::builder()
        .pool_max_idle_per_host(0)
        .timeout(Duration::from_secs(5))
        .build()
        .map_err(|e| error_text(&e))?;
    let answer = send(fresh.get(ctx.url("/api/health"))).await;
    let opened_count = held.len();
    let mut closed_after = Vec::new();
    for h in held {
        if h.is_finished() {
            closed_after.extend(h.await.ok().map(|d| d.as_secs_f64()));
        } else {
            h.abort(); // drops the stream: our side closes
        }
    }
    let still_open = opened_count - closed_after.len();
    closed_after.sort_by(f64::total_cmp);
    let median = closed_after
        .get(closed_after.len() / 2)
        .map_or(String::new(), |s| format!(", the median at {s:.1} s"));
    let (status, ms) = match &answer {
        Ok(a) => (format!("health {}", a.status), Some(a.ms)),
        Err(e) => (format!("health: {}", shorten(e, 60)), None),
    };
    Ok(Outcome {
        status,
        request_ms: ms,
        note: format!(
            "{} of {} half-sent connections closed by the server within {} s{median}; {still_open} still open; {failed} failed to open",
            closed_after.len(),
            opened_count,
            WAIT.as_secs()
        ),
    })
}

async fn match_table(ctx: &Ctx) -> Result<Outcome, String> {
    const TRIES: usize = 100;
    let body = json!({"map": "office", "clock": "manual", "planner": "idle"});
    let t = Instant::now();
    let mut statuses: BTreeMap<u16, usize> = BTreeMap::new();
    let mut first_refusal = None;
    for _ in 0..TRIES {
        let a = ctx.post("/api/matches", &body, None).await?;
        *statuses.entry(a.status).or_default() += 1;
        if a.status != 201 && first_refusal.is_none() {
            first_refusal = Some(a.gist());
        }
    }
    let status: Vec<String> = statuses.iter().map(|(s, n)| format!("{n}×{s}")).collect();
    let admitted = statuses.get(&201).copied().unwrap_or(0);
    Ok(Outcome {
        status: status.join(", "),
        request_ms: Some(ms_since(t)),
        note: format!(
            "{admitted} of {TRIES} admitted (the bystander is one more from the same address); first refusal: {}",
            first_refusal.unwrap_or_else(|| "none".into())
        ),
    })
}

async fn stranger_delete(ctx: &Ctx) -> Result<Outcome, String> {
    let (_, id, token) = ctx
        .create(&json!({"map": "office", "clock": "manual", "planner": "idle"}))
        .await?;
    let path = format!("/api/matches/{id}");
    let d = send(ctx.http.delete(ctx.url(&path))).await?;
    let after = ctx.get(&path).await?;
    let fate = match after.status {
        404 => "gone: deleted by a stranger",
        200 => "still there",
        _ => "?",
    };
    Ok(Outcome {
        status: d.status.to_string(),
        request_ms: Some(d.ms),
        note: joined(&[
            &format!(
                "owner_token handed out: {}; GET afterwards {} ({fate})",
                if token.is_some() { "yes" } else { "no" },
                after.status,
            ),
            &d.gist(),
        ]),
    })
}

async fn wallhack(ctx: &Ctx) -> Result<Outcome, String> {
    let (created, id, _) = ctx
        .create(&json!({"map": "office", "opponent_control": "human"}))
        .await?;
    let join = ctx
        .post(
            &format!("/api/matches/{id}/players"),
            &json!({"name": "x"}),
            None,
        )
        .await?;
    // Far enough into the match that a live state cannot pass for the first frame.
    tokio::time::sleep(Duration::from_secs(1)).await;
    let t = Instant::now();
    let public1 = ctx.public_tick(&id).await?;
    let read_ms = ms_since(t);
    let live1 = ctx.listed_tick(&id).await?;
    tokio::time::sleep(Duration::from_secs(2)).await;
    let public2 = ctx.public_tick(&id).await?;
    let live2 = ctx.listed_tick(&id).await?;
    let verdict = if public2 + 20 >= live2 {
        "the public state is live"
    } else {
        "the public state is held back"
    };
    Ok(Outcome {
        status: format!("join {}, state 200", join.status),
        request_ms: Some(read_ms),
        note: format!(
            "public tick {public1} → {public2}, live tick {live1} → {live2} (2 s apart): {verdict}; spectator_delay_s {}",
            created
                .body
                .get("spectator_delay_s")
                .unwrap_or(&json!("absent"))
        ),
    })
}

async fn lobby_stall(ctx: &Ctx) -> Result<Outcome, String> {
    // The manual match of `tests/hostile.rs` (8 robots, 8 bots, warehouse, a time limit past
    // 20,000 ticks) with idle robots: hunting, they win within a few hundred ticks and the
    // step ends early; idle, every one of the 20,000 ticks is stepped.
    let (_, id, token) = ctx
        .create(
            &json!({"map": "warehouse", "clock": "manual", "robots": 8, "opponents": 8,
                        "planner": "idle", "time_limit_s": 3600}),
        )
        .await?;
    let step = tokio::spawn(send(
        Ctx::with_token(
            ctx.http.post(ctx.url(&format!("/api/matches/{id}/step"))),
            token.as_deref(),
        )
        .json(&json!({"ticks": 20000})),
    ));
    let mut latencies = Vec::new();
    let mut failed = 0;
    while !step.is_finished() && Instant::now() < ctx.give_up {
        match ctx.get("/api/matches").await {
            Ok(a) if a.status == 200 => latencies.push(a.ms),
            _ => failed += 1,
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    latencies.sort_by(f64::total_cmp);
    let listing = format!(
        "listing read {} times during the step: max {:.0} ms, median {:.1} ms{}",
        latencies.len(),
        latencies.last().copied().unwrap_or(f64::NAN),
        latencies
            .get(latencies.len() / 2)
            .copied()
            .unwrap_or(f64::NAN),
        if failed > 0 {
            format!(", {failed} failed")
        } else {
            String::new()
        }
    );
    if !step.is_finished() {
        step.abort();
        return Ok(Outcome {
            status: "step unanswered".into(),
            request_ms: None,
            note: format!("the step was still running when the probe gave up; {listing}"),
        });
    }
    let a = step.await.map_err(|e| e.to_string())??;
    Ok(Outcome {
        status: format!("step {}", a.status),
        request_ms: Some(a.ms),
        note: format!(
            "{listing}; the step reached tick {} ({}){}",
            a.body["tick"],
            a.body["status"].as_str().unwrap_or("?"),
            if a.status == 200 {
                String::new()
            } else {
                format!("; {}", a.gist())
            }
        ),
    })
}

// ---------------------------------------------------------------------------------------
// One class on a fresh server, and the report.
// ---------------------------------------------------------------------------------------

#[derive(Debug, Default)]
struct Row {
    class: String,
    outcome: Outcome,
    /// Before, peak, after (MiB).
    rss_mib: [Option<f64>; 3],
    bystander_ticked: Option<bool>,
    ticks_per_s: Option<f64>,
    longest_gap_ms: Option<f64>,
    health_max_ms: Option<f64>,
    health_failed: u32,
    server_exit: Option<String>,
    seconds: f64,
}

async fn measure(args: &Args, class: Class, version: &mut Option<String>) -> Row {
    let started = Instant::now();
    let mut row = Row {
        class: class.name(),
        ..Row::default()
    };
    let mut server = match Server::start(args).await {
        Ok(s) => s,
        Err(e) => {
            row.outcome.status = "no server".into();
            row.outcome.note = e;
            return row;
        }
    };
    version.get_or_insert_with(|| server.version.clone());
    let limit = Duration::from_secs(args.timeout_s);
    let mut ctx = Ctx {
        http: reqwest::Client::builder()
            .pool_idle_timeout(Duration::from_secs(5))
            .build()
            .unwrap_or_default(),
        addr: server.addr,
        bystander: String::new(),
        give_up: Instant::now(),
    };
    match ctx
        .create(&json!({"map": "office", "planner": "idle"}))
        .await
    {
        Ok((_, id, _)) => ctx.bystander = id,
        Err(e) => {
            row.outcome.status = "no bystander".into();
            row.outcome.note = e;
            server.kill().await;
            return row;
        }
    }
    // The bystander's first ticks and the showcase's start, before anything is measured.
    tokio::time::sleep(Duration::from_secs(1)).await;
    let before = rss_kib(server.pid);
    let first = ctx
        .public_tick(&ctx.bystander)
        .await
        .ok()
        .map(|t| (Instant::now(), t));
    let watchers = Watchers::start(server.addr, server.pid, &ctx.bystander);
    let from = Instant::now();
    ctx.give_up = from + limit.saturating_sub(Duration::from_secs(5));
    row.outcome = match tokio::time::timeout(limit, attack(class, &ctx)).await {
        Ok(Ok(o)) => o,
        Ok(Err(e)) => Outcome {
            status: "error".into(),
            request_ms: None,
            note: e,
        },
        Err(_) => {
            let probe = reqwest::Client::builder()
                .timeout(Duration::from_secs(2))
                .build()
                .unwrap_or_default();
            let health = match send(probe.get(ctx.url("/api/health"))).await {
                Ok(a) => format!("{} in {:.0} ms", a.status, a.ms),
                Err(e) => shorten(&e, 60),
            };
            Outcome {
                status: "hung".into(),
                request_ms: None,
                note: format!(
                    "no answer within {} s; /api/health then: {health}",
                    limit.as_secs()
                ),
            }
        }
    };
    tokio::time::sleep(SETTLE).await;
    let to = Instant::now();
    let watch = watchers.stop();
    let after = rss_kib(server.pid);
    let mib = |k: Option<u64>| k.map(|k| k as f64 / 1024.0);
    let peak = [before, Some(watch.rss_peak_kib), after]
        .into_iter()
        .flatten()
        .max();
    row.rss_mib = [mib(before), mib(peak), mib(after)];
    (row.bystander_ticked, row.ticks_per_s, row.longest_gap_ms) =
        bystander_figures(first, &watch.ticks, from, to);
    row.health_max_ms = (watch.health_max_ms > 0.0).then_some(watch.health_max_ms);
    row.health_failed = watch.health_failed;
    row.server_exit = server.exited();
    server.kill().await;
    row.seconds = started.elapsed().as_secs_f64();
    row
}

fn num(x: Option<f64>) -> String {
    match x {
        None => "-".into(),
        Some(x) if x.abs() < 10.0 => format!("{x:.1}"),
        Some(x) => format!("{x:.0}"),
    }
}

fn notes(r: &Row) -> String {
    let mut n = r.outcome.note.clone();
    if r.health_failed > 0 {
        n += &format!("; {} health requests failed or timed out", r.health_failed);
    }
    if let Some(exit) = &r.server_exit {
        n += &format!("; the server process ended: {exit}");
    }
    n
}

fn markdown(rows: &[Row]) -> String {
    let mut out = String::from(
        "| class | status | request ms | RSS MiB before / peak / after | bystander ticked | bystander ticks/s | longest bystander gap ms | health max ms | notes |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let [b, p, a] = r.rss_mib;
        out += &format!(
            "| {} | {} | {} | {} / {} / {} | {} | {} | {} | {} | {} |\n",
            r.class,
            r.outcome.status,
            num(r.outcome.request_ms),
            num(b),
            num(p),
            num(a),
            match r.bystander_ticked {
                Some(true) => "yes",
                Some(false) => "no",
                None => "-",
            },
            num(r.ticks_per_s),
            num(r.longest_gap_ms),
            num(r.health_max_ms),
            notes(r).replace('|', "\\|"),
        );
    }
    out
}

fn to_json(rows: &[Row]) -> Value {
    let rows: Vec<Value> = rows
        .iter()
        .map(|r| {
            json!({"class": r.class, "status": r.outcome.status,
                   "request_ms": r.outcome.request_ms,
                   "rss_mib": {"before": r.rss_mib[0], "peak": r.rss_mib[1], "after": r.rss_mib[2]},
                   "bystander_ticked": r.bystander_ticked, "bystander_ticks_per_s": r.ticks_per_s,
                   "bystander_longest_gap_ms": r.longest_gap_ms,
                   "health_max_ms": r.health_max_ms, "health_failed": r.health_failed,
                   "server_exit": r.server_exit, "note": r.outcome.note, "seconds": r.seconds})
        })
        .collect();
    json!(rows)
}

#[tokio::main]
async fn main() -> std::process::ExitCode {
    let args = Args::parse();
    if !(10..=600).contains(&args.timeout_s) {
        eprintln!("--timeout-s must be in 10..=600");
        return std::process::ExitCode::FAILURE;
    }
    let chosen: Vec<Class> = CLASSES
        .into_iter()
        .filter(|c| args.only.is_empty() || args.only.iter().any(|o| c.name().contains(o)))
        .collect();
    let load_start = load_average();
    let mut version = None;
    let mut rows = Vec::new();
    for class in chosen {
        eprintln!("{} …", class.name());
        let row = measure(&args, class, &mut version).await;
        eprintln!(
            "{}: {} in {:.0} s",
            row.class, row.outcome.status, row.seconds
        );
        rows.push(row);
    }
    let load_end = load_average();
    let version = version.unwrap_or_else(|| "?".into());
    if args.json {
        let out = json!({"server": args.server.display().to_string(), "version": version,
                         "load_average_start": load_start, "load_average_end": load_end,
                         "rows": to_json(&rows)});
        println!("{}", serde_json::to_string_pretty(&out).unwrap_or_default());
    } else {
        println!(
            "server `{}` (version {version}); load average {load_start} at the start, {load_end} at the end\n",
            args.server.display()
        );
        print!("{}", markdown(&rows));
    }
    std::process::ExitCode::SUCCESS
}
