//! `GET /ws/matches/{id}`: play (with `?token=`) or spectate a match over a WebSocket.
//!
//! Each connection is its own task. It waits on the match's `watch` channel of frames, so it
//! always sends the latest frame and skips the ones it was too slow for: a slow or dead client
//! costs the tick nothing and the other clients nothing. Events are never skipped for a
//! client that keeps up; one that fell behind gets the missing ones from the match's log.
//!
//! What a client sends is size-capped, parsed strictly, and rate-limited by a token bucket,
//! as on every socket ([`crate::http::socket`]); which compact snapshot carries what is the
//! connection's [`Schedule`].

use std::time::Duration;

use axum::extract::State;
use axum::extract::ws::Message;
use axum::http::StatusCode;
use axum::response::Response;

use crate::config::Config;
use crate::game::view::{BELIEF_EVERY, Frame, visible_to};
use crate::game::{MatchHandle, Seat, Sight, SpectatorSeat};
use crate::http::error::ApiError;
use crate::http::socket::schedule::Schedule;
use crate::http::socket::{self, Asked, End, Manner, Socket};
use crate::http::state::AppState;
use crate::metrics::Refusal;
use crate::protocol::socket::{self as common, Limits};
use crate::protocol::ws::{self as wire, ClientMessage, Welcome};
use lasertag_core::world::HumanInput;
use lasertag_core::world::MatchStatus;

/// How long a closing connection waits for the client's close reply.
const CLOSE_DRAIN: Duration = Duration::from_secs(3);

pub async fn upgrade(
    State(state): State<AppState>,
    Asked { id, query, ip, ws }: Asked,
) -> Result<Response, ApiError> {
    let registry = &state.registry;
    let cfg = &registry.config;
    socket::refuse_while_stopping(registry)?;
    let handle = registry
        .get(&id)
        .ok_or_else(|| ApiError::not_found(format!("no match {id}")))?;
    socket::only_params(&query, &["token", "format"])?;
    let compact = socket::compact_format(&query)?;
    let admitted = socket::admit(&state, ip, ws)?;
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
    let manner = Manner {
        role,
        close_drain: CLOSE_DRAIN,
        error: common::error,
    };
    let config = cfg.clone();
    Ok(admitted.open(&state, manner, span, move |sock| {
        let mut connection = Connection::new(sock, handle, seat, config);
        connection.compact = compact;
        connection.run()
    }))
}

/// What the connection plays: an opponent slot, or a counted spectator's place.
enum Seated {
    Player(Seat),
    Spectator(SpectatorSeat),
}

struct Connection {
    sock: Socket,
    handle: MatchHandle,
    seat: Option<Seat>,
    config: Config,
    /// Whether it is shown everything (from the spectators' frames): a spectator, or a
    /// player whose opponent was tagged and has left the arena.
    watching: bool,
    belief: bool,
    /// Snapshots as compact binary messages (else JSON text), and which parts each carries.
    compact: bool,
    schedule: Schedule,
    last_seq: u64,
    finished_sent: bool,
    _spectator: Option<SpectatorSeat>,
}

impl Connection {
    fn new(sock: Socket, handle: MatchHandle, seated: Seated, config: Config) -> Self {
        let (seat, spectator) = match seated {
            Seated::Player(s) => (Some(s), None),
            Seated::Spectator(s) => (None, Some(s)),
        };
        Connection {
            sock,
            watching: seat.is_none(),
            belief: seat.is_none(),
            compact: false,
            schedule: Schedule::default(),
            seat,
            handle,
            config,
            last_seq: 0,
            finished_sent: false,
            _spectator: spectator,
        }
    }

    async fn run(mut self) {
        let end = self.serve().await;
        self.sock.close(end).await;
        // Dropping the seat's `kicked` receiver tells the match task the player has gone.
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
                reconnect_s: Some(self.config.reconnect_grace.as_secs_f64()),
                ..Limits::of(&self.config)
            },
        };
        self.sock.text(wire::welcome(&welcome)).await?;
        self.last_seq = frame.last_seq;
        self.deliver(&frame, false).await?;
        let shutdown = self.sock.shutdown().clone();
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
                            self.sock.text(wire::finished(&last)).await?;
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
                msg = self.sock.recv() => {
                    if let Some(m) = self.sock.read(msg, ClientMessage::parse).await? {
                        self.on_message(m).await?;
                    }
                }
                _ = shutdown.cancelled(), if !self.finished_sent => {
                    // The match task is being stopped too and will publish its end; this
                    // tells the client even if the task's last frame is not seen first.
                    self.finished_sent = true;
                    let last = frames.borrow().clone();
                    self.sock.text(wire::finished_by_shutdown(&last)).await?;
                    return Err(self.ended());
                }
                kick = async {
                    match kicked.as_mut() {
                        Some(k) => k.await,
                        None => std::future::pending().await,
                    }
                } => match kick {
                    Ok(()) => {
                        return Err(End::policy("another connection took over this player"));
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
        if self.sock.shutdown().is_cancelled() {
            End::going_away()
        } else {
            End::normal("the match has ended")
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
        use crate::protocol::compact;
        let finished = frame.status == MatchStatus::Finished;
        let wanted = self.belief && frame.belief.is_some();
        let mut parts = self.schedule.parts(frame.tick, finished, wanted);
        let visible = match &self.seat {
            Some(seat) if !self.watching => {
                visible_to(frame, &self.handle.hub.arena, seat.slot).map(|v| (seat.slot, v))
            }
            _ => None,
        };
        let whole = match &visible {
            None => wire::spectator_compact(frame, parts.belief, parts.slow),
            Some((slot, v)) => {
                // A player's own view has no slow parts: they stay due.
                parts.slow = false;
                compact::snapshot(frame, Some(*slot), Some(v), parts.belief, false).into()
            }
        };
        let bytes = self.schedule.sent(frame.tick, parts, whole);
        self.sock.count_snapshot(bytes.len());
        self.sock.send(Message::Binary(bytes)).await
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
        self.sock.count_snapshot(snapshot.len());
        self.sock.text(snapshot).await
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
                    self.sock.text(wire::event(e)).await?;
                }
            }
            let last = self.last_seq;
            for e in frame.events.iter().filter(|e| e.seq > last) {
                self.sock.text(wire::event(e)).await?;
            }
            self.last_seq = frame.last_seq;
        }
        if frame.status == MatchStatus::Finished && !self.finished_sent {
            self.finished_sent = true;
            self.sock.text(wire::finished(frame)).await?;
        }
        Ok(())
    }

    async fn on_message(&mut self, msg: ClientMessage) -> Result<(), End> {
        match msg {
            ClientMessage::Ping { t } => self.sock.text(common::pong(t)).await,
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
                        .sock
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
                    return self.sock.error(&why).await;
                }
                let input = HumanInput {
                    forward: forward as f32,
                    turn: turn as f32,
                    tag,
                    seen_tick: view_tick,
                };
                if !self.handle.input(slot, generation, input, seq).await {
                    return Err(End::normal("the match has ended"));
                }
                Ok(())
            }
        }
    }
}

fn dummy_receiver() -> tokio::sync::oneshot::Receiver<()> {
    tokio::sync::oneshot::channel().1
}
