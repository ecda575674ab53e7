//! `GET /ws/matches/{id}`: play (with `?token=`) or spectate a match over a WebSocket.
//!
//! Each connection is its own task. It waits on the match's `watch` channel of frames, so it
//! always sends the latest frame and skips the ones it was too slow for: a slow or dead client
//! costs the tick nothing and the other clients nothing. Events are never skipped for a
//! client that keeps up; one that fell behind gets the missing ones from the match's log.
//!
//! What a client sends is size-capped, parsed strictly, and rate-limited by a token bucket;
//! every bad message gets an `error`, and a client that keeps sending them is closed with a
//! reason (close code 1008).

use std::collections::HashMap;
use std::time::Duration;

use axum::extract::ws::{CloseFrame, Message, Utf8Bytes, WebSocket, WebSocketUpgrade};
use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
use axum::response::Response;
use tokio_util::sync::CancellationToken;
use tracing::Instrument;

use crate::config::Config;
use crate::game::view::{BELIEF_EVERY, Frame, visible_to};
use crate::game::{ConnectionGuard, MatchHandle, Seat, Sight, SpectatorSeat};
use crate::http::limits::{AddressConnection, Bucket, ClientIp};
use crate::http::{ApiError, AppState};
use crate::metrics::{ClientGuard, Metrics, Refusal};
use crate::protocol::ws::{self as wire, ClientMessage, Limits, Welcome};
use lasertag_core::world::HumanInput;
use lasertag_core::world::MatchStatus;

/// Bad messages tolerated in a row before the connection is closed...
pub const STRIKES: f64 = 10.0;
/// ...recovering one strike every this many seconds.
pub const STRIKE_RECOVERY_S: f64 = 5.0;
/// A client that cannot take a message within this time is dropped.
pub const SEND_TIMEOUT: Duration = Duration::from_secs(10);

/// How long a closing connection waits for the client's close reply.
const CLOSE_DRAIN: Duration = Duration::from_secs(3);
/// ...and when the server is shutting down (it has 5 s in all).
const SHUTDOWN_DRAIN: Duration = Duration::from_secs(1);
/// Close codes (RFC 6455): policy violation, message too big, normal, going away.
const POLICY: u16 = 1008;
const TOO_BIG: u16 = 1009;
const NORMAL: u16 = 1000;
const GOING_AWAY: u16 = 1001;

pub async fn upgrade(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
    ClientIp(ip): ClientIp,
    ws: Result<WebSocketUpgrade, axum::extract::ws::rejection::WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    let registry = &state.registry;
    let cfg = &registry.config;
    if registry.shutdown.is_cancelled() {
        return Err(ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "the server is shutting down",
        ));
    }
    let handle = registry
        .get(&id)
        .ok_or_else(|| ApiError::not_found(format!("no match {id}")))?;
    if let Some(k) = query
        .keys()
        .find(|k| !matches!(k.as_str(), "token" | "format"))
    {
        return Err(ApiError::bad_request(format!(
            "{k}: unknown query parameter (token, format)"
        )));
    }
    let compact = match query.get("format").map(String::as_str) {
        None | Some("json") => false,
        Some("compact") => true,
        Some(other) => {
            return Err(ApiError::bad_request(format!(
                "format: {other:?} is not a snapshot format (json or compact)"
            )));
        }
    };
    let ws = ws.map_err(|e| {
        ApiError::new(
            axum::http::StatusCode::BAD_REQUEST,
            format!("not a WebSocket upgrade: {e}"),
        )
    })?;
    let Some(address) = state
        .limits
        .open_connection(ip, cfg.max_connections_per_address)
    else {
        registry.metrics.refuse(Refusal::ConnectionsPerAddress);
        return Err(ApiError::new(
            StatusCode::TOO_MANY_REQUESTS,
            format!(
                "too many connections from {ip}: at most {} WebSockets open at once per address",
                cfg.max_connections_per_address
            ),
        ));
    };
    // A bad token is refused here, before the upgrade (401); so is a spectator past the cap.
    let seat = match query.get("token") {
        Some(token) => Seated::Player(handle.connect(token.clone()).await?),
        None => match handle.hub.add_spectator(cfg.max_spectators_per_match) {
            Some(s) => Seated::Spectator(s),
            None => {
                registry.metrics.refuse(Refusal::SpectatorsFull);
                return Err(ApiError::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    format!(
                        "spectators: match {id} is at this server's limit of {} per match",
                        cfg.max_spectators_per_match
                    ),
                ));
            }
        },
    };
    let role = match seat {
        Seated::Player(_) => "player",
        Seated::Spectator(_) => "spectator",
    };
    let span = tracing::info_span!("ws", match_id = %id, role, %ip);
    let registry = state.registry.clone();
    let hard = cfg.hard_message_bytes();
    Ok(ws
        .max_message_size(hard)
        .max_frame_size(hard)
        .on_upgrade(move |socket| {
            async move {
                tracing::debug!("connected");
                let guards = Guards {
                    _address: address,
                    _open: registry.connection(),
                    _client: registry.metrics.client(role),
                };
                let mut connection = Connection::new(socket, handle, seat, &registry, guards);
                connection.compact = compact;
                connection.run().await;
                tracing::debug!("disconnected");
            }
            .instrument(span)
        }))
}

/// What the connection plays: an opponent slot, or a counted spectator's place.
enum Seated {
    Player(Seat),
    Spectator(SpectatorSeat),
}

/// Counts a connection holds until it ends: per address, open (for shutdown), per role.
struct Guards {
    _address: AddressConnection,
    _open: ConnectionGuard,
    _client: ClientGuard,
}

/// Why a connection ends.
enum End {
    /// The client left or the socket failed: nothing more to send.
    Gone,
    /// Close with this code and reason.
    Close(u16, String),
}

struct Connection {
    socket: WebSocket,
    handle: MatchHandle,
    seat: Option<Seat>,
    config: Config,
    metrics: Metrics,
    shutdown: CancellationToken,
    role: &'static str,
    /// Whether it is shown everything (from the spectators' frames): a spectator, or a
    /// player whose opponent was tagged and has left the arena.
    watching: bool,
    belief: bool,
    /// Snapshots as compact binary messages (else JSON text), and the ticks whose snapshot
    /// last carried the slow parts and the belief (each is sent again once it is due).
    compact: bool,
    slow_at: Option<u64>,
    belief_at: Option<u64>,
    /// The last compact snapshot written, whole: the baseline of the next one's delta.
    sent: Option<axum::body::Bytes>,
    last_seq: u64,
    finished_sent: bool,
    messages: Bucket,
    strikes: Bucket,
    _spectator: Option<SpectatorSeat>,
    _guards: Guards,
}

impl Connection {
    fn new(
        socket: WebSocket,
        handle: MatchHandle,
        seated: Seated,
        registry: &crate::game::Registry,
        guards: Guards,
    ) -> Self {
        let (seat, spectator) = match seated {
            Seated::Player(s) => (Some(s), None),
            Seated::Spectator(s) => (None, Some(s)),
        };
        let cfg = registry.config.clone();
        Connection {
            socket,
            watching: seat.is_none(),
            belief: seat.is_none(),
            compact: false,
            slow_at: None,
            belief_at: None,
            sent: None,
            role: if seat.is_some() {
                "player"
            } else {
                "spectator"
            },
            seat,
            handle,
            messages: Bucket::new(cfg.message_burst, cfg.messages_per_s),
            strikes: Bucket::new(STRIKES, 1.0 / STRIKE_RECOVERY_S),
            config: cfg,
            metrics: registry.metrics.clone(),
            shutdown: registry.shutdown.clone(),
            last_seq: 0,
            finished_sent: false,
            _spectator: spectator,
            _guards: guards,
        }
    }

    async fn run(mut self) {
        let end = self.serve().await;
        if let Err(End::Close(code, reason)) = end {
            let drain = if self.shutdown.is_cancelled() {
                SHUTDOWN_DRAIN
            } else {
                CLOSE_DRAIN
            };
            let close = Message::Close(Some(CloseFrame {
                code,
                reason: Utf8Bytes::from(reason),
            }));
            if let Ok(Ok(())) = tokio::time::timeout(SEND_TIMEOUT, self.socket.send(close)).await {
                // Finish the closing handshake: read (and drop) what the client still sends
                // until its close, so the socket is not reset under the close frame.
                let drain_fut = async {
                    while let Some(Ok(m)) = self.socket.recv().await {
                        if matches!(m, Message::Close(_)) {
                            break;
                        }
                    }
                };
                let _ = tokio::time::timeout(drain, drain_fut).await;
            }
        }
        // Dropping the seat's `kicked` receiver tells the match task the player has gone.
    }

    async fn send(&mut self, text: Utf8Bytes) -> Result<(), End> {
        match tokio::time::timeout(SEND_TIMEOUT, self.socket.send(Message::Text(text))).await {
            Ok(Ok(())) => Ok(()),
            _ => Err(End::Gone),
        }
    }

    async fn serve(&mut self) -> Result<(), End> {
        // Players see the match as it is now (through their opponent's eyes); spectators
        // see it as late as it is held back.
        let hub = &self.handle.hub;
        let mut frames = if self.watching {
            hub.spectate.clone()
        } else {
            hub.frames.clone()
        };
        let frame = frames.borrow_and_update().clone();
        let welcome = Welcome {
            kind: "welcome",
            match_id: &self.handle.id,
            role: if self.seat.is_some() {
                "player"
            } else {
                "spectator"
            },
            you: self.seat.as_ref().map(|s| s.opponent_id.clone()),
            name: self.seat.as_ref().map(|s| s.name.clone()),
            map: crate::maps::to_file(&self.handle.hub.arena.def),
            tick_hz: lasertag_core::sim::TICK_HZ,
            time_limit_s: frame.time_limit_s,
            belief_every: BELIEF_EVERY,
            spectator_delay_s: self.handle.hub.delay_ticks as f64
                / lasertag_core::sim::TICK_HZ as f64,
            kinematics: wire::Kinematics::of(&self.handle.hub.physics),
            protocol: 2,
            format: if self.compact { "compact" } else { "json" },
            belief: self.belief,
            limits: Limits {
                max_message_bytes: self.config.max_message_bytes,
                messages_per_s: self.config.messages_per_s,
                burst: self.config.message_burst,
                reconnect_s: self.config.reconnect_grace.as_secs_f64(),
            },
        };
        self.send(wire::welcome(&welcome)).await?;
        self.last_seq = frame.last_seq;
        self.deliver(&frame, false).await?;
        // The receiver is moved out so the loop can borrow `self` mutably; it lives until
        // this function returns.
        let mut kicked = self
            .seat
            .as_mut()
            .map(|s| std::mem::replace(&mut s.kicked, dummy_receiver()));
        loop {
            tokio::select! {
                changed = frames.changed() => {
                    if changed.is_err() {
                        // The match's task has ended (deleted, cleaned up, or the server is
                        // stopping).
                        let last = frames.borrow().clone();
                        if !self.finished_sent {
                            self.finished_sent = true;
                            self.send(wire::finished(&last)).await?;
                        }
                        return Err(self.ended());
                    }
                    let frame = frames.borrow_and_update().clone();
                    self.deliver(&frame, true).await?;
                    if !self.watching && !self.finished_sent && self.tagged(&frame) {
                        // Its opponent has left the arena: the player now watches, as
                        // spectators do (as late as they do, or a tagged player could tell
                        // the others where everyone is).
                        self.watching = true;
                        frames = self.handle.hub.spectate.clone();
                        frames.mark_changed();
                    }
                }
                msg = self.socket.recv() => match msg {
                    None | Some(Ok(Message::Close(_))) => return Err(End::Gone),
                    Some(Err(e)) => {
                        let text = e.to_string();
                        return Err(if text.contains("too long") || text.contains("Space limit") || text.contains("capacity") {
                            self.metrics.refuse(Refusal::MessageTooLarge);
                            End::Close(TOO_BIG, format!("message over {} bytes", self.config.hard_message_bytes()))
                        } else {
                            End::Gone
                        });
                    }
                    Some(Ok(Message::Text(text))) => self.on_text(text.as_str()).await?,
                    Some(Ok(Message::Binary(b))) => {
                        let why = format!("binary message of {} bytes: send JSON text", b.len());
                        self.strike(Refusal::MessageInvalid, &why).await?;
                    }
                    Some(Ok(_)) => {} // pings are answered by the socket itself
                },
                _ = self.shutdown.cancelled(), if !self.finished_sent => {
                    // The match task is being stopped too and will publish its end; this
                    // tells the client even if the task's last frame is not seen first.
                    self.finished_sent = true;
                    let last = frames.borrow().clone();
                    self.send(wire::finished_by_shutdown(&last)).await?;
                    return Err(self.ended());
                }
                kick = async {
                    match kicked.as_mut() {
                        Some(k) => k.await,
                        None => std::future::pending().await,
                    }
                } => match kick {
                    Ok(()) => {
                        return Err(End::Close(POLICY, "another connection took over this player".into()));
                    }
                    Err(_) => kicked = None, // the task ended; `frames` will say so
                },
            }
        }
    }

    /// Whether this connection's opponent is tagged in `frame`.
    fn tagged(&self, frame: &Frame) -> bool {
        self.seat
            .as_ref()
            .and_then(|s| frame.opponents.get(s.slot))
            .is_some_and(|o| o.tagged)
    }

    /// How to close once the match has ended.
    fn ended(&self) -> End {
        if self.shutdown.is_cancelled() {
            End::Close(GOING_AWAY, "the server is shutting down".into())
        } else {
            End::Close(NORMAL, "the match has ended".into())
        }
    }

    /// Sends a frame's snapshot, the events since the last one sent, and `finished` once.
    async fn deliver(&mut self, frame: &Frame, with_events: bool) -> Result<(), End> {
        if self.compact {
            self.deliver_compact(frame).await?;
        } else {
            self.deliver_json(frame).await?;
        }
        self.deliver_events(frame, with_events).await
    }

    /// The compact snapshot of `frame` (see `protocol::compact`).
    async fn deliver_compact(&mut self, frame: &Frame) -> Result<(), End> {
        use crate::protocol::compact::{self, BELIEF_COMPACT_EVERY, SLOW_EVERY};
        let finished = frame.status == MatchStatus::Finished;
        let due = |at: Option<u64>, every: u64| {
            finished || at.is_none_or(|t| frame.tick >= t + every || frame.tick < t)
        };
        let slow = due(self.slow_at, SLOW_EVERY);
        let belief =
            self.belief && frame.belief.is_some() && due(self.belief_at, BELIEF_COMPACT_EVERY);
        let visible = match &self.seat {
            Some(seat) if !self.watching => {
                visible_to(frame, &self.handle.hub.arena, seat.slot).map(|v| (seat.slot, v))
            }
            _ => None,
        };
        let whole = match &visible {
            None => wire::spectator_compact(frame, belief, slow),
            Some((slot, v)) => compact::snapshot(frame, Some(*slot), Some(v), belief, false).into(),
        };
        let bytes = match self
            .sent
            .as_deref()
            .and_then(|base| compact::delta(base, &whole))
        {
            Some(d) => d.into(),
            None => whole.clone(),
        };
        self.sent = Some(whole);
        if visible.is_none() && slow {
            self.slow_at = Some(frame.tick);
        }
        if belief {
            self.belief_at = Some(frame.tick);
        }
        self.metrics
            .snapshot_bytes
            .with_label_values(&[self.role])
            .inc_by(bytes.len() as u64);
        match tokio::time::timeout(SEND_TIMEOUT, self.socket.send(Message::Binary(bytes))).await {
            Ok(Ok(())) => Ok(()),
            _ => Err(End::Gone),
        }
    }

    /// The JSON snapshot of `frame`.
    async fn deliver_json(&mut self, frame: &Frame) -> Result<(), End> {
        let snapshot = match &self.seat {
            Some(_) if self.watching => wire::spectator_snapshot(frame, self.belief),
            None => wire::spectator_snapshot(frame, self.belief),
            Some(seat) => match visible_to(frame, &self.handle.hub.arena, seat.slot) {
                Some(v) => wire::player_snapshot(frame, &seat.opponent_id, &v, self.belief),
                // Its opponent was tagged and left the arena: the player now spectates.
                None => wire::spectator_snapshot(frame, self.belief),
            },
        };
        self.metrics
            .snapshot_bytes
            .with_label_values(&[self.role])
            .inc_by(snapshot.len() as u64);
        self.send(snapshot).await
    }

    /// The events since the last one sent, and `finished` once.
    async fn deliver_events(&mut self, frame: &Frame, with_events: bool) -> Result<(), End> {
        if with_events && frame.last_seq > self.last_seq {
            if self.last_seq < frame.since_seq {
                // Frames were skipped while this client was slow: fetch what it missed.
                let since = self.last_seq;
                let missed = self
                    .handle
                    .read(Sight::Live, move |r| Ok(r.events(since).to_vec()))
                    .await
                    .unwrap_or_default();
                for e in missed.iter().filter(|e| e.seq <= frame.since_seq) {
                    self.send(wire::event(e)).await?;
                }
            }
            let last = self.last_seq;
            for e in frame.events.iter().filter(|e| e.seq > last) {
                self.send(wire::event(e)).await?;
            }
            self.last_seq = frame.last_seq;
        }
        if frame.status == MatchStatus::Finished && !self.finished_sent {
            self.finished_sent = true;
            self.send(wire::finished(frame)).await?;
        }
        Ok(())
    }

    /// A bad message: an `error` now, a close when it happens too often.
    async fn strike(&mut self, refusal: Refusal, why: &str) -> Result<(), End> {
        self.metrics.refuse(refusal);
        if self.strikes.take().is_err() {
            return Err(End::Close(
                POLICY,
                truncate(&format!("too many bad messages; last: {why}"), 120),
            ));
        }
        self.send(wire::error(why)).await
    }

    async fn on_text(&mut self, text: &str) -> Result<(), End> {
        let max = self.config.max_message_bytes;
        if text.len() > max {
            let why = format!(
                "message of {} bytes is over the {max}-byte limit",
                text.len()
            );
            return self.strike(Refusal::MessageTooLarge, &why).await;
        }
        if self.messages.take().is_err() {
            let why = format!(
                "rate limit: at most {} messages per second (bursts of {})",
                self.config.messages_per_s, self.config.message_burst
            );
            return self.strike(Refusal::MessageRate, &why).await;
        }
        let msg = match ClientMessage::parse(text) {
            Ok(m) => m,
            Err(e) => return self.strike(Refusal::MessageInvalid, &e.to_string()).await,
        };
        match msg {
            ClientMessage::Ping { t } => self.send(wire::pong(t)).await,
            ClientMessage::Belief { on } => {
                self.belief = on;
                Ok(())
            }
            ClientMessage::Input {
                forward,
                turn,
                tag,
                seq,
                view_tick,
            } => {
                let Some(seat) = &self.seat else {
                    return self
                        .strike(
                            Refusal::MessageInvalid,
                            "input: spectators cannot move anyone",
                        )
                        .await;
                };
                let (slot, generation) = (seat.slot, seat.generation);
                let frame = self.handle.hub.frames.borrow().clone();
                if frame.opponents.get(slot).is_some_and(|o| o.tagged) {
                    let why = format!("input: {} has been tagged", seat.opponent_id);
                    return self.send(wire::error(&why)).await;
                }
                let input = HumanInput {
                    forward: forward as f32,
                    turn: turn as f32,
                    tag,
                    seen_tick: view_tick,
                };
                if !self.handle.input(slot, generation, input, seq).await {
                    return Err(End::Close(NORMAL, "the match has ended".into()));
                }
                Ok(())
            }
        }
    }
}

fn dummy_receiver() -> tokio::sync::oneshot::Receiver<()> {
    tokio::sync::oneshot::channel().1
}

fn truncate(s: &str, max: usize) -> String {
    // Close reasons must fit a control frame (123 bytes).
    let mut out = String::new();
    for c in s.chars() {
        if out.len() + c.len_utf8() > max {
            break;
        }
        out.push(c);
    }
    out
}
