//! What every socket of the server does alike (`ws`: a live match, `replay_ws`: a replay),
//! over either carrier (a WebSocket, or a WebTransport session: [`Carrier`]): the checks
//! before the upgrade that are not about what is shown, the counts a connection holds while
//! it is open, and a [`Socket`] that sends with a time-out, caps, rate-limits and parses what
//! the client sends (every bad message gets an `error`; a client that keeps sending them is
//! closed, close code 1008), and closes with a code and a reason.
//!
//! Each socket's loop is its own (what it waits on differs); it reads with [`Socket::recv`],
//! which is cancel-safe in a `select!`, and hands what came to [`Socket::read`].

mod end;
pub mod schedule;

pub use end::End;
use end::TOO_BIG;

use std::collections::HashMap;
use std::future::Future;
use std::net::IpAddr;
use std::time::Duration;

use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::{CloseFrame, Message, Utf8Bytes, WebSocket, WebSocketUpgrade};
use axum::extract::{FromRequestParts, Path, Query};
use axum::http::StatusCode;
use axum::http::request::Parts;
use axum::response::{IntoResponse, Response};
use tokio_util::sync::CancellationToken;
use tracing::Instrument;

use crate::http::transport::seats;
use crate::http::transport::session::{Refusable, Session};

use crate::game::{ConnectionGuard, Registry};
use crate::http::error::ApiError;
use crate::http::limits::{AddressConnection, Bucket, ClientIp};
use crate::http::state::AppState;
use crate::metrics::{ClientGuard, Metrics, Refusal};
use crate::protocol::Invalid;

/// Bad messages tolerated in a row before the connection is closed...
pub const STRIKES: f64 = 10.0;
/// ...recovering one strike every this many seconds.
pub const STRIKE_RECOVERY_S: f64 = 5.0;
/// A client that cannot take a message within this time is dropped.
pub const SEND_TIMEOUT: Duration = Duration::from_secs(10);

/// How long a closing connection waits for the client's close reply when the server is
/// shutting down (it has 5 s in all).
const SHUTDOWN_DRAIN: Duration = Duration::from_secs(1);
/// Close reasons are cut to this many bytes: they must fit a control frame (123 bytes).
const REASON_BYTES: usize = 120;

/// What a socket's upgrade request brings: the id in its path, its query, the client's
/// address, and the upgrade itself (or why it is none, refused by [`admit`] after the
/// socket's own checks).
pub struct Asked {
    pub id: String,
    pub query: HashMap<String, String>,
    pub ip: IpAddr,
    pub ws: Pending,
}

/// The carrier a socket is asked over, before it is admitted.
pub enum Pending {
    /// A WebSocket upgrade (or why the request is none).
    WebSocket(Result<WebSocketUpgrade, WebSocketUpgradeRejection>),
    /// A WebTransport session's request (`http::transport`), which refuses it with the
    /// error's status when the socket is not admitted.
    WebTransport(Refusable),
}

/// The carrier of an admitted socket.
pub enum Carrier {
    WebSocket(Box<WebSocket>),
    WebTransport(Box<Session>),
}

impl FromRequestParts<AppState> for Asked {
    type Rejection = Response;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, Response> {
        let Path(id) = Path::<String>::from_request_parts(parts, state)
            .await
            .map_err(IntoResponse::into_response)?;
        let Query(query) = Query::<HashMap<String, String>>::from_request_parts(parts, state)
            .await
            .map_err(IntoResponse::into_response)?;
        let ClientIp(ip) = ClientIp::from_request_parts(parts, state)
            .await
            .unwrap_or_else(|never| match never {});
        let ws = Pending::WebSocket(WebSocketUpgrade::from_request_parts(parts, state).await);
        Ok(Asked { id, query, ip, ws })
    }
}

/// 503 while the server shuts down: no socket opens then.
pub fn refuse_while_stopping(registry: &Registry) -> Result<(), ApiError> {
    if registry.shutdown.is_cancelled() {
        return Err(ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "the server is shutting down",
        ));
    }
    Ok(())
}

/// `?token=`, which a socket that is one person's own needs (a party member's, a queue
/// ticket's): 401 naming `what` without it.
pub fn token_param<'a>(
    query: &'a HashMap<String, String>,
    what: &str,
) -> Result<&'a str, ApiError> {
    query.get("token").map(String::as_str).ok_or_else(|| {
        ApiError::new(
            StatusCode::UNAUTHORIZED,
            format!("token: {what} needs ?token=<token>"),
        )
    })
}

/// 400 for a query parameter the socket does not take; `names` are those it takes.
pub fn only_params(query: &HashMap<String, String>, names: &[&str]) -> Result<(), ApiError> {
    match query.keys().find(|k| !names.contains(&k.as_str())) {
        Some(k) => Err(ApiError::bad_request(format!(
            "{k}: unknown query parameter ({})",
            names.join(", ")
        ))),
        None => Ok(()),
    }
}

/// `?format=`: whether snapshots go as compact binary messages (else JSON text).
pub fn compact_format(query: &HashMap<String, String>) -> Result<bool, ApiError> {
    match query.get("format").map(String::as_str) {
        None | Some("json") => Ok(false),
        Some("compact") => Ok(true),
        Some(other) => Err(ApiError::bad_request(format!(
            "format: {other:?} is not a snapshot format (json or compact)"
        ))),
    }
}

/// An upgrade request that is a socket's, counted against its address's open sockets.
pub struct Admitted {
    ws: Ready,
    address: AddressConnection,
}

enum Ready {
    WebSocket(WebSocketUpgrade),
    WebTransport(Refusable),
}

/// 400 for a request that is no WebSocket upgrade, 429 for an address with all the sockets
/// it may have open (WebSockets and WebTransport sessions counted together).
pub fn admit(state: &AppState, ip: IpAddr, ws: Pending) -> Result<Admitted, ApiError> {
    let ws = match ws {
        Pending::WebSocket(ws) => Ready::WebSocket(
            ws.map_err(|e| ApiError::bad_request(format!("not a WebSocket upgrade: {e}")))?,
        ),
        Pending::WebTransport(request) => Ready::WebTransport(request),
    };
    let registry = &state.registry;
    let max = registry.config.max_connections_per_address;
    let Some(address) = state.limits.open_connection(ip, max) else {
        registry.metrics.refuse(Refusal::ConnectionsPerAddress);
        return Err(ApiError::new(
            StatusCode::TOO_MANY_REQUESTS,
            format!(
                "too many connections from {ip}: at most {max} WebSockets and WebTransport sessions open at once per address"
            ),
        ));
    };
    Ok(Admitted { ws, address })
}

/// What differs between the sockets' [`Socket`]s.
pub struct Manner {
    /// The metrics' label for the connection (`player`, `spectator`, `replay`).
    pub role: &'static str,
    /// How long a closing connection waits for the client's close reply.
    pub close_drain: Duration,
    /// The `error` message a bad message is answered with.
    pub error: fn(&str) -> Utf8Bytes,
}

impl Admitted {
    /// Upgrades, with messages capped at the hard size, and serves the connection with
    /// `serve` in its own task, inside `span`. A WebTransport session is accepted in that
    /// task (the response is then only the handler's: nobody reads it).
    pub fn open<F, Fut>(
        self,
        state: &AppState,
        manner: Manner,
        span: tracing::Span,
        serve: F,
    ) -> Response
    where
        F: FnOnce(Socket) -> Fut + Send + 'static,
        Fut: Future<Output = ()> + Send + 'static,
    {
        let registry = state.registry.clone();
        let hard = registry.config.hard_message_bytes();
        let address = self.address;
        match self.ws {
            Ready::WebSocket(ws) => ws
                .max_message_size(hard)
                .max_frame_size(hard)
                .read_buffer_size(READ_BUFFER_BYTES)
                .on_upgrade(move |socket| {
                    async move {
                        tracing::debug!("connected");
                        let carrier = Carrier::WebSocket(Box::new(socket));
                        serve(Socket::new(carrier, &registry, manner, address)).await;
                        tracing::debug!("disconnected");
                    }
                    .instrument(span)
                }),
            Ready::WebTransport(request) => {
                let seats = state.webtransport_seats.clone();
                tokio::spawn(
                    async move {
                        // Players first: a spectator past the sessions the server carries
                        // is refused (its page takes the WebSocket), a player takes the
                        // place of the spectator who came last.
                        let kind = seats::Kind::of_role(manner.role);
                        let seat = match seats.take(kind, &registry.shutdown) {
                            Ok(seat) => seat,
                            Err(full) => {
                                registry.metrics.refuse(Refusal::WebTransportFull);
                                tracing::debug!("{full}");
                                return request.refuse(StatusCode::SERVICE_UNAVAILABLE).await;
                            }
                        };
                        let Some(session) = request.accept(hard).await else {
                            return;
                        };
                        tracing::debug!("connected over WebTransport");
                        let carrier = Carrier::WebTransport(Box::new(session));
                        let mut socket = Socket::new(carrier, &registry, manner, address);
                        socket.shutdown = seat.ends.clone();
                        socket._guards._seat = Some(seat);
                        serve(socket).await;
                        tracing::debug!("disconnected");
                    }
                    .instrument(span),
                );
                StatusCode::OK.into_response()
            }
        }
    }
}

/// What a socket reads at a time. Clients send inputs, pongs and small requests; tungstenite's
/// default of 128 KiB is zeroed afresh on every read, which at 2,000 sockets cost a tenth of
/// the server's CPU (docs/performance.md). A larger message is still read whole, in pieces.
const READ_BUFFER_BYTES: usize = 4 << 10;

/// Counts a connection holds until it ends: per address, open (for shutdown), per role.
struct Guards {
    _address: AddressConnection,
    _open: ConnectionGuard,
    _client: ClientGuard,
    /// A WebTransport session's place among those the server carries.
    _seat: Option<seats::Seat>,
}

/// One client's socket, with its limits.
pub struct Socket {
    carrier: Carrier,
    manner: Manner,
    metrics: Metrics,
    /// Ends the socket: the server's shutdown, or (a spectator's WebTransport session) a
    /// player that needs its place.
    shutdown: CancellationToken,
    /// The server's own shutdown.
    stopping: CancellationToken,
    /// Whether a stop suspends the matches (`Registry::suspends_on_stop`).
    resumes: bool,
    max_message_bytes: usize,
    hard_message_bytes: usize,
    /// How the rate limit is said: sustained messages per second, and bursts.
    rate: (f64, f64),
    messages: Bucket,
    strikes: Bucket,
    _guards: Guards,
}

impl Socket {
    fn new(
        carrier: Carrier,
        registry: &Registry,
        manner: Manner,
        address: AddressConnection,
    ) -> Socket {
        let cfg = &registry.config;
        Socket {
            carrier,
            metrics: registry.metrics.clone(),
            shutdown: registry.shutdown.clone(),
            stopping: registry.shutdown.clone(),
            resumes: registry.suspends_on_stop(),
            max_message_bytes: cfg.max_message_bytes,
            hard_message_bytes: cfg.hard_message_bytes(),
            rate: (cfg.messages_per_s, cfg.message_burst),
            messages: Bucket::new(cfg.message_burst, cfg.messages_per_s),
            strikes: Bucket::new(STRIKES, 1.0 / STRIKE_RECOVERY_S),
            _guards: Guards {
                _address: address,
                _open: registry.connection(),
                _client: registry.metrics.client(manner.role),
                _seat: None,
            },
            manner,
        }
    }

    /// What ends the socket: the server's shutdown, or a player that needs a spectator's
    /// WebTransport session (the socket then closes as "going away" and the page comes
    /// back over its WebSocket).
    pub fn shutdown(&self) -> &CancellationToken {
        &self.shutdown
    }

    /// Whether a player took this spectator's WebTransport session (the server goes on).
    pub fn moved_off_webtransport(&self) -> bool {
        self.shutdown.is_cancelled() && !self.stopping.is_cancelled()
    }

    /// Whether the server is stopping and the match goes on in the next one (its store
    /// resumes matches): then a socket closes with [`End::restarting`], not `finished`.
    pub fn restarting(&self) -> bool {
        self.resumes && self.stopping.is_cancelled()
    }

    /// Counts `bytes` of snapshots sent, under the connection's role.
    pub fn count_snapshot(&self, bytes: usize) {
        self.metrics
            .snapshot_bytes
            .with_label_values(&[self.manner.role])
            .inc_by(bytes as u64);
    }

    /// Whether snapshots may be lost on the way (they go as datagrams): a delta is then only
    /// against one the client acknowledged ([`Socket::acks`]).
    pub fn lossy(&self) -> bool {
        matches!(self.carrier, Carrier::WebTransport(_))
    }

    /// Which snapshots the client says it holds, over a carrier that may lose them (a
    /// WebSocket's client holds each one sent: `None`).
    pub fn acks(&self) -> Option<crate::protocol::compact::Acks> {
        match &self.carrier {
            Carrier::WebSocket(_) => None,
            Carrier::WebTransport(session) => session.acks(),
        }
    }

    /// Whether a snapshot of `len` bytes reaches the client as one piece that may be lost on
    /// its own (a datagram): over a WebSocket always.
    pub fn fits_datagram(&self, len: usize) -> bool {
        match &self.carrier {
            Carrier::WebSocket(_) => true,
            Carrier::WebTransport(session) => session.fits_datagram(len),
        }
    }

    /// The client's next message, as it came: hand it to [`Socket::read`]. Cancel-safe.
    pub async fn recv(&mut self) -> Option<Result<Message, axum::Error>> {
        match &mut self.carrier {
            Carrier::WebSocket(socket) => socket.recv().await,
            Carrier::WebTransport(session) => session.recv().await,
        }
    }

    /// What the client sent, checked: a text message within the size cap and the rate
    /// limit that `parse` takes. Anything else is struck (`Ok(None)`, or the end after too
    /// many); a ping frame is `Ok(None)` (the socket answers it itself); a close, a failed
    /// socket or a message over the hard cap end the connection.
    pub async fn read<T>(
        &mut self,
        msg: Option<Result<Message, axum::Error>>,
        parse: impl FnOnce(&str) -> Result<T, Invalid>,
    ) -> Result<Option<T>, End> {
        let text = match msg {
            None | Some(Ok(Message::Close(_))) => return Err(End::Gone),
            Some(Err(e)) => {
                let text = e.to_string();
                if text.contains("too long")
                    || text.contains("Space limit")
                    || text.contains("capacity")
                {
                    self.metrics.refuse(Refusal::MessageTooLarge);
                    let reason = format!("message over {} bytes", self.hard_message_bytes);
                    return Err(End::Close(TOO_BIG, reason));
                }
                return Err(End::Gone);
            }
            Some(Ok(Message::Text(text))) => text,
            Some(Ok(Message::Binary(b))) => {
                let why = format!("binary message of {} bytes: send JSON text", b.len());
                return self
                    .strike(Refusal::MessageInvalid, &why)
                    .await
                    .map(|()| None);
            }
            Some(Ok(_)) => return Ok(None),
        };
        let max = self.max_message_bytes;
        if text.len() > max {
            let why = format!(
                "message of {} bytes is over the {max}-byte limit",
                text.len()
            );
            return self
                .strike(Refusal::MessageTooLarge, &why)
                .await
                .map(|()| None);
        }
        if self.messages.take().is_err() {
            let (per_s, burst) = self.rate;
            let why =
                format!("rate limit: at most {per_s} messages per second (bursts of {burst})");
            return self.strike(Refusal::MessageRate, &why).await.map(|()| None);
        }
        match parse(text.as_str()) {
            Ok(m) => Ok(Some(m)),
            Err(e) => {
                let why = e.to_string();
                self.strike(Refusal::MessageInvalid, &why)
                    .await
                    .map(|()| None)
            }
        }
    }

    /// A bad message: an `error` now, a close when it happens too often.
    pub async fn strike(&mut self, refusal: Refusal, why: &str) -> Result<(), End> {
        self.metrics.refuse(refusal);
        if self.strikes.take().is_err() {
            return Err(End::policy(format!("too many bad messages; last: {why}")));
        }
        self.error(why).await
    }

    /// An `error` that is no strike (the message was fine; what it asked for is not).
    pub async fn error(&mut self, why: &str) -> Result<(), End> {
        let text = (self.manner.error)(why);
        self.text(text).await
    }

    /// Sends `message`, or ends the connection if the client cannot take it in time.
    pub async fn send(&mut self, message: Message) -> Result<(), End> {
        let sent = match &mut self.carrier {
            Carrier::WebSocket(socket) => tokio::time::timeout(SEND_TIMEOUT, socket.send(message))
                .await
                .map(|r| r.map_err(|e| e.to_string())),
            Carrier::WebTransport(session) => {
                tokio::time::timeout(SEND_TIMEOUT, session.send(message)).await
            }
        };
        match sent {
            Ok(Ok(())) => Ok(()),
            _ => Err(End::Gone),
        }
    }

    /// Sends a snapshot: as [`Socket::send`] over a WebSocket; over WebTransport as a datagram
    /// when it fits one (a client that does not read loses datagrams, and holds nothing up).
    pub async fn snapshot(&mut self, message: Message) -> Result<(), End> {
        match &mut self.carrier {
            Carrier::WebSocket(_) => self.send(message).await,
            Carrier::WebTransport(session) => {
                match tokio::time::timeout(SEND_TIMEOUT, session.send_snapshot(message)).await {
                    Ok(Ok(())) => Ok(()),
                    _ => Err(End::Gone),
                }
            }
        }
    }

    pub async fn text(&mut self, text: Utf8Bytes) -> Result<(), End> {
        self.send(Message::Text(text)).await
    }

    /// Ends the connection as `end` says: nothing more for a client gone; a close frame (its
    /// reason cut to fit) and the closing handshake otherwise.
    pub async fn close(&mut self, end: Result<(), End>) {
        let Err(End::Close(code, reason)) = end else {
            return;
        };
        let drain = if self.stopping.is_cancelled() {
            SHUTDOWN_DRAIN
        } else {
            self.manner.close_drain
        };
        let socket = match &mut self.carrier {
            Carrier::WebSocket(socket) => socket,
            Carrier::WebTransport(session) => {
                return session
                    .close(code, &truncate(&reason, REASON_BYTES), drain)
                    .await;
            }
        };
        let close = Message::Close(Some(CloseFrame {
            code,
            reason: Utf8Bytes::from(truncate(&reason, REASON_BYTES)),
        }));
        if let Ok(Ok(())) = tokio::time::timeout(SEND_TIMEOUT, socket.send(close)).await {
            // Finish the closing handshake: read (and drop) what the client still sends
            // until its close, so the socket is not reset under the close frame.
            let drain_fut = async {
                while let Some(Ok(m)) = socket.recv().await {
                    if matches!(m, Message::Close(_)) {
                        break;
                    }
                }
            };
            let _ = tokio::time::timeout(drain, drain_fut).await;
        }
    }
}

/// The longest start of `s` within `max` bytes, cut between characters.
fn truncate(s: &str, max: usize) -> String {
    let mut out = String::new();
    for c in s.chars() {
        if out.len() + c.len_utf8() > max {
            break;
        }
        out.push(c);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn close_reasons_are_cut_between_characters() {
        assert_eq!(truncate("short", REASON_BYTES), "short");
        let long = "é".repeat(100);
        let cut = truncate(&long, REASON_BYTES);
        assert_eq!(cut.len(), REASON_BYTES);
        assert_eq!(truncate("aé", 2), "a");
    }

    #[test]
    fn only_the_named_parameters_and_formats_pass() {
        let q = |pairs: &[(&str, &str)]| -> HashMap<String, String> {
            pairs
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect()
        };
        assert!(only_params(&q(&[("token", "x")]), &["token", "format"]).is_ok());
        let e = only_params(&q(&[("x", "1")]), &["token", "format"]).unwrap_err();
        assert_eq!(e.message, "x: unknown query parameter (token, format)");
        assert_eq!(compact_format(&q(&[])).ok(), Some(false));
        assert_eq!(
            compact_format(&q(&[("format", "compact")])).ok(),
            Some(true)
        );
        assert!(compact_format(&q(&[("format", "xml")])).is_err());
    }
}
