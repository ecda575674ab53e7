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
//!   peak (sampled every 50 ms) and after it (6 s after its last answer);
//! - the bystander's tick (`GET /api/matches/{id}` every 100 ms): whether it advanced, its
//!   ticks per second, and the longest time it did not advance (the sampling alone makes that
//!   100–150 ms), and, after the class, the longest interval between two of its ticks as its
//!   own task measured it (`longest_tick_gap_ms` of its `/stats`: 50 ms when on time);
//! - `GET /api/health` every 100 ms, from an address of its own (127.0.0.250): the median
//!   and slowest answers, and answers that never came.
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
//!   robots, 8 bots, warehouse) steps 20,000 ticks in one request;
//! - `seed-oracle`: a headless copy of a match people may join, made from its listing (its
//!   settings and seed), stepped to the live tick: how far its robots are from the live ones
//!   (and whether the showcase's seed is listed);
//! - `events-fog`: a player alone in one room while a robot tags another opponent in the
//!   next: the shots and tags out of its sight that reached its socket before spectators
//!   saw them;
//! - `slow-export`: three exports of a 6,000-tick replay whose readers stop for 35 s (two from
//!   127.0.0.2, one from .3), a visitor's export from .4 5 s later, then what the slow ones
//!   got in the end (lines, and the last line: complete, or where to resume);
//! - `conn-flood`: 1,000 connections from 127.0.0.2, each half a header: how many the server
//!   closed at once, and `/api/health` from .3;
//! - `seat-hold`: for 30 s ten addresses (.2 to .11) take every showcase seat they can
//!   (join-or-create and plain joins) and play each (one input), while every 2 s a visitor
//!   (each from its own address, .30 and up) asks for a seat as the lobby does;
//! - `idle-spectators`: once the showcase is 30 s old (its spectators see it that late), 60
//!   spectator sockets from each of ten addresses (.2 to .11) on it, reading nothing; a
//!   visitor from .30 tries to watch once a second for 30 s (run with `--timeout-s 120`);
//! - `command-cost`: sixteen waypoints between the far corners of a 500 m map, sent again and
//!   again to a manual match whose robots take orders (each a grid search);
//! - `inputs-growth`: commands of 1,000 waypoints to an API-driven opponent until the match
//!   refuses them;
//! - `command-memory`: 4,000 such commands into a real-time match, which is then deleted:
//!   the memory the live match holds of them (the peak) and leaves (after);
//! - `replay-cost`: strangers (127.0.0.2 to .5) read two 6,000-tick replays at their end and
//!   middle (each read a re-simulation) while a visitor creates a match every 300 ms;
//! - `replay-memory`: the biggest of a few big matches the server admits (a large open map,
//!   many agents, a lossy radio, a fine merge grid), stepped 1,000 ticks, ended and read twice
//!   by a stranger: the memory the reads take and leave;
//! - `disk-maps`: thirty matches on ~185 KB inline maps, each ended, against `--keep-mb 1`:
//!   the data directory's largest and last size;
//! - `search-planner`: a real-time search planner past its price (depth 6, branching 12, a
//!   round every tick), then four at the deepest priced in (depth 5, branching 6) from one
//!   address, left to run 10 s;
//! - `belief-loop`: four parallel loops of gzip'd `GET /belief` of a 100,000-particle role
//!   from one address, for 5 s;
//! - `name-claims`: `POST /api/names` of fresh names as fast as one address sends them, 10 s;
//! - `quic-datagrams`: over WebTransport, 5 s of datagrams of every bad kind (malformed,
//!   binary, oversized, 50 inputs at once) as fast as one session sends them, beside a
//!   session of the same address that reads nothing;
//! - `quic-sessions`: 40 WebTransport sessions on one match from one address, held 5 s.
//!
//! "request ms" is the wall time of the class's main request (for `match-table`, all 100; for
//! `slowloris`, the newcomer's request after 15 s; for `wallhack`, the first public read; for
//! `slow-export`, the visitor's export; for `conn-flood`, the health request; for
//! `idle-spectators`, the time until the visitor got in; for `replay-cost`, the slowest
//! creation; for `replay-memory`, the two reads; for `disk-maps`, the whole stream).
//!
//! Every server gets a data directory of its own under the system's temporary directory
//! (removed with it); "data KiB after" is its size after the class.
//!
//! Output: a Markdown table on stdout (one row per class), or JSON with `--json`; progress on
//! stderr.
//!
//! `harness.rs` starts and watches a server process; `classes.rs` holds the requests,
//! `fair.rs` those of fair play, `doors.rs` those of the classes that take a door's share
//! from other clients, `costs.rs` those that cost on a match's own thread, `history.rs`
//! those of replays and the history on disk, `priced.rs` those of the search planner,
//! belief reads and name claims, `quic.rs` those of WebTransport.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::Parser;
use serde_json::{Value, json};

#[derive(Debug, Parser)]
#[command(about = "Hostile requests against a real server process: status, time, memory, others")]
pub(crate) struct Args {
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
/// Long enough for a server that hands freed memory back every 5 s to have done so once.
pub(crate) const SETTLE: Duration = Duration::from_secs(6);

mod classes;
mod costs;
mod doors;
mod fair;
mod harness;
mod history;
mod priced;
mod quic;
#[allow(dead_code)]
#[path = "../../tests/common/wt.rs"]
mod wt;

use classes::*;
use harness::*;

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
    /// The bystander's own longest interval between two ticks, as its task measured it
    /// (`longest_tick_gap_ms` of its `/stats`; none from builds without it): the polled gap
    /// above includes the 100 ms of sampling and the poll's own wait.
    tick_gap_ms: Option<f64>,
    health_p50_ms: Option<f64>,
    health_max_ms: Option<f64>,
    health_failed: u32,
    /// The history's directory after the class (KiB).
    data_kib: Option<f64>,
    server_exit: Option<String>,
    seconds: f64,
}

async fn measure(args: &Args, class: Class, version: &mut Option<String>) -> Row {
    let started = Instant::now();
    let mut row = Row {
        class: class.name(),
        ..Row::default()
    };
    let mut server = match Server::start(args, class.server_flags()).await {
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
        pid: server.pid,
        data_dir: server.data_dir.clone(),
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
    if let Ok(a) = ctx
        .get(&format!("/api/matches/{}/stats", ctx.bystander))
        .await
    {
        row.tick_gap_ms = a.body["longest_tick_gap_ms"].as_f64();
    }
    (row.bystander_ticked, row.ticks_per_s, row.longest_gap_ms) =
        bystander_figures(first, &watch.ticks, from, to);
    row.health_max_ms = (watch.health_max_ms > 0.0).then_some(watch.health_max_ms);
    row.health_p50_ms = median(watch.health_ms);
    row.health_failed = watch.health_failed;
    row.data_kib = Some(dir_bytes(&server.data_dir) as f64 / 1024.0);
    row.server_exit = server.exited();
    server.kill().await;
    row.seconds = started.elapsed().as_secs_f64();
    row
}

/// The median of `xs`, none when empty.
fn median(mut xs: Vec<f64>) -> Option<f64> {
    xs.sort_by(f64::total_cmp);
    xs.get(xs.len() / 2).copied()
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
        "| class | status | request ms | RSS MiB before / peak / after | bystander ticked | bystander ticks/s | longest bystander gap ms (polled / its task's) | health p50 ms | health max ms | data KiB after | notes |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let [b, p, a] = r.rss_mib;
        out += &format!(
            "| {} | {} | {} | {} / {} / {} | {} | {} | {} / {} | {} | {} | {} | {} |\n",
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
            num(r.tick_gap_ms),
            num(r.health_p50_ms),
            num(r.health_max_ms),
            num(r.data_kib),
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
                   "bystander_tick_gap_ms": r.tick_gap_ms,
                   "health_p50_ms": r.health_p50_ms, "health_max_ms": r.health_max_ms, "health_failed": r.health_failed,
                   "data_kib_after": r.data_kib,
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
