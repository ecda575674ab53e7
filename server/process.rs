//! The server process: from its settings to serving, and from a stop signal to a clean
//! exit (the drain, every client told and closed, the history flushed, a fleet left or its
//! matches handed over).
//!
//! Here rather than in the binary so that everything generic it drives (tokio's tasks for
//! these futures, the runtime's `block_on`) is compiled with this library, while the binary,
//! the last step of a clean build, only parses the command line.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use crate::fleet::{Fleet, FleetError};
use crate::game::Registry;
use crate::http::TooFewFiles;
use crate::http::tls::TlsError;
use crate::http::transport::{Source, TransportError};
use crate::maps::{LoadError, MapStore};
use crate::store::StoreError;

/// Why the server could not start, or stopped serving before a stop signal: printed by the
/// binary, which exits non-zero.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    #[error("cannot start the async runtime: {0}")]
    Runtime(std::io::Error),
    #[error(transparent)]
    TooFewFiles(#[from] TooFewFiles),
    #[error("loading maps: {0}")]
    Maps(#[from] LoadError),
    #[error("opening the history: {0}")]
    History(#[from] StoreError),
    #[error("cannot listen on {addr}: {source}")]
    Listen {
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error(transparent)]
    Fleet(#[from] FleetError),
    #[error(transparent)]
    Tls(#[from] TlsError),
    #[error(transparent)]
    WebTransport(#[from] TransportError),
    #[error("server error: {0}")]
    Serve(std::io::Error),
}

/// `lasertag serve`'s settings (the binary's default command): where to listen, what to
/// serve, and the limits, history and fleet of [`crate::config`], [`crate::store`] and
/// [`crate::fleet`].
#[derive(Debug, Clone, clap::Args)]
pub struct ServeArgs {
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
    /// Serve no WebTransport (HTTP/3 over UDP on the same port): pages then play over
    /// WebSockets only.
    #[arg(long, env = "LASERTAG_NO_WEBTRANSPORT")]
    no_webtransport: bool,
    /// The certificate (PEM, a chain), with `--tls-key`: the server then speaks HTTPS on
    /// its TCP port and WebTransport with it. Without them it speaks plain HTTP, and makes
    /// its own certificate for WebTransport, which browsers pin by its hash
    /// (`GET /api/transport`).
    #[arg(long, env = "LASERTAG_TLS_CERT", requires = "tls_key")]
    tls_cert: Option<PathBuf>,
    /// The private key (PEM) of `--tls-cert`.
    #[arg(long, env = "LASERTAG_TLS_KEY", requires = "tls_cert")]
    tls_key: Option<PathBuf>,
    #[command(flatten)]
    history: crate::store::StoreArgs,
    #[command(flatten)]
    config: crate::config::Config,
    #[command(flatten)]
    fleet: crate::fleet::FleetArgs,
}

/// Logs to stdout, filtered by `RUST_LOG` (default `info,tower_http=warn`).
pub fn init_logging() {
    use std::io::IsTerminal;
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
}

/// Serves until a stop signal, on a runtime of its own; the error says why it could not
/// start or went wrong.
pub fn run(args: ServeArgs) -> Result<(), ServeError> {
    let runtime = tokio::runtime::Runtime::new().map_err(ServeError::Runtime)?;
    let result = runtime.block_on(serve(args));
    // Whatever is still running (a blocking map build, a client that never closed) must not
    // hold the exit past the shutdown budget.
    runtime.shutdown_timeout(Duration::from_millis(200));
    result
}

/// From the signal to the end of `serve`: every client told and closed, or given up on.
/// The process must exit within 5 s of SIGTERM; this leaves room for the rest.
const SHUTDOWN_BUDGET: Duration = Duration::from_millis(4000);

async fn serve(args: ServeArgs) -> Result<(), ServeError> {
    // Before anything opens a file: every connection holds a descriptor.
    let open_files = crate::http::raise_open_files_limit();
    tracing::info!(?open_files, "open files limit");
    // Too few to serve stops the start here, before anything runs.
    let config = &args.config;
    crate::http::derive_caps(
        open_files,
        config.max_connections,
        config.max_tcp_per_address,
    )?;
    crate::http::trim_memory_periodically();
    let maps = MapStore::load_dir(&args.maps)?;
    tracing::info!(maps = maps.len(), dir = %args.maps.display(), "maps loaded");
    tracing::info!(config = ?args.config, "settings");
    let store = crate::store::Store::from_args(&args.history)?;
    tracing::info!(at = %crate::store::Store::describe(&args.history), "history opened");
    let history = crate::game::replay::History::with_store(store);
    let registry = Registry::with_history(maps, args.config, history);
    // The matches the last process left running come back first (requests for them get
    // 503 meanwhile; everything else is served at once), then the showcase, which carries
    // on with a resumed one.
    // The policies uploaded to this store, before the matches they drive come back.
    let restored = {
        let registry = registry.clone();
        tokio::task::spawn_blocking(move || crate::game::resume::restore_policies(&registry))
            .await
            .unwrap_or(0)
    };
    if restored > 0 {
        tracing::info!(policies = restored, "uploaded policies loaded");
    }
    let rooms = {
        let registry = registry.clone();
        tokio::task::spawn_blocking(move || crate::game::resume::restore_parties(&registry))
            .await
            .unwrap_or(0)
    };
    if rooms > 0 {
        tracing::info!(parties = rooms, "parties' rooms taken back");
    }
    {
        let left = crate::game::resume::left_running(&registry);
        let registry = registry.clone();
        let showcase = !args.no_showcase;
        tokio::spawn(async move {
            crate::game::resume::resume_all(registry.clone(), left).await;
            if showcase {
                crate::game::showcase::keep_running(registry).await;
            }
        });
    }
    let listener = tokio::net::TcpListener::bind(args.addr)
        .await
        .map_err(|source| ServeError::Listen {
            addr: args.addr,
            source,
        })?;
    let local = listener.local_addr().map_err(|source| ServeError::Listen {
        addr: args.addr,
        source,
    })?;
    // In a fleet, the directory task starts before the first request: it connects by
    // itself, and a Redis that is down only leaves this node alone in its listing.
    let fleet = args
        .fleet
        .settings(local)?
        .map(|(settings, client)| Fleet::start(settings, client, registry.clone()));
    if fleet.is_some() {
        // A fleet node's own store is not where another node would resume its matches: a
        // node that stops hands them over through a shared store, or else ends them.
        registry.end_matches_on_stop();
    }
    // On a shared store, the matches other servers can no longer run are taken over here.
    tokio::spawn(crate::game::resume::adopt_forever(registry.clone()));
    // The operator's certificate: HTTPS on the TCP port (read before anything is served, so
    // a bad file stops the start with its name).
    let tls = match (&args.tls_cert, &args.tls_key) {
        (Some(cert), Some(key)) => Some(crate::http::tls::acceptor(cert, key)?),
        _ => None,
    };
    let scheme = if tls.is_some() { "https" } else { "http" };
    tracing::info!("serving {scheme}://{local}");
    let (app, state) = crate::http::app_and_state(registry.clone(), args.web, fleet.clone());
    if !args.no_webtransport {
        let source = match (args.tls_cert, args.tls_key) {
            (Some(cert), Some(key)) => Source::Files { cert, key },
            _ => Source::SelfSigned,
        };
        // Beside the TCP listener, on the same address and port in UDP.
        crate::http::transport::start(state, local, source).await?;
    }
    let mut limits = crate::http::ConnectionLimits::of(&registry)?;
    limits.tls = tls;
    // Under Agones, Ready once listening; Health, the matches counter and Allocated after.
    #[cfg(feature = "agones")]
    let sidecar = crate::agones::Sidecar::from_env();
    #[cfg(feature = "agones")]
    if let Some(sidecar) = &sidecar {
        tokio::spawn(crate::agones::run(registry.clone(), sidecar.clone()));
    }
    let server = crate::http::serve(
        listener,
        app,
        limits,
        shutdown_signal(registry.clone(), fleet.clone()),
    );
    tokio::pin!(server);
    // Before a signal only an accept loop that failed ends the server. After one, the server
    // future may well be the branch that finishes first (it has no HTTP request left to wait
    // for), and returning then dropped every WebSocket task mid-close: clients got a bare
    // EOF instead of `finished` and their close frame (2 to 7 runs in 30).
    let served_early = tokio::select! {
        r = &mut server => Some(r),
        _ = registry.shutdown.cancelled() => None,
    };
    if !registry.shutdown.is_cancelled() {
        return served_early.unwrap_or(Ok(())).map_err(ServeError::Serve);
    }
    let deadline = tokio::time::Instant::now() + SHUTDOWN_BUDGET;
    // Every match has been told to end: leave the fleet's directory now, beside the rest
    // of the shutdown, so that other lobbies drop this node's matches at their next read.
    let leaving =
        fleet.map(|fleet| tokio::spawn(async move { fleet.leave(Duration::from_secs(2)).await }));
    // The listener is closed and every match told to stop: wait for the HTTP requests in
    // flight and for the WebSockets to send `finished` and close, within the budget.
    let drained = tokio::time::timeout_at(deadline, async {
        let served = match served_early {
            Some(r) => r,
            None => (&mut server).await,
        };
        registry.connections_closed().await;
        served
    })
    .await;
    // Every match has ended and sent its end to the history: wait for the writer to commit.
    let flushed = {
        let registry = registry.clone();
        tokio::task::spawn_blocking(move || match registry.history.store() {
            Some(store) => store.flush(Duration::from_millis(800)),
            None => Ok(()),
        })
        .await
    };
    if !matches!(flushed, Ok(Ok(()))) {
        tracing::warn!("the history's last writes may be lost");
    }
    if let Some(leaving) = leaving {
        let _ = tokio::time::timeout_at(deadline, leaving).await;
    }
    // Drained: hand the game server back to Agones.
    #[cfg(feature = "agones")]
    if let Some(sidecar) = &sidecar {
        match sidecar.shutdown().await {
            Ok(()) => tracing::info!("Agones: shutdown"),
            Err(e) => tracing::warn!(error = %e, "Agones: shutdown"),
        }
    }
    match drained {
        Ok(r) => {
            tracing::info!("shut down cleanly");
            r.map_err(ServeError::Serve)
        }
        Err(_) => {
            tracing::warn!(
                "shutdown budget of {SHUTDOWN_BUDGET:?} spent; exiting with connections open"
            );
            Ok(())
        }
    }
}

/// Resolves on Ctrl-C or SIGTERM, after the drain (`--drain-s`) and after telling every
/// match and connection to stop.
async fn shutdown_signal(registry: Arc<Registry>, fleet: Option<Arc<Fleet>>) {
    let mut signals = StopSignals::new();
    signals.next().await;
    let drain = registry.config.drain;
    // Marked draining at once (a fleet's directory hears of it now): no new match here.
    registry.begin_drain();
    if !drain.is_zero() && !registry.all_finished() {
        tracing::info!(
            ?drain,
            "draining: no new matches; the running ones go on until they end or the drain does"
        );
        let all_ended = async {
            while !registry.all_finished() {
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        };
        tokio::select! {
            () = all_ended => tracing::info!("drained: every match has ended"),
            () = tokio::time::sleep(drain) => tracing::info!("the drain is over"),
            () = signals.next() => tracing::info!("a second signal ends the drain"),
        }
    }
    tracing::info!("shutting down");
    // In a fleet on a shared store, the running matches go on on another node with room.
    let target = fleet
        .filter(|_| registry.history.store().is_some_and(|s| s.adopts()))
        .and_then(|f| f.hand_over_to());
    match target {
        Some((url, writer)) => {
            tracing::info!(to = %url, "handing the running matches over");
            registry.begin_shutdown_moving_to(&url).await;
            let store = registry.clone();
            let handed = tokio::task::spawn_blocking(move || {
                store
                    .history
                    .store()
                    .map(|s| s.hand_over(&writer, Duration::from_secs(2)))
            })
            .await;
            match handed {
                Ok(Some(Ok(ids))) => {
                    tracing::info!(matches = ids.len(), to = %url, "matches handed over")
                }
                _ => tracing::warn!(
                    "the matches could not be handed over; others take them once this node's lease runs out"
                ),
            }
        }
        None => registry.begin_shutdown().await,
    }
}

/// Ctrl-C and SIGTERM, as often as they come.
struct StopSignals {
    #[cfg(unix)]
    terminate: Option<tokio::signal::unix::Signal>,
}

impl StopSignals {
    fn new() -> StopSignals {
        StopSignals {
            #[cfg(unix)]
            terminate: tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
                .ok(),
        }
    }

    async fn next(&mut self) {
        let ctrl_c = async {
            let _ = tokio::signal::ctrl_c().await;
        };
        #[cfg(unix)]
        let terminate = async {
            match &mut self.terminate {
                Some(s) => {
                    s.recv().await;
                }
                None => std::future::pending::<()>().await,
            }
        };
        #[cfg(not(unix))]
        let terminate = std::future::pending::<()>();
        tokio::select! {
            _ = ctrl_c => {},
            _ = terminate => {},
        }
    }
}
