//! The processes the fleet probe starts and reads: `redis-server`, the nodes, their CPU from
//! `/proc`, their metrics, Redis's counters.

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A child process killed when dropped.
pub struct Process(pub Child);

impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

pub struct Node {
    pub process: Process,
    pub url: String,
    pub addr: SocketAddr,
}

/// Seconds of CPU (user + system) the process `pid` has used, from `/proc/<pid>/stat`
/// (in clock ticks of 1/100 s, Linux's USER_HZ).
pub fn cpu_seconds(pid: u32) -> f64 {
    let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
        return 0.0;
    };
    let after = stat.rsplit(')').next().unwrap_or_default();
    let fields: Vec<&str> = after.split_whitespace().collect();
    // After the name: state is field 3, utime 14 and stime 15 (1-based over the line).
    let ticks = |i: usize| fields.get(i - 3).and_then(|v| v.parse::<f64>().ok());
    (ticks(14).unwrap_or(0.0) + ticks(15).unwrap_or(0.0)) / 100.0
}

pub fn free_port() -> Result<u16, String> {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| e.to_string())
}

pub fn start_redis(bin: &PathBuf) -> Result<(Process, u16), String> {
    let port = free_port()?;
    let dir = std::env::temp_dir().join(format!("lasertag-fleet-probe-redis-{port}"));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let child = Command::new(bin)
        .args(["--port", &port.to_string(), "--bind", "127.0.0.1"])
        .args(["--save", "", "--appendonly", "no"])
        .arg("--dir")
        .arg(&dir)
        .stdout(Stdio::null())
        .spawn()
        .map_err(|e| format!("{}: {e} (apt-get install redis-server)", bin.display()))?;
    let started = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        if started.elapsed() > Duration::from_secs(10) {
            return Err("redis-server did not listen within 10 s".into());
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok((Process(child), port))
}

/// Starts node `k` of the server binary `server`, in the fleet of the Redis on port `redis`
/// (heartbeat every `heartbeat_s`) or alone.
pub fn start_node(
    server: &Path,
    heartbeat_s: f64,
    k: usize,
    redis: Option<u16>,
) -> Result<Node, String> {
    let data =
        std::env::temp_dir().join(format!("lasertag-fleet-probe-{}-{k}", std::process::id()));
    let _ = std::fs::remove_dir_all(&data);
    let mut cmd = Command::new(server);
    cmd.args(["serve", "--addr", "127.0.0.1:0", "--no-showcase"])
        .arg("--data-dir")
        .arg(&data)
        // Every client is 127.0.0.1: lift what would refuse one machine's load.
        .args(["--max-connections-per-address", "100000"])
        .args(["--max-spectators-per-match", "100000"])
        .args(["--max-spectators-per-address", "100000"])
        .args(["--max-matches-per-address", "100000"])
        .args(["--requests-per-s", "1000000", "--request-burst", "1000000"])
        .args(["--client-budget-share", "1"])
        .env("RUST_LOG", "info")
        .env("NO_COLOR", "1")
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    if let Some(port) = redis {
        cmd.args(["--fleet", &format!("redis://127.0.0.1:{port}/0")])
            .args(["--node-id", &format!("n{k}")])
            .args(["--fleet-heartbeat-s", &heartbeat_s.to_string()])
            .args(["--fleet-ttl-s", &(3.0 * heartbeat_s).to_string()]);
    }
    let mut child = cmd
        .spawn()
        .map_err(|e| format!("{}: {e}", server.display()))?;
    let stdout = child.stdout.take().ok_or("no stdout")?;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Some(rest) = line.split("serving http://").nth(1) {
                let _ = tx.send(rest.split_whitespace().next().unwrap_or("").to_owned());
            }
        }
    });
    let process = Process(child);
    let addr: SocketAddr = rx
        .recv_timeout(Duration::from_secs(60))
        .map_err(|_| "a node did not log its address")?
        .parse()
        .map_err(|e| format!("{e}"))?;
    Ok(Node {
        process,
        url: format!("http://{addr}"),
        addr,
    })
}

pub async fn metric(http: &reqwest::Client, node: &Node, name: &str) -> f64 {
    let Ok(r) = http.get(format!("{}/metrics", node.url)).send().await else {
        return 0.0;
    };
    let text = r.text().await.unwrap_or_default();
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.trim().parse().ok())
        .unwrap_or(0.0)
}

/// Redis's `INFO stats` counters and its process's CPU.
pub async fn redis_counters(con: &mut redis::aio::MultiplexedConnection) -> (f64, f64, f64, f64) {
    let info: String = redis::cmd("INFO")
        .arg("stats")
        .query_async(con)
        .await
        .unwrap_or_default();
    let field = |name: &str| {
        info.lines()
            .find_map(|l| l.strip_prefix(name)?.strip_prefix(':')?.trim().parse().ok())
            .unwrap_or(0.0)
    };
    let server: String = redis::cmd("INFO")
        .arg("server")
        .query_async(con)
        .await
        .unwrap_or_default();
    let pid: u32 = server
        .lines()
        .find_map(|l| l.strip_prefix("process_id:")?.trim().parse().ok())
        .unwrap_or(0);
    (
        field("total_commands_processed"),
        field("total_net_input_bytes"),
        field("total_net_output_bytes"),
        cpu_seconds(pid),
    )
}
