//! WebTransport beside the WebSocket: the same sockets (`/ws/matches/{id}`,
//! `/ws/replays/{id}`, the same query, tokens, fog, delays and budgets) over HTTP/3 sessions
//! on the server's port in UDP, so that a lost packet costs one snapshot and not a round trip
//! of everything behind it (docs/network.md).
//!
//! [`start`] binds the endpoint and runs its accept loop; each session's request goes
//! through the very handler a WebSocket upgrade does (`ws::upgrade`, `replay_ws::upgrade`),
//! which admits it (counted with its address's WebSockets) or refuses it with the status a
//! WebSocket would get; an admitted one is accepted and served by the same connection code,
//! over a [`Session`] instead of a WebSocket. `GET /api/transport` tells a page where to
//! connect and which certificate hash to pin ([`certificate`]).

pub mod certificate;
pub mod published;
pub mod seats;
pub mod session;

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::Json;
use axum::extract::{Query, State};
use axum::http::HeaderMap;
use serde::Serialize;
use wtransport::config::QuicTransportConfig;
use wtransport::endpoint::IncomingSession;
use wtransport::endpoint::endpoint_side::Server;
use wtransport::{Endpoint, ServerConfig};

use crate::http::error::ApiError;
use crate::http::socket::{Asked, Pending};
use crate::http::state::AppState;
use crate::http::{replay_ws, ws};
use crate::metrics::Refusal;
pub use certificate::{CertificateError, Source};
use published::Info;
pub use published::Published;
use session::Refusable;

/// How long a client has to finish its QUIC handshake and send its session's request.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);
/// Handshakes in progress at once, in all and from one address: beyond them new ones are
/// refused before any work is done for them.
const HANDSHAKES: usize = 256;
const HANDSHAKES_PER_ADDRESS: usize = 8;
/// A session with nothing heard for this long is over (the page pings every second).
const IDLE_TIMEOUT: Duration = Duration::from_secs(15);

#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    #[error(transparent)]
    Certificate(#[from] CertificateError),
    #[error("WebTransport cannot listen on udp {at}: {error}")]
    Bind { at: SocketAddr, error: String },
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct TransportReply {
    /// Where a WebTransport session opens, and the certificate hash to pin (`null` when the
    /// server does not offer WebTransport).
    webtransport: Option<WebTransportAt>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct WebTransportAt {
    /// `https://host:port`, the host as the request named this server.
    url: String,
    /// For browsers' `serverCertificateHashes`: empty when the certificate is the operator's
    /// (trusted as any HTTPS one).
    certificate_hashes: Vec<CertificateHash>,
}

#[derive(Serialize, utoipa::ToSchema)]
pub struct CertificateHash {
    /// Always `sha-256`.
    algorithm: &'static str,
    /// The hash of the certificate's DER, in lowercase hex.
    value: String,
}

/// `GET /api/transport`: where the page opens a WebTransport session, if anywhere.
#[utoipa::path(get, path = "/api/transport",
    responses((status = 200, body = TransportReply,
        description = "Where a WebTransport session opens (the sockets' paths and queries, over HTTP/3) and the certificate hash a browser pins; `webtransport` is null when the server does not offer it")))]
pub async fn transport(State(state): State<AppState>, headers: HeaderMap) -> Json<TransportReply> {
    let webtransport = state.transport.get().map(|info| {
        let host = headers
            .get(axum::http::header::HOST)
            .and_then(|h| h.to_str().ok())
            .map_or("127.0.0.1", host_of);
        WebTransportAt {
            url: format!("https://{host}:{}", info.port),
            certificate_hashes: info
                .hash
                .into_iter()
                .map(|value| CertificateHash {
                    algorithm: "sha-256",
                    value,
                })
                .collect(),
        }
    });
    Json(TransportReply { webtransport })
}

/// The host part of a `Host` header (`name:port`, `[v6]:port`, or a bare name).
fn host_of(header: &str) -> &str {
    if header.starts_with('[') {
        return header.split_inclusive(']').next().unwrap_or(header);
    }
    header.rsplit_once(':').map_or(header, |(host, _)| host)
}

/// QUIC's settings for the server's sessions: few streams (the session's own, HTTP/3's
/// three and the client's one), small buffers, an idle time-out, and BBR for congestion
/// control: CUBIC halves its window at each loss, and at a snapshot stream's trickle the
/// window sat at its floor with datagrams queued behind it (15 stalls a minute at 150 ms and
/// 2% loss, none with BBR: docs/network.md).
fn quic_transport() -> QuicTransportConfig {
    use wtransport::quinn::VarInt;
    let mut t = QuicTransportConfig::default();
    t.max_concurrent_bidi_streams(VarInt::from_u32(4))
        .max_concurrent_uni_streams(VarInt::from_u32(8))
        .stream_receive_window(VarInt::from_u32(256 << 10))
        .receive_window(VarInt::from_u32(1 << 20))
        .send_window(4 << 20)
        .datagram_receive_buffer_size(Some(64 << 10))
        .datagram_send_buffer_size(256 << 10)
        .keep_alive_interval(Some(Duration::from_secs(5)))
        .congestion_controller_factory(Arc::new(
            wtransport::quinn::congestion::BbrConfig::default(),
        ));
    if let Ok(idle) = IDLE_TIMEOUT.try_into() {
        t.max_idle_timeout(Some(idle));
    }
    t
}

fn server_config(at: SocketAddr, cert: certificate::Certificate) -> ServerConfig {
    ServerConfig::builder()
        .with_bind_address(at)
        .with_custom_transport(cert.identity, quic_transport())
        .build()
}

/// Serves WebTransport on `at` (UDP) until the server stops: binds, publishes where, accepts
/// sessions, and renews the server's own certificate.
pub async fn start(state: AppState, at: SocketAddr, source: Source) -> Result<(), TransportError> {
    let cert = source.load().await?;
    let hash = cert.pinned.then(|| cert.hash.clone());
    let endpoint = Endpoint::server(server_config(at, cert)).map_err(|e| TransportError::Bind {
        at,
        error: e.to_string(),
    })?;
    let port = endpoint.local_addr().map_or(at.port(), |a| a.port());
    state.transport.set(Info { port, hash });
    tracing::info!(port, "serving WebTransport (udp)");
    let endpoint = Arc::new(endpoint);
    if source.renews() {
        tokio::spawn(renew(state.clone(), endpoint.clone(), at, source, port));
    }
    tokio::spawn(accept_loop(state, endpoint));
    Ok(())
}

/// Replaces the server's own certificate every [`certificate::RENEW_EVERY`]: new sessions
/// get the new one, open ones keep theirs.
async fn renew(
    state: AppState,
    endpoint: Arc<Endpoint<Server>>,
    at: SocketAddr,
    source: Source,
    port: u16,
) {
    let shutdown = state.registry.shutdown.clone();
    loop {
        tokio::select! {
            () = tokio::time::sleep(certificate::RENEW_EVERY) => {}
            () = shutdown.cancelled() => return,
        }
        match source.load().await {
            Ok(cert) => {
                let hash = Some(cert.hash.clone());
                match endpoint.reload_config(server_config(at, cert), false) {
                    Ok(()) => {
                        state.transport.set(Info { port, hash });
                        tracing::info!("WebTransport certificate renewed");
                    }
                    Err(e) => tracing::warn!(error = %e, "WebTransport certificate not renewed"),
                }
            }
            Err(e) => tracing::warn!(error = %e, "WebTransport certificate not renewed"),
        }
    }
}

async fn accept_loop(state: AppState, endpoint: Arc<Endpoint<Server>>) {
    let shutdown = state.registry.shutdown.clone();
    let pending = Arc::new(Handshakes::default());
    loop {
        // The endpoint must not be asked for more after it is closed.
        let incoming = tokio::select! {
            i = endpoint.accept() => i,
            () = shutdown.cancelled() => break,
        };
        let ip = incoming.remote_address().ip().to_canonical();
        // Past the sessions the server is sized for and the handshakes that may be in
        // progress, refused at once: the page's session fails within a round trip and it
        // plays over its WebSocket. Below it, whether a session gets a place is decided once
        // its request says who it is for (`seats`: players first).
        if endpoint.open_connections()
            >= state.registry.config.max_webtransport_sessions + HANDSHAKES
        {
            state.registry.metrics.refuse(Refusal::WebTransportFull);
            incoming.refuse();
            continue;
        }
        let Some(slot) = pending.open(ip) else {
            incoming.refuse();
            continue;
        };
        let state = state.clone();
        tokio::spawn(async move {
            let _slot = slot;
            handshake(state, incoming, ip).await;
        });
    }
    // Sessions end with their sockets, which watch the shutdown too.
    tokio::time::sleep(Duration::from_secs(2)).await;
    endpoint.close(
        wtransport::VarInt::from_u32(0),
        b"the server is shutting down",
    );
}

/// A session's handshake and request, routed as a WebSocket's upgrade would be.
async fn handshake(state: AppState, incoming: IncomingSession, ip: IpAddr) {
    let Ok(Ok(request)) = tokio::time::timeout(HANDSHAKE_TIMEOUT, incoming).await else {
        return;
    };
    // The path and query as the WebSocket's extractors read them: a query that is no query
    // is refused, as axum's `Query` refuses it.
    let Ok(uri) = request.path().parse::<axum::http::Uri>() else {
        return request.forbidden().await;
    };
    let Ok(Query(query)) = Query::<HashMap<String, String>>::try_from_uri(&uri) else {
        return request.forbidden().await;
    };
    let route = uri.path();
    let (kind, id) = match route.trim_start_matches('/').split_once('/') {
        Some(("ws", rest)) => match rest.split_once('/') {
            Some((kind, id)) if !id.is_empty() && !id.contains('/') => (kind, id),
            _ => return request.not_found().await,
        },
        _ => return request.not_found().await,
    };
    let Ok(id) = percent_encoding::percent_decode_str(id).decode_utf8() else {
        return request.not_found().await;
    };
    let (kind, id) = (kind.to_string(), id.into_owned());
    let refusable = Refusable::new(request);
    let asked = Asked {
        id,
        query,
        ip,
        ws: Pending::WebTransport(refusable.clone()),
    };
    let answer = match kind.as_str() {
        "matches" => ws::upgrade(State(state), asked).await,
        "replays" => replay_ws::upgrade(State(state), asked).await,
        _ => Err(ApiError::not_found(format!("no socket at {}", uri.path()))),
    };
    if let Err(e) = answer {
        tracing::debug!(%ip, status = %e.status, error = %e.message, "WebTransport session refused");
        refusable.refuse(e.status).await;
    }
}

/// Handshakes in progress, in all and by address.
#[derive(Default)]
struct Handshakes(Mutex<HashMap<IpAddr, usize>>);

struct HandshakeSlot(Arc<Handshakes>, IpAddr);

impl Handshakes {
    fn open(self: &Arc<Self>, ip: IpAddr) -> Option<HandshakeSlot> {
        let mut map = self.0.lock().ok()?;
        let all: usize = map.values().sum();
        let mine = map.entry(ip).or_default();
        if all >= HANDSHAKES || *mine >= HANDSHAKES_PER_ADDRESS {
            return None;
        }
        *mine += 1;
        Some(HandshakeSlot(self.clone(), ip))
    }
}

impl Drop for HandshakeSlot {
    fn drop(&mut self) {
        if let Ok(mut map) = self.0.0.lock()
            && let Some(n) = map.get_mut(&self.1)
        {
            *n -= 1;
            if *n == 0 {
                map.remove(&self.1);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hosts_are_read_as_a_browser_sends_them() {
        assert_eq!(host_of("127.0.0.1:8080"), "127.0.0.1");
        assert_eq!(host_of("example.org"), "example.org");
        assert_eq!(host_of("[::1]:8080"), "[::1]");
    }

    #[test]
    fn handshakes_are_capped_per_address() {
        let h = Arc::new(Handshakes::default());
        let ip: IpAddr = "10.0.0.1".parse().unwrap();
        let held: Vec<_> = (0..HANDSHAKES_PER_ADDRESS)
            .map(|_| h.open(ip).expect("room"))
            .collect();
        assert!(h.open(ip).is_none());
        assert!(h.open("10.0.0.2".parse().unwrap()).is_some());
        drop(held);
        assert!(h.open(ip).is_some());
    }
}
