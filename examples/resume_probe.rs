//! How long a restarted server takes to bring back the matches it was running
//! (docs/operations.md, "Matches survive their server").
//!
//! 1. Plays `--matches` matches `--minutes` into play in-process and writes each one's
//!    record to a fresh SQLite store as a running match does: its start with owner and
//!    seat, then its inputs a second at a time, and a checkpoint of the core's state every
//!    `--checkpoint-every` ticks (600, the server's; 0 for none: a resume then re-simulates
//!    every match from its first tick), the newest two kept. None is ended: the store is what a server
//!    killed at that moment leaves. The match is one that lasts: one coordinated robot
//!    against eight bots that run from it on `warehouse` (two robots, or five bots, tag them
//!    all within five minutes in nearly every seed); in half of them a person has taken a
//!    bot's place, keys changing a few times a second, its truth shown 30 s late. A match
//!    that ends before is played again with another seed.
//! 2. Starts the real release binary on that store and times, from the spawn: its first
//!    `GET /api/health`, and each match's first `200` to `GET /api/matches/{id}` (503 until
//!    then): p50 and max, and when the last was back.
//!
//! `cargo build --release && cargo run --release --example resume_probe -- [--matches 100]
//! [--minutes 5] [--seed 1] [--checkpoint-every 600]`

use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use lasertag::access::SecretHash;
use lasertag::maps::MapStore;
use lasertag::store::codec::{StoredClock, StoredLive, StoredSeat, StoredSettings};
use lasertag::store::{Retention, Store, Write};
use lasertag_core::planner::PlannerKind;
use lasertag_core::world::{ControlKind, HumanInput, MatchConfig, MatchStatus, World, WorldInput};
use rand::{RngExt, SeedableRng};

fn flag(name: &str, default: u64) -> u64 {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

/// One running match's record, as the store gets it.
struct Record {
    id: String,
    writes: Vec<Write>,
    /// The newest checkpoint's size as stored (deflated).
    checkpoint_bytes: usize,
}

/// Plays match `i` for `ticks` ticks; `None` when it ended before (it would not be running).
fn play(
    i: u64,
    seed: u64,
    ticks: u64,
    checkpoint_every: u64,
    arena: Arc<lasertag_core::sim::arena::Arena>,
) -> Option<Record> {
    let people = i.is_multiple_of(2);
    let mut config = MatchConfig {
        robots: 1,
        opponents: 8,
        planner: PlannerKind::Coordinated,
        opponent_control: ControlKind::Bot,
        seed: seed * 1000 + i,
        time_limit_ticks: 3600 * 20,
        ..MatchConfig::default()
    };
    config.opponent_bot = lasertag_core::bots::BotKind::Evade;
    let delay = if people { 600 } else { 0 };
    let mut world = World::new(arena.clone(), config.clone()).ok()?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(config.seed);
    let mut inputs: Vec<(u64, WorldInput)> = Vec::new();
    let id = format!("probe{i:08}");
    let token = format!("{:032x}", config.seed);
    let mut seats = Vec::new();
    if people {
        let seat = WorldInput::Seat {
            slot: 0,
            name: format!("p{i}"),
        };
        world.apply(&seat).ok()?;
        inputs.push((0, seat));
        seats.push(StoredSeat {
            seat: 0,
            player_id: format!("{i:016x}"),
            name: format!("p{i}"),
            token: SecretHash::of(&token).to_hex(),
            client: Some("127.0.0.1".into()),
        });
    }
    let settings = StoredSettings::of(&config, StoredClock::Realtime, people, delay, None, false);
    let mut writes = vec![Write::Begin {
        id: id.clone(),
        arena: arena.clone(),
        settings: Box::new(settings),
        live: Box::new(StoredLive {
            owner: Some(SecretHash::of(&token).to_hex()),
            client: Some("127.0.0.1".into()),
            reads_live: true,
            seats,
            head_start_ticks: 0,
            people: Vec::new(),
        }),
        started_at: SystemTime::now(),
    }];
    let mut stored = inputs.len();
    let mut pending = std::mem::take(&mut inputs);
    let mut last_checkpoint = 0;
    let mut checkpoints = Vec::new();
    while world.tick < ticks {
        if people && world.tick.is_multiple_of(8) {
            let keys = WorldInput::Keys {
                slot: 0,
                input: HumanInput {
                    forward: rng.random_range(-1.0..1.0),
                    turn: rng.random_range(-1.0..1.0),
                    ..HumanInput::default()
                },
            };
            if world.apply(&keys).is_ok() {
                pending.push((world.tick, keys));
            }
        }
        world.step();
        if world.status != MatchStatus::Running {
            return None;
        }
        if world.tick.is_multiple_of(20) {
            stored += pending.len();
            writes.push(Write::Append {
                id: id.clone(),
                inputs: std::mem::take(&mut pending),
                names: None,
                live: None,
                tick: world.tick,
            });
            if checkpoint_every > 0 && world.tick.is_multiple_of(checkpoint_every) {
                // The store keeps the newest two; holding only those here keeps the probe's
                // memory to two worlds a match.
                if checkpoints.len() == 2 {
                    checkpoints.remove(0);
                }
                checkpoints.push(Write::Checkpoint {
                    id: id.clone(),
                    tick: world.tick,
                    applied: stored as u64,
                    keep_from: last_checkpoint,
                    world: Box::new(world.clone()),
                    max_bytes: u64::MAX,
                });
                last_checkpoint = world.tick;
            }
        }
    }
    let checkpoint_bytes = match checkpoints.last() {
        Some(Write::Checkpoint { world, .. }) => {
            lasertag::store::codec::encode_checkpoint(world, u64::MAX).map_or(0, |b| b.len())
        }
        _ => 0,
    };
    writes.extend(checkpoints);
    Some(Record {
        id,
        writes,
        checkpoint_bytes,
    })
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// The status of `GET path` on 127.0.0.1:`port` (HTTP/1.0), or `None` while nothing answers.
fn status(port: u16, path: &str) -> Option<u16> {
    use std::io::{Read, Write};
    let mut s = TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    write!(s, "GET {path} HTTP/1.0\r\nHost: probe\r\n\r\n").ok()?;
    let mut head = [0u8; 12];
    s.read_exact(&mut head).ok()?;
    std::str::from_utf8(&head[9..12]).ok()?.parse().ok()
}

/// The body of `GET path` on 127.0.0.1:`port` (HTTP/1.0), or `None` while nothing answers.
fn body(port: u16, path: &str) -> Option<String> {
    use std::io::{Read, Write};
    let mut s = TcpStream::connect(("127.0.0.1", port)).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    write!(s, "GET {path} HTTP/1.0\r\nHost: probe\r\n\r\n").ok()?;
    let mut all = String::new();
    s.read_to_string(&mut all).ok()?;
    Some(all.split_once("\r\n\r\n")?.1.to_string())
}

fn main() {
    let matches = flag("--matches", 100);
    let minutes = flag("--minutes", 5);
    let seed = flag("--seed", 1);
    let checkpoint_every = flag("--checkpoint-every", 600);
    let ticks = minutes * 60 * 20;
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let maps = MapStore::load_dir(&root.join("maps")).expect("the shipped maps");
    let arena = maps.get("warehouse").expect("warehouse").arena.clone();
    let dir: PathBuf =
        std::env::temp_dir().join(format!("lasertag-resume-probe-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);

    // 1. The records, played on every core.
    let t = Instant::now();
    let cores = std::thread::available_parallelism().map_or(2, |n| n.get()) as u64;
    let next = Arc::new(std::sync::atomic::AtomicU64::new(0));
    let records = Arc::new(std::sync::Mutex::new(Vec::new()));
    let workers: Vec<_> = (0..cores)
        .map(|_| {
            let (next, records, arena) = (next.clone(), records.clone(), arena.clone());
            std::thread::spawn(move || {
                loop {
                    if records.lock().unwrap().len() as u64 >= matches {
                        break;
                    }
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    if i > 20 * matches {
                        panic!(
                            "fewer than one match in 20 is still running {minutes} min into play"
                        );
                    }
                    if let Some(r) = play(i, seed, ticks, checkpoint_every, arena.clone()) {
                        let mut all = records.lock().unwrap();
                        if (all.len() as u64) < matches {
                            all.push(r);
                            eprint!(
                                "\rplayed {} of {matches} matches {minutes} min into play",
                                all.len()
                            );
                        }
                    }
                }
            })
        })
        .collect();
    for w in workers {
        w.join().expect("a worker");
    }
    eprintln!(" ({:.1} s)", t.elapsed().as_secs_f64());
    let records = std::mem::take(&mut *records.lock().unwrap());
    let ids: Vec<String> = records.iter().map(|r| r.id.clone()).collect();
    let mut sizes: Vec<f64> = records.iter().map(|r| r.checkpoint_bytes as f64).collect();
    sizes.sort_by(f64::total_cmp);
    if checkpoint_every > 0 {
        eprintln!(
            "checkpoints every {checkpoint_every} ticks, the newest deflated: p50 {:.0} KiB, max {:.0} KiB",
            percentile(&sizes, 0.5) / 1024.0,
            percentile(&sizes, 1.0) / 1024.0
        );
    }
    {
        let store = Store::open(
            &dir,
            Retention {
                max_matches: 10_000,
                max_bytes: 1 << 32,
            },
        )
        .expect("a store");
        for r in records {
            for w in r.writes {
                let mut w = w;
                while let Err(back) = store.send(w) {
                    w = *back;
                    std::thread::sleep(Duration::from_millis(5));
                }
            }
        }
        store.flush(Duration::from_secs(60)).expect("stored");
    }

    // 2. The real server on it.
    let exe = std::env::current_exe().expect("this program's path");
    let bin = exe
        .parent()
        .and_then(Path::parent)
        .map(|d| d.join("lasertag"))
        .filter(|b| b.exists())
        .expect("the release binary next to the examples: run `cargo build --release` first");
    let port = free_port();
    let spawned = Instant::now();
    let mut child = Command::new(bin)
        .current_dir(root)
        .args([
            "serve",
            "--no-showcase",
            "--addr",
            &format!("127.0.0.1:{port}"),
        ])
        .arg("--data-dir")
        .arg(&dir)
        .env("RUST_LOG", "warn")
        .env("LASERTAG_REQUESTS_PER_S", "1000000")
        .env("LASERTAG_REQUEST_BURST", "1000000")
        .stdout(Stdio::null())
        .spawn()
        .expect("the server starts");
    let health = loop {
        if status(port, "/api/health") == Some(200) {
            break spawned.elapsed();
        }
        assert!(
            spawned.elapsed() < Duration::from_secs(60),
            "no health in 60 s"
        );
        std::thread::sleep(Duration::from_millis(5));
    };
    // Light polling, so as not to load the server it measures: the lobby's listing (every
    // match back is in it) every 100 ms, and one match not back yet, which must say 503.
    let mut back: Vec<Option<Duration>> = vec![None; ids.len()];
    let mut unavailable = 0u64;
    while back.iter().any(Option::is_none) {
        let listing = body(port, "/api/matches").unwrap_or_default();
        let now = spawned.elapsed();
        for (i, id) in ids.iter().enumerate() {
            if back[i].is_none() && listing.contains(&format!("\"{id}\"")) {
                back[i] = Some(now);
            }
        }
        if let Some(i) = back.iter().position(Option::is_none) {
            match status(port, &format!("/api/matches/{}", ids[i])) {
                Some(503) => unavailable += 1,
                Some(200) => {}
                other => panic!("match {}: {other:?}", ids[i]),
            }
        }
        assert!(
            spawned.elapsed() < Duration::from_secs(300),
            "not all back in 300 s"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let _ = child.kill();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&dir);
    let mut s: Vec<f64> = back.iter().flatten().map(Duration::as_secs_f64).collect();
    s.sort_by(f64::total_cmp);
    println!(
        "{} matches {minutes} min into play ({} ticks each): health after {:.0} ms; back p50 {:.2} s, first {:.2} s, last {:.2} s ({unavailable} polls of a match not back answered 503)",
        ids.len(),
        ticks,
        health.as_secs_f64() * 1e3,
        percentile(&s, 0.5),
        s[0],
        s[s.len() - 1],
    );
}
