//! The `lasertag` binary: parse the command line and run its command (serving is
//! `lasertag::process`).

use std::net::SocketAddr;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use clap::{Parser, Subcommand};
use lasertag::maps::MapStore;
use lasertag::process::ServeArgs;

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
    Serve(Box<ServeArgs>),
    /// Reproduce one of the paper's experiments: CSV files and SVG plots.
    #[command(subcommand)]
    Experiment(lasertag_lab::cli::Experiment),
    /// Import a ROS or MovingAI map as one of ours, or export one of ours as a ROS map.
    #[command(subcommand)]
    Map(lasertag::maps::cli::MapCommand),
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

/// Every map of `dir`, for the experiments (which know no map files).
fn load_maps(
    dir: &std::path::Path,
) -> Result<Vec<Arc<lasertag_core::sim::arena::Arena>>, lasertag_lab::error::LabError> {
    let store =
        MapStore::load_dir(dir).map_err(|e| lasertag_lab::error::LabError::Maps(e.into()))?;
    Ok(store.iter().map(|m| m.arena.clone()).collect())
}

fn main() -> ExitCode {
    lasertag::process::init_logging();
    let cli = Cli::parse();
    let args = match cli.command {
        Some(Command::Serve(args)) => *args,
        Some(Command::Experiment(e)) => {
            return match lasertag_lab::cli::run(e, load_maps) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::FAILURE
                }
            };
        }
        Some(Command::Map(command)) => {
            return match lasertag::maps::cli::run(&command) {
                Ok(report) => {
                    print!("{report}");
                    ExitCode::SUCCESS
                }
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
    match lasertag::process::run(args) {
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
