//! The server process of one class, and what watches it: resident memory, `/api/health`
//! and the bystander match, sampled while the class runs.

use std::collections::VecDeque;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crate::Args;

use serde_json::Value;
use tokio::io::{AsyncBufRead, AsyncBufReadExt, BufReader, Lines};
use tokio::process::{Child, Command};

// ---------------------------------------------------------------------------------------
// The server process.
// ---------------------------------------------------------------------------------------

/// Lines of the server's log kept, to say why it failed to start.
const LOG_TAIL: usize = 20;

type Tail = Arc<Mutex<VecDeque<String>>>;

pub(crate) struct Server {
    pub(crate) child: Child,
    pub(crate) pid: u32,
    pub(crate) addr: SocketAddr,
    pub(crate) version: String,
    /// The history's directory (`--data-dir`), the probe's own, removed with the server.
    pub(crate) data_dir: PathBuf,
}

pub(crate) fn remember(tail: &Tail, line: String) {
    let mut t = tail.lock().unwrap_or_else(|e| e.into_inner());
    if t.len() == LOG_TAIL {
        t.pop_front();
    }
    t.push_back(line);
}

/// Reads a pipe of the server's to its end. It must be drained: a server whose log pipe is
/// full blocks on its next log line, which would look like a hang this program caused.
pub(crate) async fn drain<R: AsyncBufRead + Unpin>(mut lines: Lines<R>, tail: Tail) {
    while let Ok(Some(line)) = lines.next_line().await {
        remember(&tail, line);
    }
}

/// The address in a `serving http://127.0.0.1:41234` log line (the server logs it once it
/// listens; `--addr 127.0.0.1:0` lets the kernel choose a free port, so there is no race).
pub(crate) fn serving_addr(line: &str) -> Option<SocketAddr> {
    let at = line.find("serving http://")? + "serving http://".len();
    line[at..].split_whitespace().next()?.parse().ok()
}

impl Server {
    /// Starts `<server> serve` with `extra` flags after the probe's own, a fresh data
    /// directory of its own (under the system's temporary directory) and every other setting
    /// at its default.
    pub(crate) async fn start(args: &Args, extra: &[&str]) -> Result<Server, String> {
        static STARTED: AtomicUsize = AtomicUsize::new(0);
        let data_dir = std::env::temp_dir().join(format!(
            "hostile-probe-{}-{}",
            std::process::id(),
            STARTED.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&data_dir);
        let mut cmd = Command::new(&args.server);
        cmd.arg("serve")
            .args(["--addr", "127.0.0.1:0", "--maps"])
            .arg(&args.maps)
            .arg("--web")
            .arg(&args.web)
            .arg("--data-dir")
            .arg(&data_dir)
            .args(extra);
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
            data_dir,
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
    pub(crate) fn exited(&mut self) -> Option<String> {
        match self.child.try_wait() {
            Ok(Some(status)) => Some(status.to_string()),
            _ => None,
        }
    }

    /// Kills the process by its id (SIGKILL: nothing of it needs to survive) and reaps it.
    pub(crate) async fn kill(&mut self) {
        let _ = self.child.start_kill();
        let _ = tokio::time::timeout(Duration::from_secs(5), self.child.wait()).await;
        let _ = std::fs::remove_dir_all(&self.data_dir);
    }
}

/// Bytes of the files in a directory and its subdirectories (what the history takes on disk).
pub(crate) fn dir_bytes(dir: &Path) -> u64 {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    entries
        .flatten()
        .map(|e| match e.metadata() {
            Ok(m) if m.is_dir() => dir_bytes(&e.path()),
            Ok(m) => m.len(),
            Err(_) => 0,
        })
        .sum()
}

/// Resident memory of a process, KiB.
pub(crate) fn rss_kib(pid: u32) -> Option<u64> {
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

pub(crate) fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "?".into())
}

// ---------------------------------------------------------------------------------------
// HTTP.
// ---------------------------------------------------------------------------------------

/// One answer: status, body (JSON, or the text as a JSON string) and wall time.
pub(crate) struct Answer {
    pub(crate) status: u16,
    pub(crate) body: Value,
    pub(crate) ms: f64,
}

impl Answer {
    /// What the answer says, short: the error text of a refusal, or what was created.
    pub(crate) fn gist(&self) -> String {
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

pub(crate) fn shorten(s: &str, n: usize) -> String {
    if s.chars().count() <= n {
        s.to_string()
    } else {
        format!("{}…", s.chars().take(n).collect::<String>())
    }
}

/// Notes joined with "; ", the empty ones left out.
pub(crate) fn joined(parts: &[&str]) -> String {
    parts
        .iter()
        .filter(|p| !p.is_empty())
        .copied()
        .collect::<Vec<_>>()
        .join("; ")
}

pub(crate) fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// reqwest's error with its causes ("error sending request: connection closed …").
pub(crate) fn error_text(e: &reqwest::Error) -> String {
    let mut text = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(s) = source {
        text = format!("{text}: {s}");
        source = s.source();
    }
    text
}

pub(crate) async fn send(request: reqwest::RequestBuilder) -> Result<Answer, String> {
    let t = Instant::now();
    let r = request.send().await.map_err(|e| error_text(&e))?;
    let status = r.status().as_u16();
    let text = r.text().await.map_err(|e| error_text(&e))?;
    let ms = ms_since(t);
    let body = serde_json::from_str(&text).unwrap_or(Value::String(text));
    Ok(Answer { status, body, ms })
}

/// What a class talks to.
pub(crate) struct Ctx {
    pub(crate) http: reqwest::Client,
    pub(crate) addr: SocketAddr,
    pub(crate) bystander: String,
    /// The server process's id (for its memory) and its history's directory.
    pub(crate) pid: u32,
    pub(crate) data_dir: PathBuf,
    /// When a class that runs until something happens gives up and reports what it saw.
    pub(crate) give_up: Instant,
}

impl Ctx {
    pub(crate) fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    pub(crate) async fn get(&self, path: &str) -> Result<Answer, String> {
        send(self.http.get(self.url(path))).await
    }

    /// A request with the owner's token when there is one (older builds hand out none).
    pub(crate) fn with_token(
        rb: reqwest::RequestBuilder,
        token: Option<&str>,
    ) -> reqwest::RequestBuilder {
        match token {
            Some(t) => rb.bearer_auth(t),
            None => rb,
        }
    }

    pub(crate) async fn post(
        &self,
        path: &str,
        body: &Value,
        token: Option<&str>,
    ) -> Result<Answer, String> {
        send(Self::with_token(self.http.post(self.url(path)), token).json(body)).await
    }

    pub(crate) async fn create(
        &self,
        body: &Value,
    ) -> Result<(Answer, String, Option<String>), String> {
        let a = self.post("/api/matches", body, None).await?;
        let id = a.body["id"].as_str().map(str::to_string);
        let token = a.body["owner_token"].as_str().map(str::to_string);
        match id {
            Some(id) if a.status == 201 => Ok((a, id, token)),
            _ => Err(format!("creating {body}: {} {}", a.status, a.gist())),
        }
    }

    /// The tick of a match's state as an anonymous client sees it.
    pub(crate) async fn public_tick(&self, id: &str) -> Result<u64, String> {
        let a = self.get(&format!("/api/matches/{id}")).await?;
        a.body["tick"]
            .as_u64()
            .ok_or_else(|| format!("GET /api/matches/{id}: {} {}", a.status, a.gist()))
    }

    /// The tick of a match in the listing, which is live for every match.
    pub(crate) async fn listed_tick(&self, id: &str) -> Result<u64, String> {
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
pub(crate) struct Watch {
    pub(crate) rss_peak_kib: u64,
    pub(crate) health_max_ms: f64,
    /// Every answered health request's time (ms), for the median.
    pub(crate) health_ms: Vec<f64>,
    pub(crate) health_failed: u32,
    /// A health request sent and not answered yet, so that a hang shows at the end too.
    pub(crate) health_since: Option<Instant>,
    pub(crate) ticks: Vec<(Instant, u64)>,
}

pub(crate) struct Watchers {
    pub(crate) data: Arc<Mutex<Watch>>,
    pub(crate) tasks: Vec<tokio::task::JoinHandle<()>>,
}

pub(crate) fn with<T>(data: &Mutex<Watch>, f: impl FnOnce(&mut Watch) -> T) -> T {
    f(&mut data.lock().unwrap_or_else(|e| e.into_inner()))
}

impl Watchers {
    pub(crate) fn start(addr: SocketAddr, pid: u32, bystander: &str) -> Watchers {
        let data: Arc<Mutex<Watch>> = Arc::default();
        // Their own client, from an address of their own (127.0.0.250): the attack's
        // connections must not queue the watchers', nor its address's limits refuse them.
        let http = reqwest::Client::builder()
            .local_address(std::net::IpAddr::V4(std::net::Ipv4Addr::new(
                127, 0, 0, 250,
            )))
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
                            Ok(a) if a.status == 200 => {
                                w.health_max_ms = w.health_max_ms.max(a.ms);
                                w.health_ms.push(a.ms);
                            }
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

    pub(crate) fn stop(self) -> Watch {
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
pub(crate) fn bystander_figures(
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
// Maps the classes share.
// ---------------------------------------------------------------------------------------

/// Rounds to a millimetre, as a map author writes coordinates.
pub(crate) fn r3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// An open square floor of `side` metres, a robot and an opponent in opposite corners.
pub(crate) fn empty_map(side: f64) -> Value {
    serde_json::json!({"name": "big", "width": side, "height": side, "obstacles": [],
           "robot_spawns": [[2.0, 2.0, 0.0]], "opponent_spawns": [[side - 2.0, side - 2.0]]})
}
