//! The `lasertag` binary: parse the command line, load the maps, serve, shut down cleanly.

use std::io::IsTerminal;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use clap::{Parser, Subcommand};
use lasertag::game::Registry;
use lasertag::maps::MapStore;

#[derive(Debug, Parser)]
#[command(
    version,
    about = "A team of autonomous robots plays laser tag against people in a web browser."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    serve: ServeArgs,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Serve the game and the API (the default command).
    Serve(ServeArgs),
    /// Reproduce one of the paper's experiments: CSV files and SVG plots.
    #[command(subcommand)]
    Experiment(Experiment),
    /// Ask a running server's `GET /api/health`; exit 0 when it answers ok (the container's
    /// HEALTHCHECK: the runtime image has no curl).
    Healthcheck {
        /// The server's address; 0.0.0.0 or [::] (listening everywhere) is asked on loopback.
        #[arg(long, env = "LASERTAG_ADDR", default_value = "127.0.0.1:8080")]
        addr: SocketAddr,
        /// Seconds to wait for the answer.
        #[arg(long, default_value_t = 3)]
        timeout_s: u64,
    },
}

#[derive(Debug, Subcommand)]
enum Experiment {
    /// Fig. 4: active filters with and without role merging on `hallway`.
    Filters {
        /// Runs per variant (with and without merging).
        #[arg(long, default_value_t = 25)]
        runs: usize,
        /// Opponents passing the door in each run.
        #[arg(long, default_value_t = 20)]
        opponents: usize,
        /// Particles per role.
        #[arg(long, default_value_t = 1000)]
        particles: usize,
        /// Symmetric KL divergence under which two roles merge.
        #[arg(long, default_value_t = 0.7)]
        kl_cutoff: f32,
        /// Seed of the first run (run i uses seed + i).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Directory of map files.
        #[arg(long, default_value = "maps")]
        maps: PathBuf,
        /// Where to write filters.csv and filters.svg.
        #[arg(long, default_value = "out/filters")]
        out: PathBuf,
    },
    /// Fig. 5: capture time of `coordinated` vs `baseline` on `office` and `warehouse`.
    Capture {
        /// Runs per map, opponent bot and planner.
        #[arg(long, default_value_t = 100)]
        runs: usize,
        /// Seed of the first run (run i uses seed + i, the same for both planners).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Time limit of each run in seconds (runs that reach it count as not captured).
        #[arg(long, default_value_t = 300)]
        time_limit: u64,
        /// Maps to run on.
        #[arg(long, value_delimiter = ',', default_value = "office,warehouse")]
        on: Vec<String>,
        /// Directory of map files.
        #[arg(long, default_value = "maps")]
        maps: PathBuf,
        /// Where to write the CSV files and plots.
        #[arg(long, default_value = "out/capture")]
        out: PathBuf,
        /// Override a weight of the coordinated planner, e.g. `--set travel_weight=0.02`
        /// (repeatable; names as in the README's planner section).
        #[arg(long = "set", value_name = "NAME=VALUE")]
        set: Vec<String>,
        /// Whether robots localise themselves (false: odometry alone, which drifts).
        #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
        localisation: bool,
        /// Team radio latency in ticks (0..=100); with a latency or loss each robot keeps
        /// its own tracker.
        #[arg(long, default_value_t = 0)]
        radio_latency: u32,
        /// Probability that a robot misses one teammate message (0..=1).
        #[arg(long, default_value_t = 0.0)]
        radio_loss: f32,
    },
    /// Issue 6, Coltin et al.'s Table I: time for a robot to see an opponent again that a
    /// teammate sees, with and without shared hypotheses and the tracker's prediction.
    Reacquire {
        /// Runs per condition (the same seeds and routes in every condition).
        #[arg(long, default_value_t = 50)]
        runs: usize,
        /// Seed of the first run (run i uses seed + i).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Longest search counted, seconds (runs that reach it count at it).
        #[arg(long, default_value_t = 60)]
        limit: u64,
        /// Radio latency in ticks (no loss).
        #[arg(long, default_value_t = 2)]
        latency: u32,
        /// Directory of map files (the experiment runs on `office`).
        #[arg(long, default_value = "maps")]
        maps: PathBuf,
        /// Where to write the CSV files and the plot.
        #[arg(long, default_value = "out/reacquire")]
        out: PathBuf,
    },
    /// Issue 6: the robots' localisation error over time on every map: with landmarks,
    /// without them, and odometry alone.
    Localisation {
        /// Runs per map and variant (with and without landmarks).
        #[arg(long, default_value_t = 3)]
        runs: usize,
        /// Seed of the first run (run i uses seed + i).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Length of each run in seconds.
        #[arg(long, default_value_t = 600)]
        seconds: u64,
        #[arg(long, default_value_t = 2)]
        robots: usize,
        #[arg(long, default_value_t = 2)]
        opponents: usize,
        /// Directory of map files (every map in it is run).
        #[arg(long, default_value = "maps")]
        maps: PathBuf,
        /// Where to write the CSV files and plots.
        #[arg(long, default_value = "out/localisation")]
        out: PathBuf,
    },
    /// Issue 6, point 2: uncertainty-aware motion on and off, for robots that localise from
    /// landmarks and odometry alone (Fabiani & Latombe's setting).
    Uncertainty {
        /// Runs per map, opponent bot and variant (the same seeds in both variants).
        #[arg(long, default_value_t = 100)]
        runs: usize,
        /// Seed of the first run (run i uses seed + i).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Time limit of each run in seconds (runs that reach it count as not captured).
        #[arg(long, default_value_t = 300)]
        time_limit: u64,
        /// Laser beams the localiser uses (0: landmarks and odometry alone).
        #[arg(long, default_value_t = 0)]
        beams: usize,
        /// Odometry noise as a multiple of the default (5% of distance, 2°/m, 2% of turns).
        #[arg(long, default_value_t = 4.0)]
        odometry_scale: f32,
        /// Length of each hunt (tagging off) in seconds.
        #[arg(long, default_value_t = 120)]
        hunt_s: u64,
        /// Maps to run on.
        #[arg(long, value_delimiter = ',', default_value = "office,warehouse")]
        on: Vec<String>,
        /// Directory of map files.
        #[arg(long, default_value = "maps")]
        maps: PathBuf,
        /// Where to write the CSV files and plots.
        #[arg(long, default_value = "out/uncertainty")]
        out: PathBuf,
    },
}

#[derive(Debug, Clone, clap::Args)]
struct ServeArgs {
    /// Address to listen on.
    #[arg(long, env = "LASERTAG_ADDR", default_value = "127.0.0.1:8080")]
    addr: SocketAddr,
    /// Directory of map files (`<name>.json`).
    #[arg(long, env = "LASERTAG_MAPS", default_value = "maps")]
    maps: PathBuf,
    /// Directory of the static web client.
    #[arg(long, env = "LASERTAG_WEB", default_value = "web")]
    web: PathBuf,
    /// Start without the showcase match.
    #[arg(long, env = "LASERTAG_NO_SHOWCASE")]
    no_showcase: bool,
    #[command(flatten)]
    config: lasertag::config::Config,
}

fn main() -> ExitCode {
    // Colour only for a person at a terminal: `docker logs` and log collectors got escape
    // codes in every line. NO_COLOR (no-color.org) turns it off at a terminal too.
    let colour = std::io::stdout().is_terminal() && std::env::var_os("NO_COLOR").is_none();
    tracing_subscriber::fmt()
        .with_ansi(colour)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "info,tower_http=warn".into()),
        )
        .init();
    let cli = Cli::parse();
    let args = match cli.command {
        Some(Command::Serve(args)) => args,
        Some(Command::Experiment(e)) => {
            return match experiment(e) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::FAILURE
                }
            };
        }
        Some(Command::Healthcheck { addr, timeout_s }) => {
            return match healthcheck(addr, Duration::from_secs(timeout_s.max(1))) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("unhealthy: {e}");
                    ExitCode::FAILURE
                }
            };
        }
        None => cli.serve,
    };
    let runtime = match tokio::runtime::Runtime::new() {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("error: cannot start the async runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    let result = runtime.block_on(serve(args));
    // Whatever is still running (a blocking map build, a client that never closed) must not
    // hold the exit past the shutdown budget.
    runtime.shutdown_timeout(Duration::from_millis(200));
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `GET /api/health` over a plain TCP connection (HTTP/1.0, so the server closes after the
/// answer): std only, so the binary needs no HTTP client for its own health check.
fn healthcheck(mut addr: SocketAddr, timeout: Duration) -> Result<(), String> {
    use std::io::{Read, Write};
    if addr.ip().is_unspecified() {
        addr.set_ip(if addr.is_ipv4() {
            std::net::Ipv4Addr::LOCALHOST.into()
        } else {
            std::net::Ipv6Addr::LOCALHOST.into()
        });
    }
    let mut stream = std::net::TcpStream::connect_timeout(&addr, timeout)
        .map_err(|e| format!("cannot connect to {addr}: {e}"))?;
    stream
        .set_read_timeout(Some(timeout))
        .and_then(|()| stream.set_write_timeout(Some(timeout)))
        .map_err(|e| e.to_string())?;
    write!(
        stream,
        "GET /api/health HTTP/1.0\r\nHost: {addr}\r\nAccept: application/json\r\n\r\n"
    )
    .map_err(|e| format!("sending to {addr}: {e}"))?;
    let mut answer = Vec::new();
    // The body is a few dozen bytes; cap what a wrong server could make us read.
    stream
        .take(64 * 1024)
        .read_to_end(&mut answer)
        .map_err(|e| format!("reading from {addr}: {e}"))?;
    let answer = String::from_utf8_lossy(&answer);
    let status = answer.lines().next().unwrap_or_default();
    if !status.starts_with("HTTP/1.") || status.split(' ').nth(1) != Some("200") {
        return Err(format!("GET /api/health answered {status:?}"));
    }
    let body = answer.split("\r\n\r\n").nth(1).unwrap_or_default();
    let health: serde_json::Value =
        serde_json::from_str(body).map_err(|e| format!("GET /api/health: {e}: {body:?}"))?;
    if health["status"] != "ok" {
        return Err(format!("GET /api/health: {body}"));
    }
    Ok(())
}

/// From the signal to the end of `serve`: every client told and closed, or given up on.
/// The process must exit within 5 s of SIGTERM; this leaves room for the rest.
const SHUTDOWN_BUDGET: Duration = Duration::from_millis(4000);

async fn serve(args: ServeArgs) -> Result<(), String> {
    let maps = MapStore::load_dir(&args.maps).map_err(|e| format!("loading maps: {e}"))?;
    tracing::info!(maps = maps.len(), dir = %args.maps.display(), "maps loaded");
    tracing::info!(config = ?args.config, "settings");
    let registry = Registry::with_config(maps, args.config);
    if !args.no_showcase {
        tokio::spawn(lasertag::game::showcase::keep_running(registry.clone()));
    }
    let listener = tokio::net::TcpListener::bind(args.addr)
        .await
        .map_err(|e| format!("cannot listen on {}: {e}", args.addr))?;
    let local = listener.local_addr().map_err(|e| e.to_string())?;
    tracing::info!("serving http://{local}");
    let app = lasertag::http::app(registry.clone(), args.web);
    let server = axum::serve(
        listener,
        app.into_make_service_with_connect_info::<SocketAddr>(),
    )
    .with_graceful_shutdown(shutdown_signal(registry.clone()))
    .into_future();
    tokio::pin!(server);
    // Before a signal only an accept loop that failed ends the server. After one, the server
    // future may well be the branch that finishes first (it has no HTTP request left to wait
    // for), and returning then dropped every WebSocket task mid-close: clients got a bare
    // EOF instead of `finished` and their close frame (issue 7, 2 to 7 runs in 30).
    let served_early = tokio::select! {
        r = &mut server => Some(r),
        _ = registry.shutdown.cancelled() => None,
    };
    if !registry.shutdown.is_cancelled() {
        return served_early
            .unwrap_or(Ok(()))
            .map_err(|e| format!("server error: {e}"));
    }
    // The listener is closed and every match told to stop: wait for the HTTP requests in
    // flight and for the WebSockets to send `finished` and close, within the budget.
    let deadline = tokio::time::Instant::now() + SHUTDOWN_BUDGET;
    let drained = tokio::time::timeout_at(deadline, async {
        let served = match served_early {
            Some(r) => r,
            None => (&mut server).await,
        };
        registry.connections_closed().await;
        served
    })
    .await;
    match drained {
        Ok(r) => {
            tracing::info!("shut down cleanly");
            r.map_err(|e| format!("server error: {e}"))
        }
        Err(_) => {
            tracing::warn!(
                "shutdown budget of {SHUTDOWN_BUDGET:?} spent; exiting with connections open"
            );
            Ok(())
        }
    }
}

/// Resolves on Ctrl-C or SIGTERM, after telling every match and connection to stop.
async fn shutdown_signal(registry: Arc<Registry>) {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = terminate => {},
    }
    tracing::info!("shutting down");
    registry.begin_shutdown().await;
}

/// The maps named in `on`, loaded from the directory `maps`.
fn chosen_maps(
    maps: &std::path::Path,
    on: &[String],
) -> Result<Vec<(String, Arc<lasertag::sim::arena::Arena>)>, String> {
    let store = MapStore::load_dir(maps).map_err(|e| format!("loading maps: {e}"))?;
    on.iter()
        .map(|name| {
            store
                .get(name)
                .map(|m| (name.clone(), m.arena.clone()))
                .ok_or_else(|| format!("no map {name:?} in {}", maps.display()))
        })
        .collect()
}

fn experiment(e: Experiment) -> Result<(), String> {
    match e {
        Experiment::Capture {
            runs,
            seed,
            time_limit,
            on,
            maps,
            out,
            set,
            localisation,
            radio_latency,
            radio_loss,
        } => {
            if runs == 0 || time_limit == 0 {
                return Err("--runs and --time-limit must be at least 1".into());
            }
            let chosen = chosen_maps(&maps, &on)?;
            let mut coordination = lasertag::planner::coordinated::Settings::default();
            for kv in &set {
                let (k, v) = kv
                    .split_once('=')
                    .ok_or_else(|| format!("--set {kv}: expected NAME=VALUE"))?;
                coordination
                    .set(k, v)
                    .map_err(|e| format!("--set {kv}: {e}"))?;
            }
            let radio = lasertag::radio::Settings {
                latency_ticks: radio_latency,
                loss: radio_loss,
                ..Default::default()
            };
            radio.validate().map_err(|e| {
                format!(
                    "--{}",
                    e.replacen("radio.", "radio-", 1).replacen("_ticks", "", 1)
                )
            })?;
            let cfg = lasertag::experiment::capture::CaptureConfig {
                runs,
                seed,
                time_limit_s: time_limit,
                coordination,
                localisation,
                radio,
            };
            let table = lasertag::experiment::capture::run(&chosen, &cfg, &out)?;
            print!("{table}");
            println!(
                "ratio: median capture time / baseline's; p: two-sided Mann–Whitney U against baseline\n\
                 wrote {0}/capture.csv, {0}/capture_summary.csv and {0}/capture_<map>_<bot>.svg",
                out.display()
            );
            Ok(())
        }
        Experiment::Reacquire {
            runs,
            seed,
            limit,
            latency,
            maps,
            out,
        } => {
            if runs == 0 || limit == 0 {
                return Err("--runs and --limit must be at least 1".into());
            }
            if latency > lasertag::radio::MAX_LATENCY_TICKS {
                return Err(format!(
                    "--latency {latency} must be in 0..={}",
                    lasertag::radio::MAX_LATENCY_TICKS
                ));
            }
            let store = MapStore::load_dir(&maps).map_err(|e| format!("loading maps: {e}"))?;
            let arena = store
                .get("office")
                .ok_or_else(|| format!("no office map in {}", maps.display()))?
                .arena
                .clone();
            let cfg = lasertag::experiment::reacquire::ReacquireConfig {
                runs,
                seed,
                limit_s: limit,
                latency_ticks: latency,
            };
            let summaries = lasertag::experiment::reacquire::run(arena, &cfg, &out)?;
            println!(
                "condition   shared  predicted  found    mean ± std (s)  median (s)  teammate saw"
            );
            for s in &summaries {
                println!(
                    "{:<11} {:<7} {:<10} {:>3}/{:<3} {:>7.2} ± {:<5.2} {:>10.2} {:>12.0}%",
                    s.condition.name,
                    s.condition.shared,
                    s.condition.predicted,
                    s.found,
                    s.runs,
                    s.mean_s,
                    s.std_s,
                    s.median_s,
                    100.0 * s.teammate_saw
                );
            }
            println!(
                "wrote {0}/reacquire.csv, {0}/reacquire_summary.csv and {0}/reacquire.svg",
                out.display()
            );
            Ok(())
        }
        Experiment::Localisation {
            runs,
            seed,
            seconds,
            robots,
            opponents,
            maps,
            out,
        } => {
            if runs == 0 || seconds == 0 || robots == 0 {
                return Err("--runs, --seconds and --robots must be at least 1".into());
            }
            let store = MapStore::load_dir(&maps).map_err(|e| format!("loading maps: {e}"))?;
            let mut arenas: Vec<Arc<lasertag::sim::arena::Arena>> =
                store.iter().map(|m| m.arena.clone()).collect();
            arenas.sort_by(|a, b| a.def.name.cmp(&b.def.name));
            let cfg = lasertag::experiment::localisation::LocalisationConfig {
                runs,
                seed,
                seconds,
                robots,
                opponents,
            };
            let curves = lasertag::experiment::localisation::run(&arenas, &cfg, &out)?;
            println!("map        variant        mean error (m)  worst (m)");
            for c in &curves {
                println!(
                    "{:<10} {:<14} {:>14.4} {:>10.4}",
                    c.map,
                    c.variant.name(),
                    c.mean,
                    c.worst
                );
            }
            println!(
                "wrote {0}/localisation.csv, {0}/localisation_summary.csv and {0}/localisation_<map>.svg",
                out.display()
            );
            Ok(())
        }
        Experiment::Uncertainty {
            runs,
            seed,
            time_limit,
            beams,
            odometry_scale,
            hunt_s,
            on,
            maps,
            out,
        } => {
            if runs == 0 || time_limit == 0 || hunt_s == 0 {
                return Err("--runs, --time-limit and --hunt-s must be at least 1".into());
            }
            if beams > 181 {
                return Err(format!(
                    "--beams {beams}: must be in 0..=181 (the laser has 181)"
                ));
            }
            // The noise scaled past the API's ranges (heading 45°/m, fractions 1) is nonsense.
            if !(0.0..=20.0).contains(&odometry_scale) {
                return Err(format!(
                    "--odometry-scale {odometry_scale}: must be in [0, 20]"
                ));
            }
            let chosen = chosen_maps(&maps, &on)?;
            let cfg = lasertag::experiment::uncertainty::UncertaintyConfig {
                runs,
                seed,
                time_limit_s: time_limit,
                beams,
                odometry_scale,
                hunt_s,
            };
            let table = lasertag::experiment::uncertainty::run(&chosen, &cfg, &out)?;
            print!("{table}");
            println!(
                "wrote {0}/uncertainty_{{hunt,capture}}{{,_summary}}.csv, {0}/uncertainty_lost.svg and {0}/uncertainty_error_<map>.svg",
                out.display()
            );
            Ok(())
        }
        Experiment::Filters {
            runs,
            opponents,
            particles,
            kl_cutoff,
            seed,
            maps,
            out,
        } => {
            if runs == 0
                || opponents == 0
                || particles < 10
                || !(kl_cutoff > 0.0 && kl_cutoff.is_finite())
            {
                return Err(
                    "--runs and --opponents must be at least 1, --particles at least 10, --kl-cutoff positive".into(),
                );
            }
            let store = MapStore::load_dir(&maps).map_err(|e| format!("loading maps: {e}"))?;
            let arena = store
                .get("hallway")
                .ok_or_else(|| format!("no hallway map in {}", maps.display()))?
                .arena
                .clone();
            let cfg = lasertag::experiment::filters::FiltersConfig {
                runs,
                opponents,
                seed,
                particles_per_role: particles,
                kl_cutoff,
            };
            let r = lasertag::experiment::filters::run(arena, &cfg, &out)?;
            println!(
                "with merging: mean active filters peaks at {:.2}, ends at {:.2}\n\
                 without merging: peaks at {:.2}, ends at {:.2} ({} s of play)\n\
                 wrote {}/filters.csv and {}/filters.svg",
                r.with_merge_max_mean,
                r.with_merge_final_mean,
                r.without_merge_max_mean,
                r.without_merge_final_mean,
                r.seconds,
                out.display(),
                out.display()
            );
            Ok(())
        }
    }
}
