//! A PostgreSQL server of the tests' own: `initdb` in a temporary directory, `postgres` on a
//! free loopback port (fsync off), a database per test, everything gone when the last test
//! using it drops its [`Database`]. Tests that use it run in parallel, each in its own
//! database of one shared server.
//!
//! PostgreSQL refuses to run as root: as root, the server runs as `postgres` (Debian's
//! package makes that user) or else `nobody`, owning the directory. It runs under a small
//! shell that holds a pipe from the test process and stops the server when the pipe closes,
//! so a test binary that is killed takes its server with it.
//!
//! The binaries are looked for in `LASERTAG_PG_BIN`, on `PATH`, then in Debian's
//! `/usr/lib/postgresql/<version>/bin`.
#![allow(dead_code)]

use std::io::Read;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::{Arc, Mutex, Weak};
use std::time::{Duration, Instant};

/// The database user `initdb` makes (a superuser, no password, trusted on loopback).
const USER: &str = "lasertag";

/// A running PostgreSQL server in a directory of its own.
pub struct Cluster {
    pub port: u16,
    base: PathBuf,
    child: Child,
    /// Closing it stops the server (see the module doc).
    lifeline: Option<ChildStdin>,
}

/// One test's database on the shared [`Cluster`].
pub struct Database {
    /// `postgres://lasertag@127.0.0.1:<port>/<name>`.
    pub url: String,
    pub name: String,
    pub cluster: Arc<Cluster>,
}

/// The cluster tests share while any of them holds a database on it.
static SHARED: Mutex<Weak<Cluster>> = Mutex::new(Weak::new());

/// A new, empty database named after `what`, on the shared cluster (started if none runs).
/// Blocking; safe inside a tokio test (the client runs on a thread of its own).
pub fn database(what: &str) -> Database {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let name: String = format!("{what}_{}_{n}", std::process::id())
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect();
    // Held while creating, too: PostgreSQL copies template1 for each new database and
    // refuses two copies at once.
    let mut shared = SHARED.lock().unwrap_or_else(|e| e.into_inner());
    let cluster = match shared.upgrade() {
        Some(c) => c,
        None => {
            let c = Arc::new(Cluster::start());
            *shared = Arc::downgrade(&c);
            c
        }
    };
    cluster.sql("postgres", &format!("CREATE DATABASE \"{name}\""));
    Database {
        url: format!("postgres://{USER}@127.0.0.1:{}/{name}", cluster.port),
        name,
        cluster,
    }
}

impl Database {
    /// The same database through the server's Unix socket (`host` a percent-encoded path).
    pub fn socket_url(&self) -> String {
        let dir = self.cluster.base.display().to_string().replace('/', "%2F");
        format!(
            "postgres://{USER}@{dir}:{}/{}",
            self.cluster.port, self.name
        )
    }

    /// Runs `sql` (one or more statements) in this database.
    pub fn sql(&self, sql: &str) {
        self.cluster.sql(&self.name, sql);
    }

    /// The first column of the first row of `sql`, as text (`NULL` as `None`).
    pub fn query_text(&self, sql: &str) -> Option<String> {
        let (port, name, sql) = (self.cluster.port, self.name.clone(), sql.to_string());
        on_a_thread(move || {
            let mut c = connect(port, &name).expect("the test database answers");
            let row = c.query_one(sql.as_str(), &[]).expect(&sql);
            row.get::<_, Option<String>>(0)
        })
    }
}

/// Runs `f` on a plain thread: the `postgres` client panics on a tokio worker.
fn on_a_thread<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    std::thread::spawn(f).join().expect("the database thread")
}

fn connect(port: u16, db: &str) -> Result<postgres::Client, postgres::Error> {
    postgres::Config::new()
        .host("127.0.0.1")
        .port(port)
        .user(USER)
        .dbname(db)
        .connect_timeout(Duration::from_secs(5))
        .connect(postgres::NoTls)
}

/// The directory of PostgreSQL's server binaries.
fn binaries() -> PathBuf {
    if let Some(dir) = std::env::var_os("LASERTAG_PG_BIN") {
        return PathBuf::from(dir);
    }
    let on_path = std::env::var_os("PATH")
        .map(|p| std::env::split_paths(&p).collect::<Vec<_>>())
        .unwrap_or_default();
    if let Some(dir) = on_path.into_iter().find(|d| d.join("initdb").is_file()) {
        return dir;
    }
    let mut versions: Vec<(u32, PathBuf)> = std::fs::read_dir("/usr/lib/postgresql")
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let v = e.file_name().to_str()?.parse().ok()?;
            let bin = e.path().join("bin");
            bin.join("initdb").is_file().then_some((v, bin))
        })
        .collect();
    versions.sort();
    match versions.pop() {
        Some((_, bin)) => bin,
        None => panic!(
            "PostgreSQL's server binaries (initdb, postgres) are not installed: install the \
             Debian package `postgresql` (apt-get install postgresql), or set LASERTAG_PG_BIN \
             to the directory that holds them"
        ),
    }
}

/// The uid and gid to run the server as when we are root: `postgres`, else `nobody`.
fn unprivileged() -> (u32, u32) {
    let passwd = std::fs::read_to_string("/etc/passwd").unwrap_or_default();
    for name in ["postgres", "nobody"] {
        for line in passwd.lines() {
            let f: Vec<&str> = line.split(':').collect();
            if f.len() > 3
                && f[0] == name
                && let (Ok(uid), Ok(gid)) = (f[2].parse(), f[3].parse())
            {
                return (uid, gid);
            }
        }
    }
    panic!("running as root, and neither a `postgres` nor a `nobody` user to run PostgreSQL as")
}

/// A command that runs as `owner` when there is one.
fn command(program: &Path, owner: Option<(u32, u32)>, base: &Path) -> Command {
    use std::os::unix::process::CommandExt;
    let mut c = Command::new(program);
    c.current_dir(base);
    if let Some((uid, gid)) = owner {
        c.uid(uid).gid(gid);
    }
    c
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free loopback port")
        .port()
}

impl Cluster {
    /// `initdb` and a server, ready for connections.
    pub fn start() -> Cluster {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let bin = binaries();
        let base = std::env::temp_dir().join(format!("lasertag-pg-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&base);
        std::fs::create_dir_all(&base).expect("a temporary directory");
        let root = std::fs::metadata(&base)
            .map(|m| m.uid() == 0)
            .unwrap_or(false);
        let owner = root.then(unprivileged);
        if let Some((uid, gid)) = owner {
            std::os::unix::fs::chown(&base, Some(uid), Some(gid)).expect("chown");
        }
        let out = command(&bin.join("initdb"), owner, &base)
            .args(["-D", "data", "-U", USER, "-A", "trust", "-E", "UTF8"])
            .args(["--locale=C", "--no-sync", "--no-instructions"])
            .output()
            .expect("initdb runs");
        assert!(
            out.status.success(),
            "initdb failed: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        for _ in 0..5 {
            if let Some(cluster) = Cluster::serve(&bin, owner, &base) {
                return cluster;
            }
        }
        panic!("PostgreSQL never started: {}", log(&base));
    }

    /// The server on a free port, once it accepts connections; none when it exited (the port
    /// taken in between).
    fn serve(bin: &Path, owner: Option<(u32, u32)>, base: &Path) -> Option<Cluster> {
        let port = free_port();
        let logfile = std::fs::File::create(base.join("log")).expect("the log file");
        if let Some((uid, gid)) = owner {
            let _ = std::os::unix::fs::chown(base.join("log"), Some(uid), Some(gid));
        }
        // The shell's stdin is the lifeline: when it closes, `read` returns and the server
        // gets SIGQUIT (immediate shutdown); the shell ends with the server.
        let script = r#"exec 3<&0 </dev/null
"$0" "$@" &
pid=$!
{ read -r _ <&3; kill -QUIT "$pid" 2>/dev/null; } &
wait "$pid""#;
        let mut child = command(Path::new("/bin/sh"), owner, base)
            .arg("-c")
            .arg(script)
            .arg(bin.join("postgres"))
            .args(["-D", "data", "-p", &port.to_string(), "-k"])
            .arg(base)
            .args(["-F", "-c", "listen_addresses=127.0.0.1"])
            .args(["-c", "max_connections=200", "-c", "full_page_writes=off"])
            .stdin(Stdio::piped())
            .stdout(logfile.try_clone().expect("the log file"))
            .stderr(logfile)
            .spawn()
            .expect("sh starts PostgreSQL");
        let lifeline = child.stdin.take();
        let cluster = Cluster {
            port,
            base: base.to_path_buf(),
            child,
            lifeline,
        };
        let deadline = Instant::now() + Duration::from_secs(60);
        let mut cluster = cluster;
        loop {
            if connect(port, "postgres").is_ok() {
                return Some(cluster);
            }
            if let Ok(Some(_)) = cluster.child.try_wait() {
                // Exited: dropping it must not delete the directory of the next try.
                cluster.lifeline = None;
                cluster.base = PathBuf::new();
                return None;
            }
            assert!(
                Instant::now() < deadline,
                "PostgreSQL did not accept connections within 60 s: {}",
                log(base)
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Runs `sql` in database `db`.
    pub fn sql(&self, db: &str, sql: &str) {
        let (port, db, sql) = (self.port, db.to_string(), sql.to_string());
        on_a_thread(move || {
            let mut c = connect(port, &db).expect("the test cluster answers");
            c.batch_execute(&sql)
                .unwrap_or_else(|e| panic!("{sql}: {e:?}"));
        });
    }
}

fn log(base: &Path) -> String {
    let mut text = String::new();
    if let Ok(mut f) = std::fs::File::open(base.join("log")) {
        let _ = f.read_to_string(&mut text);
    }
    text
}

impl Drop for Cluster {
    fn drop(&mut self) {
        self.lifeline = None;
        let _ = self.child.wait();
        if !self.base.as_os_str().is_empty() {
            let _ = std::fs::remove_dir_all(&self.base);
        }
    }
}
