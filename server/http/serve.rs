//! The accept loop: our own rather than `axum::serve`, for what a public server needs and
//! that one does not set.
//!
//! - A cap on open connections (WebSockets included: the count is held by the socket
//!   itself, so it outlives the HTTP upgrade). At the cap the loop stops accepting and new
//!   clients wait in the kernel's backlog, as mini-redis does, rather than being accepted
//!   only to be dropped.
//! - A cap on open connections per client (an IPv4 address or an IPv6 /64): one over it is
//!   closed as soon as it is accepted, before hyper sees a byte, and counted
//!   (`lasertag_refused_total{reason="tcp_per_address"}`). Accepting it costs a moment of
//!   one file descriptor; leaving it in the backlog would let one client keep every other
//!   one waiting behind it. The per-client cap sits well below the server's, so others find
//!   room (`/api/health` keeps answering while one address floods).
//! - The server's cap never exceeds the file descriptors the process may open, less a
//!   reserve for its files, database and match runtimes, so `accept` never runs out of them,
//!   and a client's default cap is a small share of the server's; a cap the operator gives
//!   is used as given, within what the files hold ([`derive_caps`]);
//!   [`raise_open_files_limit`] lifts the soft limit to the hard one at start, and a limit
//!   too low to serve stops the start with an error that says so ([`TooFewFiles`]).
//! - [`trim_memory_periodically`] hands freed memory back to the operating system, every 5 s
//!   and only then.
//! - A header read timeout: a connection that starts a request and does not finish its
//!   header in time, or sits idle between keep-alive requests that long, is closed. Without
//!   it a client sending half a header held its socket forever.
//! - HTTPS when the operator gives a certificate ([`super::tls`]): each connection's TLS
//!   handshake runs in its own task, within the header read timeout.
//! - Graceful shutdown like `axum::serve`'s: stop accepting, let every connection finish
//!   its request, then return.
//!
//! Each request carries the peer's `ConnectInfo<SocketAddr>`, as with
//! `into_make_service_with_connect_info`.

use std::collections::HashMap;
use std::net::IpAddr;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::Router;
use axum::body::Body;
use axum::extract::ConnectInfo;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, watch};
use tower::ServiceExt;

use crate::access::ClientKey;
use crate::game::Registry;
use crate::metrics::Refusal;

/// File descriptors kept out of the connection cap: the store's files, logs, maps and the
/// runtimes of real-time matches need some too. A quarter of a small limit.
const FD_RESERVE: u64 = 512;
/// Fewest connections a server may start with: a handful of players, their spectators and
/// the lobby's requests. Below it one client would take it down.
pub const MIN_CONNECTIONS: usize = 64;
/// Clients that always find room: the per-client cap is at most the server's cap divided
/// by this.
const CLIENTS_WITH_ROOM: usize = 16;

/// What the accept loop enforces.
#[derive(Clone)]
pub struct ConnectionLimits {
    /// Connections open at once, WebSockets included.
    pub max_connections: usize,
    /// Connections open at once from one client.
    pub max_per_address: usize,
    /// Time to send a request's header, and most time idle between requests.
    pub header_read_timeout: Duration,
    /// Where refused connections are counted.
    pub registry: Option<Arc<Registry>>,
    /// HTTPS: the TLS each connection starts with; `None`, plain HTTP.
    pub tls: Option<tokio_rustls::TlsAcceptor>,
}

/// The open files limit leaves too few connections to serve: the server does not start.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "the open files limit ({files}) leaves room for {room} connections once {reserve} are kept for files and matches; a server needs at least {MIN_CONNECTIONS}: raise the hard limit (`ulimit -Hn`, systemd's LimitNOFILE=, docker's --ulimit nofile=)"
)]
pub struct TooFewFiles {
    pub files: u64,
    pub room: u64,
    pub reserve: u64,
}

impl ConnectionLimits {
    /// The limits of `registry`'s config under the file descriptors the process may open
    /// (see [`derive_caps`]). A cap the operator gave that the files cannot hold is lowered
    /// to what they can, with one warning naming the flag, what was asked and what was
    /// granted; defaults derived from the files are logged as information.
    pub fn of(registry: &Arc<Registry>) -> Result<ConnectionLimits, TooFewFiles> {
        let config = &registry.config;
        let files = open_files_limit();
        let caps = derive_caps(files, config.max_connections, config.max_tcp_per_address)?;
        for (flag, asked, granted) in [
            (
                "--max-connections",
                config.max_connections,
                caps.max_connections,
            ),
            (
                "--max-tcp-per-address",
                config.max_tcp_per_address,
                caps.max_per_address,
            ),
        ] {
            if let Some(asked) = asked
                && granted < asked
            {
                tracing::warn!(
                    flag,
                    asked,
                    granted,
                    open_files = files,
                    "the open files limit cannot hold the connections asked: granted fewer (raise the hard limit: `ulimit -Hn`, systemd's LimitNOFILE=, docker's --ulimit nofile=)"
                );
            }
        }
        tracing::info!(
            max_connections = caps.max_connections,
            max_per_address = caps.max_per_address,
            open_files = files,
            "connection caps"
        );
        Ok(ConnectionLimits {
            max_connections: caps.max_connections,
            max_per_address: caps.max_per_address,
            header_read_timeout: config.header_read_timeout,
            registry: Some(registry.clone()),
            tls: None,
        })
    }
}

/// The connection caps the accept loop enforces, as [`derive_caps`] grants them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Caps {
    /// Connections open at once.
    pub max_connections: usize,
    /// Connections open at once from one client.
    pub max_per_address: usize,
}

/// The server's and each client's connection caps under an open files limit of `files`
/// (none: no limit), from the caps the operator asked for (`None`: the default).
///
/// What the files leave is the limit less a reserve (a quarter of it, at most
/// [`FD_RESERVE`]); too little to serve [`MIN_CONNECTIONS`] is an error. A cap the operator
/// gave is used as given, clamped only to what the files leave: it is theirs, whatever it
/// does to other clients. The defaults are derived: the server's
/// [`MAX_CONNECTIONS`](crate::config::defaults::MAX_CONNECTIONS) within what the files
/// leave, and each client's
/// [`MAX_TCP_PER_ADDRESS`](crate::config::defaults::MAX_TCP_PER_ADDRESS) within a
/// [`CLIENTS_WITH_ROOM`]th of that, so that by default one client never takes what the
/// files leave. (A `--max-connections` below the files' room lowers no client's cap.)
pub fn derive_caps(
    files: Option<u64>,
    max_connections: Option<usize>,
    max_per_address: Option<usize>,
) -> Result<Caps, TooFewFiles> {
    use crate::config::defaults::{MAX_CONNECTIONS, MAX_TCP_PER_ADDRESS};
    let room = match files {
        None => usize::MAX,
        Some(files) => {
            let reserve = (files / 4).min(FD_RESERVE);
            let room = files - reserve;
            if room < MIN_CONNECTIONS as u64 {
                return Err(TooFewFiles {
                    files,
                    room,
                    reserve,
                });
            }
            usize::try_from(room).unwrap_or(usize::MAX)
        }
    };
    Ok(Caps {
        max_connections: max_connections.unwrap_or(MAX_CONNECTIONS).min(room),
        max_per_address: match max_per_address {
            Some(asked) => asked.min(room),
            None => MAX_TCP_PER_ADDRESS.min(room / CLIENTS_WITH_ROOM),
        },
    })
}

/// The soft limit of open files (`RLIMIT_NOFILE`), where the platform has one.
#[cfg(unix)]
// `rlim_t` is `u64` on Linux, not on every unix.
#[allow(clippy::unnecessary_cast)]
fn open_files_limit() -> Option<u64> {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit writes one `rlimit` through a valid pointer to a local.
    let ok = unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) } == 0;
    (ok && lim.rlim_cur != libc::RLIM_INFINITY).then_some(lim.rlim_cur as u64)
}

#[cfg(not(unix))]
fn open_files_limit() -> Option<u64> {
    None
}

/// Raises the soft limit of open files to the hard one (a process may, without
/// privileges): the soft default, often 1024, is what a flood of half-sent requests
/// exhausted. Answers the soft limit in force afterwards.
#[cfg(unix)]
pub fn raise_open_files_limit() -> Option<u64> {
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit and setrlimit read and write one `rlimit`, a local.
    unsafe {
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) != 0 {
            return None;
        }
        if lim.rlim_cur < lim.rlim_max {
            let raised = libc::rlimit {
                rlim_cur: lim.rlim_max,
                rlim_max: lim.rlim_max,
            };
            if libc::setrlimit(libc::RLIMIT_NOFILE, &raised) != 0 {
                tracing::warn!(
                    soft = lim.rlim_cur,
                    hard = lim.rlim_max,
                    "could not raise the open files limit"
                );
            }
        }
    }
    open_files_limit()
}

#[cfg(not(unix))]
pub fn raise_open_files_limit() -> Option<u64> {
    None
}

/// How often freed memory is handed back to the operating system.
const TRIM_EVERY: Duration = Duration::from_secs(5);

/// Largest block the allocator takes from its own heaps rather than mapping it alone, and
/// the free space at a heap's top it keeps rather than handing back at once (bytes).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const KEEP_FREED_BYTES: libc::c_int = 32 << 20;

/// Hands the memory the allocator keeps free back to the operating system every
/// [`TRIM_EVERY`], off the async workers, and only then. glibc's allocator keeps what a
/// large request, an ended match or an evicted replay freed (the process's resident size
/// stays at its peak); `malloc_trim` returns it, so the server's size follows what it holds.
///
/// Left to itself, glibc also hands a thread heap's free top back on every `free` past
/// 128 KiB (`madvise`), and maps blocks past its threshold alone: the planner's distance
/// fields (a few hundred KiB each, several per tick and match) were then returned and
/// faulted back in zeroed pages every time, and each return interrupts every other core
/// (a TLB shootdown): a fifth of all CPU at 100 matches (docs/performance.md). So freed
/// blocks stay in the heaps until the next trim. Does nothing with other allocators.
pub fn trim_memory_periodically() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only sets the allocator's thresholds; called before the work it tunes.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, KEEP_FREED_BYTES);
        libc::mallopt(libc::M_TRIM_THRESHOLD, KEEP_FREED_BYTES);
    }
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    tokio::spawn(async {
        let mut every = tokio::time::interval(TRIM_EVERY);
        every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            every.tick().await;
            // SAFETY: malloc_trim takes a padding size and touches only the allocator's
            // own free lists.
            let _ = tokio::task::spawn_blocking(|| unsafe { libc::malloc_trim(0) }).await;
        }
    });
}

/// Open connections per client, and the guard that counts one.
#[derive(Debug, Default)]
struct PerAddress(Mutex<HashMap<ClientKey, usize>>);

impl PerAddress {
    fn open(self: &Arc<Self>, ip: IpAddr, max: usize) -> Option<AddressSlot> {
        let client = ClientKey::of(ip);
        let mut map = self.0.lock().unwrap_or_else(|e| e.into_inner());
        let n = map.entry(client).or_default();
        if *n >= max {
            return None;
        }
        *n += 1;
        Some(AddressSlot {
            counts: self.clone(),
            client,
        })
    }
}

/// One open connection of a client; uncounted when dropped (the entry goes at zero, so
/// the map holds only clients with connections).
#[derive(Debug)]
struct AddressSlot {
    counts: Arc<PerAddress>,
    client: ClientKey,
}

impl Drop for AddressSlot {
    fn drop(&mut self) {
        let mut map = self.counts.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(n) = map.get_mut(&self.client) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                map.remove(&self.client);
            }
        }
    }
}

/// Serves `app` on `listener` until `shutdown` resolves, then waits for the connections
/// to finish their requests (upgraded WebSockets are not waited for: their own tasks watch
/// the registry's shutdown).
pub async fn serve(
    listener: TcpListener,
    app: Router,
    limits: ConnectionLimits,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    serve_until(listener, app, limits, Box::pin(shutdown)).await
}

/// [`serve`] with its signal boxed: not generic, so the accept loop and hyper's connection
/// machinery under it (for plain and TLS streams) are compiled once, in this library, and
/// not again in every crate that serves (the binary's last step of a clean build).
async fn serve_until(
    listener: TcpListener,
    app: Router,
    limits: ConnectionLimits,
    mut shutdown: Pin<Box<dyn Future<Output = ()> + Send>>,
) -> std::io::Result<()> {
    let permits = Arc::new(Semaphore::new(limits.max_connections));
    let per_address = Arc::<PerAddress>::default();
    // Dropped to tell connections to shut down gracefully; `closed_rx` counts them.
    let (signal_tx, signal_rx) = watch::channel(());
    let (closed_tx, closed_rx) = watch::channel(());
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_read_timeout);
    loop {
        let permit = tokio::select! {
            permit = permits.clone().acquire_owned() => match permit {
                Ok(p) => p,
                Err(_) => break, // never closed
            },
            () = &mut shutdown => break,
        };
        let (stream, peer) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(a) => a,
                Err(e) => {
                    accept_error(e).await;
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        let Some(slot) = per_address.open(peer.ip(), limits.max_per_address) else {
            // Over its client's cap: closed at once, its permit back for someone else.
            drop(stream);
            if let Some(registry) = &limits.registry {
                registry.metrics.refuse(Refusal::TcpPerAddress);
            }
            continue;
        };
        let _ = stream.set_nodelay(true);
        let service = app
            .clone()
            .map_request(move |mut req: hyper::Request<Incoming>| {
                req.extensions_mut().insert(ConnectInfo(peer));
                req.map(Body::new)
            });
        let counted = Counted {
            stream,
            _permit: permit,
            _slot: slot,
        };
        let (builder, signal, closed) = (builder.clone(), signal_rx.clone(), closed_rx.clone());
        let service = TowerToHyperService::new(service);
        match limits.tls.clone() {
            None => {
                tokio::spawn(drive(counted, builder, service, signal, closed, peer));
            }
            Some(tls) => {
                let handshake_time = limits.header_read_timeout;
                tokio::spawn(async move {
                    match tokio::time::timeout(handshake_time, tls.accept(counted)).await {
                        Ok(Ok(stream)) => {
                            drive(stream, builder, service, signal, closed, peer).await
                        }
                        Ok(Err(e)) => tracing::debug!(%peer, "TLS handshake failed: {e}"),
                        Err(_) => tracing::debug!(%peer, "TLS handshake timed out"),
                    }
                });
            }
        }
    }
    drop(listener);
    drop(signal_tx);
    drop(closed_rx);
    closed_tx.closed().await;
    Ok(())
}

/// Serves one connection (`io`, after TLS if any) until it ends, shutting it down gracefully
/// when `signal` changes; `closed` is held until then (the loop waits for every one).
async fn drive<S, T>(
    io: S,
    builder: hyper::server::conn::http1::Builder,
    service: T,
    mut signal: watch::Receiver<()>,
    closed: watch::Receiver<()>,
    peer: std::net::SocketAddr,
) where
    S: AsyncRead + AsyncWrite + Unpin + Send + 'static,
    T: hyper::service::Service<hyper::Request<Incoming>, Response = axum::response::Response>
        + Send
        + 'static,
    T::Future: Send + 'static,
    T::Error: std::error::Error + Send + Sync + 'static,
{
    let conn = builder
        .serve_connection(TokioIo::new(io), service)
        .with_upgrades();
    tokio::pin!(conn);
    loop {
        tokio::select! {
            result = conn.as_mut() => {
                if let Err(e) = result {
                    tracing::debug!(%peer, "connection ended: {e}");
                }
                break;
            }
            _ = signal.changed() => {
                conn.as_mut().graceful_shutdown();
            }
        }
    }
    drop(closed);
}

/// Errors of `accept` that concern one connection (reset before it was taken) are skipped;
/// the rest (out of file descriptors) are waited out, as `axum::serve` does.
async fn accept_error(e: std::io::Error) {
    use std::io::ErrorKind::*;
    if matches!(
        e.kind(),
        ConnectionRefused | ConnectionAborted | ConnectionReset
    ) {
        return;
    }
    tracing::error!("accept failed: {e}; retrying in 1 s");
    tokio::time::sleep(Duration::from_secs(1)).await;
}

/// A TCP stream that holds one of the connection permits, and its client's count, for as
/// long as it is open.
struct Counted {
    stream: TcpStream,
    _permit: OwnedSemaphorePermit,
    _slot: AddressSlot,
}

impl AsyncRead for Counted {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_read(cx, buf)
    }
}

impl AsyncWrite for Counted {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.stream).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.stream).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.stream.is_write_vectored()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn caps(max_connections: usize, max_per_address: usize) -> Caps {
        Caps {
            max_connections,
            max_per_address,
        }
    }

    #[test]
    fn a_generous_limit_keeps_the_defaults_and_what_was_asked() {
        assert_eq!(derive_caps(Some(1 << 20), None, None), Ok(caps(4096, 256)));
        assert_eq!(derive_caps(None, None, None), Ok(caps(4096, 256)));
        assert_eq!(
            derive_caps(Some(1 << 20), Some(10_000), Some(5_000)),
            Ok(caps(10_000, 5_000))
        );
        assert_eq!(
            derive_caps(None, Some(usize::MAX), Some(usize::MAX)),
            Ok(caps(usize::MAX, usize::MAX))
        );
    }

    #[test]
    fn a_small_limit_lowers_the_defaults_so_one_client_cannot_take_the_room() {
        // 256 files: 64 kept, 192 connections, 12 per client: 16 clients find room.
        assert_eq!(derive_caps(Some(256), None, None), Ok(caps(192, 12)));
        // 1024 files (a common soft default): 768 connections, 48 per client.
        assert_eq!(derive_caps(Some(1024), None, None), Ok(caps(768, 48)));
        // 20,000 files: the default 256 per client is below a sixteenth (1,218).
        assert_eq!(derive_caps(Some(20_000), None, None), Ok(caps(4096, 256)));
    }

    #[test]
    fn an_explicit_cap_is_granted_up_to_what_the_files_hold_and_no_sixteenth() {
        // The operator's load test from one address: all of it, not a sixteenth (1,218).
        assert_eq!(
            derive_caps(Some(20_000), Some(1_000_000), Some(1_000_000)),
            Ok(caps(19_488, 19_488))
        );
        assert_eq!(
            derive_caps(Some(20_000), None, Some(3_000)),
            Ok(caps(4096, 3_000))
        );
        // Below what the files leave, an explicit cap is used as given, even a tiny one.
        assert_eq!(
            derive_caps(Some(1024), Some(100), Some(1)),
            Ok(caps(100, 1))
        );
        assert_eq!(derive_caps(Some(1024), None, Some(700)), Ok(caps(768, 700)));
    }

    #[test]
    fn too_few_files_to_serve_is_an_error_naming_the_limit() {
        let e = derive_caps(Some(64), Some(4096), None).unwrap_err();
        assert_eq!(e.files, 64);
        assert!(e.to_string().contains("open files limit (64)"), "{e}");
        assert!(e.to_string().contains("ulimit"), "{e}");
    }
}
