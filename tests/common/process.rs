//! The real `lasertag` binary as a child process, serving the shipped maps on an ephemeral
//! port (its address read from its log), for the tests that need a process: signals, a kill,
//! a restart.
#![allow(dead_code)]

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use serde_json::{Value, json};

pub struct Server {
    pub child: Child,
    pub addr: SocketAddr,
    /// The log lines that name a warning or an error, as they come.
    pub warnings: std::sync::Arc<std::sync::Mutex<Vec<String>>>,
    /// Every log line, as they come (the first 20,000).
    pub log: std::sync::Arc<std::sync::Mutex<Vec<String>>>,
}

impl Drop for Server {
    fn drop(&mut self) {
        // Only if the test failed before it exited.
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Server {
    /// `lasertag serve --addr 127.0.0.1:0` with `args` after it.
    pub fn start(args: &[&str]) -> Server {
        Server::start_with_env(args, &[])
    }

    /// [`Server::start`] with `env` added to the child's environment.
    pub fn start_with_env(args: &[&str], env: &[(&str, &str)]) -> Server {
        Server::start_at("127.0.0.1:0", args, env)
    }

    /// `lasertag serve --addr <addr>` with `args` after it and `env` added (a fixed address:
    /// a server started again where the last one was, for clients that reconnect).
    pub fn start_at(addr: &str, args: &[&str], env: &[(&str, &str)]) -> Server {
        Server::spawn(Server::command(addr, args, env))
    }

    /// [`Server::start`] in a process whose open files limit (soft and hard) is `files`, as
    /// a host's `ulimit -n` would set it.
    #[cfg(unix)]
    pub fn start_with_files(files: u64, args: &[&str]) -> Server {
        use std::os::unix::process::CommandExt;
        let mut cmd = Server::command("127.0.0.1:0", args, &[]);
        // SAFETY: between fork and exec the closure only calls setrlimit, which is
        // async-signal-safe, on a local.
        unsafe {
            cmd.pre_exec(move || {
                let lim = libc::rlimit {
                    rlim_cur: files as libc::rlim_t,
                    rlim_max: files as libc::rlim_t,
                };
                if libc::setrlimit(libc::RLIMIT_NOFILE, &lim) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
        Server::spawn(cmd)
    }

    fn command(addr: &str, args: &[&str], env: &[(&str, &str)]) -> Command {
        let root = env!("CARGO_MANIFEST_DIR");
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_lasertag"));
        cmd.current_dir(root)
            .args(["serve", "--addr", addr])
            .args(args)
            .envs(env.iter().copied())
            .env("RUST_LOG", "info")
            .env("NO_COLOR", "1")
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit());
        cmd
    }

    fn spawn(mut cmd: Command) -> Server {
        let mut child = cmd.spawn().expect("the lasertag binary starts");
        let stdout = child.stdout.take().expect("piped stdout");
        let (tx, rx) = std::sync::mpsc::channel();
        let warnings = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let log = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let (kept, all) = (warnings.clone(), log.clone());
        // Keep reading the log (so the pipe never fills) and pass the address on.
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                {
                    let mut all = all.lock().unwrap_or_else(|e| e.into_inner());
                    if all.len() < 20_000 {
                        all.push(line.clone());
                    }
                }
                if line.contains(" WARN ") || line.contains(" ERROR ") {
                    let mut kept = kept.lock().unwrap_or_else(|e| e.into_inner());
                    if kept.len() < 10_000 {
                        kept.push(line.clone());
                    }
                }
                let served = line.split("serving http://").nth(1);
                if let Some(rest) = served.or_else(|| line.split("serving https://").nth(1)) {
                    let addr: String = rest
                        .chars()
                        .take_while(|c| !c.is_whitespace() && *c != '\u{1b}')
                        .collect();
                    let _ = tx.send(addr);
                }
            }
        });
        let addr = rx
            .recv_timeout(Duration::from_secs(60))
            .expect("the server logs its address")
            .parse()
            .expect("a socket address");
        Server {
            child,
            addr,
            warnings,
            log,
        }
    }

    pub fn url(&self, path: &str) -> String {
        format!("http://{}{}", self.addr, path)
    }
}

/// A manual match on `s`: (id, owner token).
pub async fn create(client: &reqwest::Client, s: &Server, seed: u64) -> (String, String) {
    create_with(
        client,
        s,
        json!({"map": "office", "robots": 2, "opponents": 2, "clock": "manual",
            "opponent_bot": "evade", "seed": seed}),
    )
    .await
}

/// `POST /api/matches` of `body` on `s`: the match's id and owner token.
pub async fn create_with(client: &reqwest::Client, s: &Server, body: Value) -> (String, String) {
    let r: Value = client
        .post(s.url("/api/matches"))
        .json(&body)
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    (
        r["id"].as_str().unwrap().to_string(),
        r["owner_token"].as_str().unwrap().to_string(),
    )
}

/// Steps `ticks` and answers the state after them.
pub async fn step(
    client: &reqwest::Client,
    s: &Server,
    id: &str,
    token: &str,
    ticks: u64,
) -> Value {
    let r = client
        .post(s.url(&format!("/api/matches/{id}/step")))
        .bearer_auth(token)
        .json(&json!({"ticks": ticks}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    r.json().await.unwrap()
}

pub async fn get(client: &reqwest::Client, s: &Server, path: &str) -> (u16, Value) {
    let r = client.get(s.url(path)).send().await.unwrap();
    (r.status().as_u16(), r.json().await.unwrap_or(Value::Null))
}
