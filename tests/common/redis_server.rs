//! A real `redis-server` on a free loopback port, in a temporary directory, nothing saved to
//! disk; killed when dropped. For the fleet's tests. `bash tests/run.sh` installs Debian's
//! `redis-server` when it is missing; `LASERTAG_REDIS_SERVER` names another binary.
#![allow(dead_code)]

use std::io::{Read, Write};
use std::net::{Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub struct RedisServer {
    child: Child,
    pub port: u16,
    dir: PathBuf,
}

impl Drop for RedisServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A port nothing listens on now (another process may take it before redis does: `start`
/// tries again then).
fn free_port() -> u16 {
    TcpListener::bind((Ipv4Addr::LOCALHOST, 0))
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free loopback port")
}

/// Whether a Redis answers `PING` on `port`.
fn answers(port: u16) -> bool {
    let addr = SocketAddr::from((Ipv4Addr::LOCALHOST, port));
    let Ok(mut s) = TcpStream::connect_timeout(&addr, Duration::from_millis(200)) else {
        return false;
    };
    let _ = s.set_read_timeout(Some(Duration::from_millis(500)));
    let mut buf = [0u8; 7];
    s.write_all(b"PING\r\n").is_ok() && s.read_exact(&mut buf).is_ok() && &buf == b"+PONG\r\n"
}

impl RedisServer {
    /// Starts one, or fails the test saying how to get `redis-server`: a fleet test that
    /// cannot run must not pass.
    pub fn start() -> RedisServer {
        let bin = std::env::var("LASERTAG_REDIS_SERVER").unwrap_or_else(|_| "redis-server".into());
        for _ in 0..5 {
            let port = free_port();
            let dir =
                std::env::temp_dir().join(format!("lasertag-redis-{}-{port}", std::process::id()));
            let _ = std::fs::remove_dir_all(&dir);
            std::fs::create_dir_all(&dir).expect("a temporary directory");
            let child = Command::new(&bin)
                .args(["--port", &port.to_string(), "--bind", "127.0.0.1"])
                .args(["--save", "", "--appendonly", "no", "--daemonize", "no"])
                .arg("--dir")
                .arg(&dir)
                .stdout(Stdio::null())
                .stderr(Stdio::inherit())
                .spawn();
            let child = match child {
                Ok(c) => c,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => panic!(
                    "{bin} is not installed: the fleet's tests need a real Redis. `bash tests/run.sh` installs Debian's package (apt-get install redis-server); LASERTAG_REDIS_SERVER may name another binary"
                ),
                Err(e) => panic!("{bin} does not start: {e}"),
            };
            let mut redis = RedisServer { child, port, dir };
            let started = Instant::now();
            while started.elapsed() < Duration::from_secs(10) {
                if answers(port) {
                    return redis;
                }
                // Exited: most likely the port was taken in between; try another.
                if redis.child.try_wait().ok().flatten().is_some() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
        }
        panic!("{bin} did not answer PING on a loopback port (5 tries)");
    }

    /// The `--fleet` URL of it.
    pub fn url(&self) -> String {
        format!("redis://127.0.0.1:{}/0", self.port)
    }
}
