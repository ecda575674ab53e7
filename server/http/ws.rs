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
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use axum::extract::ws::{CloseFrame, Message, Utf8Bytes, WebSocket, WebSocketUpgrade};
use axum::extract::{Path, Query, State};
use axum::response::Response;

use crate::game::snapshot::{BELIEF_EVERY, Frame, visible_to};
use crate::game::{MatchHandle, Seat};
use crate::http::{ApiError, AppState};
use crate::protocol::ws::{self as wire, ClientMessage, Limits, Welcome};
use crate::sim::MatchStatus;
use crate::sim::world::HumanInput;

/// Largest message a client may send (the spec's 4 KiB); bigger ones get an `error`.
pub const MAX_MESSAGE_BYTES: usize = 4096;
/// Messages past this size are not even read: the connection is closed (code 1009).
pub const HARD_MESSAGE_BYTES: usize = 64 * 1024;
/// Sustained messages per second a client may send (input at 20 Hz plus pings fit easily).
pub const MESSAGES_PER_S: f64 = 30.0;
/// Messages a client may send at once.
pub const MESSAGE_BURST: f64 = 40.0;
/// Bad messages tolerated in a row before the connection is closed...
pub const STRIKES: f64 = 10.0;
/// ...recovering one strike every this many seconds.
pub const STRIKE_RECOVERY_S: f64 = 5.0;
/// A client that cannot take a message within this time is dropped.
pub const SEND_TIMEOUT: Duration = Duration::from_secs(10);

/// How long a closing connection waits for the client's close reply.
const CLOSE_DRAIN: Duration = Duration::from_secs(3);
/// Close code for a policy violation (RFC 6455).
const POLICY: u16 = 1008;
const TOO_BIG: u16 = 1009;
const NORMAL: u16 = 1000;

pub async fn upgrade(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
    ws: Result<WebSocketUpgrade, axum::extract::ws::rejection::WebSocketUpgradeRejection>,
) -> Result<Response, ApiError> {
    let handle = state
        .registry
        .get(&id)
        .ok_or_else(|| ApiError::not_found(format!("no match {id}")))?;
    if let Some(k) = query.keys().find(|k| k.as_str() != "token") {
        return Err(ApiError::bad_request(format!(
            "{k}: unknown query parameter (only token)"
        )));
    }
    let ws = ws.map_err(|e| {
        ApiError::new(
            axum::http::StatusCode::BAD_REQUEST,
            format!("not a WebSocket upgrade: {e}"),
        )
    })?;
    // A bad token is refused here, before the upgrade (401).
    let seat = match query.get("token") {
        Some(token) => Some(handle.connect(token.clone()).await?),
        None => None,
    };
    let grace = state.registry.settings.reconnect_grace;
    Ok(ws
        .max_message_size(HARD_MESSAGE_BYTES)
        .max_frame_size(HARD_MESSAGE_BYTES)
        .on_upgrade(move |socket| async move {
            Connection::new(socket, handle, seat, grace).run().await;
        }))
}

/// A token bucket: `capacity` at once, refilled at `rate` per second.
#[derive(Debug, Clone)]
struct Bucket {
    tokens: f64,
    capacity: f64,
    rate: f64,
    last: Instant,
}

impl Bucket {
    fn new(capacity: f64, rate: f64) -> Bucket {
        Bucket {
            tokens: capacity,
            capacity,
            rate,
            last: Instant::now(),
        }
    }

    fn take(&mut self) -> bool {
        let now = Instant::now();
        self.tokens =
            (self.tokens + (now - self.last).as_secs_f64() * self.rate).min(self.capacity);
        self.last = now;
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }
}

/// Counts a spectator for as long as it lives.
struct SpectatorCount(Arc<AtomicUsize>);

impl Drop for SpectatorCount {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
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
    grace: Duration,
    belief: bool,
    last_seq: u64,
    finished_sent: bool,
    messages: Bucket,
    strikes: Bucket,
    _spectator: Option<SpectatorCount>,
}

impl Connection {
    fn new(socket: WebSocket, handle: MatchHandle, seat: Option<Seat>, grace: Duration) -> Self {
        let spectator = seat.is_none().then(|| {
            handle.hub.spectators.fetch_add(1, Ordering::Relaxed);
            SpectatorCount(handle.hub.spectators.clone())
        });
        Connection {
            socket,
            belief: seat.is_none(),
            seat,
            handle,
            grace,
            last_seq: 0,
            finished_sent: false,
            messages: Bucket::new(MESSAGE_BURST, MESSAGES_PER_S),
            strikes: Bucket::new(STRIKES, 1.0 / STRIKE_RECOVERY_S),
            _spectator: spectator,
        }
    }

    async fn run(mut self) {
        let end = self.serve().await;
        if let Err(End::Close(code, reason)) = end {
            let close = Message::Close(Some(CloseFrame {
                code,
                reason: Utf8Bytes::from(reason),
            }));
            if let Ok(Ok(())) = tokio::time::timeout(SEND_TIMEOUT, self.socket.send(close)).await {
                // Finish the closing handshake: read (and drop) what the client still sends
                // until its close, so the socket is not reset under the close frame.
                let drain = async {
                    while let Some(Ok(m)) = self.socket.recv().await {
                        if matches!(m, Message::Close(_)) {
                            break;
                        }
                    }
                };
                let _ = tokio::time::timeout(CLOSE_DRAIN, drain).await;
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
        let mut frames = self.handle.hub.frames.clone();
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
            tick_hz: crate::sim::TICK_HZ,
            time_limit_s: frame.time_limit_s,
            belief_every: BELIEF_EVERY,
            belief: self.belief,
            limits: Limits {
                max_message_bytes: MAX_MESSAGE_BYTES,
                messages_per_s: MESSAGES_PER_S,
                burst: MESSAGE_BURST,
                reconnect_s: self.grace.as_secs_f64(),
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
                        // The match's task has ended (deleted, or the server is stopping).
                        let last = frames.borrow().clone();
                        if !self.finished_sent {
                            self.send(wire::finished(&last)).await?;
                        }
                        return Err(End::Close(NORMAL, "the match has ended".into()));
                    }
                    let frame = frames.borrow_and_update().clone();
                    self.deliver(&frame, true).await?;
                }
                msg = self.socket.recv() => match msg {
                    None | Some(Ok(Message::Close(_))) => return Err(End::Gone),
                    Some(Err(e)) => {
                        let text = e.to_string();
                        return Err(if text.contains("too long") || text.contains("Space limit") || text.contains("capacity") {
                            End::Close(TOO_BIG, format!("message over {HARD_MESSAGE_BYTES} bytes"))
                        } else {
                            End::Gone
                        });
                    }
                    Some(Ok(Message::Text(text))) => self.on_text(text.as_str()).await?,
                    Some(Ok(Message::Binary(b))) => {
                        let why = format!("binary message of {} bytes: send JSON text", b.len());
                        self.strike(&why).await?;
                    }
                    Some(Ok(_)) => {} // pings are answered by the socket itself
                },
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

    /// Sends a frame's snapshot, the events since the last one sent, and `finished` once.
    async fn deliver(&mut self, frame: &Frame, with_events: bool) -> Result<(), End> {
        let snapshot = match &self.seat {
            None => wire::spectator_snapshot(frame, self.belief),
            Some(seat) => match visible_to(frame, &self.handle.hub.arena, seat.slot) {
                Some(v) => wire::player_snapshot(frame, &seat.opponent_id, &v, self.belief),
                // Its opponent was tagged and left the arena: the player now spectates.
                None => wire::spectator_snapshot(frame, self.belief),
            },
        };
        self.send(snapshot).await?;
        if with_events && frame.last_seq > self.last_seq {
            if self.last_seq < frame.since_seq {
                // Frames were skipped while this client was slow: fetch what it missed.
                let missed = self
                    .handle
                    .events(self.last_seq)
                    .await
                    .map(|e| e.events)
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
    async fn strike(&mut self, why: &str) -> Result<(), End> {
        if !self.strikes.take() {
            return Err(End::Close(
                POLICY,
                truncate(&format!("too many bad messages; last: {why}"), 120),
            ));
        }
        self.send(wire::error(why)).await
    }

    async fn on_text(&mut self, text: &str) -> Result<(), End> {
        if text.len() > MAX_MESSAGE_BYTES {
            let why = format!(
                "message of {} bytes is over the {MAX_MESSAGE_BYTES}-byte limit",
                text.len()
            );
            return self.strike(&why).await;
        }
        if !self.messages.take() {
            let why = format!(
                "rate limit: at most {MESSAGES_PER_S} messages per second (bursts of {MESSAGE_BURST})"
            );
            return self.strike(&why).await;
        }
        let msg = match ClientMessage::parse(text) {
            Ok(m) => m,
            Err(e) => return self.strike(&e).await,
        };
        match msg {
            ClientMessage::Ping { t } => self.send(wire::pong(t)).await,
            ClientMessage::Belief { on } => {
                self.belief = on;
                Ok(())
            }
            ClientMessage::Input { forward, turn, tag } => {
                let Some(seat) = &self.seat else {
                    return self.strike("input: spectators cannot move anyone").await;
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
                };
                if !self.handle.input(slot, generation, input).await {
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
