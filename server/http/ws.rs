//! `GET /ws/matches/{id}`: play (with `?token=`) or spectate a match over a WebSocket.
//!
//! Each connection is its own task. It waits on the match's `watch` channel of frames, so it
//! always sends the latest frame and skips the ones it was too slow for: a slow or dead client
//! costs the tick nothing and the other clients nothing. Events are never skipped for a
//! client that keeps up; one that fell behind gets the missing ones from the match's log.
//!
//! A player's socket is live and fogged: its snapshots hold what its opponent has in line of
//! sight ([`visible_to`]), and its events follow the same rule ([`event_seen`]): what it saw
//! or took part in comes at once, the rest as late as spectators get it, from the
//! spectators' frames. The belief it may switch on is the one spectators see, as late.
//! Once its opponent is tagged it watches on, live, through its surviving teammates' eyes
//! (snapshots with `view: "teammates"`): never the truth, and never back in time.
//!
//! What a client sends is size-capped, parsed strictly, and rate-limited by a token bucket,
//! as on every socket ([`crate::http::socket`]); which compact snapshot carries what is the
//! connection's [`Schedule`].

mod events;
mod marks;

use std::collections::VecDeque;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::extract::State;
use axum::extract::ws::Message;
use axum::response::Response;

use crate::access::ClientKey;
use crate::config::Config;
use crate::game::hub::SpectatorsRefused;
use crate::game::view::{BELIEF_EVERY, Frame, Visible, visible_to};
use crate::game::{MatchError, MatchHandle, Seat, SpectatorSeat};
use crate::http::error::ApiError;
use crate::http::socket::schedule::Schedule;
use crate::http::socket::{self, Asked, End, Manner, Socket};
use crate::http::state::AppState;
use crate::metrics::Refusal;
use crate::protocol::socket::{self as common, Limits};
use crate::protocol::ws::{self as wire, ClientMessage, Welcome};
use lasertag_core::sim::AgentId;
use lasertag_core::world::MatchStatus;
use lasertag_core::world::{HumanInput, WorldInput};
use nalgebra::Point2;

/// How long a closing connection waits for the client's close reply.
const CLOSE_DRAIN: Duration = Duration::from_secs(3);
/// How often a spectator's socket is pinged: a client that reads answers, so the hub
/// knows who does not (`game::hub::SPECTATOR_SILENT`) even while nothing else is sent.
const SPECTATOR_PING: Duration = Duration::from_secs(2);

pub async fn upgrade(
    State(state): State<AppState>,
    Asked { id, query, ip, ws }: Asked,
) -> Result<Response, ApiError> {
    let registry = &state.registry;
    let cfg = &registry.config;
    socket::refuse_while_stopping(registry)?;
    let handle = registry
        .get(&id)
        .ok_or_else(|| ApiError::no_match(registry, &id))?;
    socket::only_params(&query, &["token", "format"])?;
    let compact = socket::compact_format(&query)?;
    let admitted = socket::admit(&state, ip, ws)?;
    // A bad token is refused here, before the upgrade (401); so is a spectator past the cap.
    let seat = match query.get("token") {
        Some(token) => Seated::Player(handle.connect(token.clone()).await?),
        None => {
            let spectator = handle.hub.add_spectator(
                ClientKey::of(ip),
                cfg.max_spectators_per_match,
                cfg.max_spectators_per_address,
            );
            Seated::Spectator(spectator.inspect_err(|e| {
                registry.metrics.refuse(match e {
                    SpectatorsRefused::Client { .. } => Refusal::SpectatorsPerAddress,
                    SpectatorsRefused::Full { .. } => Refusal::SpectatorsFull,
                })
            })?)
        }
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
    // A spectator that does not read is told to go when a newcomer needs its place: its
    // task ends at once, wherever it waits (most likely in a send that cannot finish).
    let dropped = match &seat {
        Seated::Spectator(s) => Some(s.watcher.dropped.clone()),
        Seated::Player(_) => None,
    };
    Ok(admitted.open(&state, manner, span, move |sock| {
        let mut connection = Connection::new(sock, handle, seat, config);
        connection.compact = compact;
        async move {
            match dropped {
                None => connection.run().await,
                Some(dropped) => tokio::select! {
                    () = connection.run() => {}
                    () = dropped.cancelled() => {
                        tracing::info!("spectator dropped: it read nothing, and a newcomer took its place");
                    }
                },
            }
        }
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
    /// Whether it is shown everything (from the spectators' frames): a spectator. A player
    /// whose opponent was tagged stays live, and sees what its teammates see
    /// ([`visible_to`]).
    watching: bool,
    belief: bool,
    /// Snapshots as compact binary messages (else JSON text), and which parts each carries.
    compact: bool,
    schedule: Schedule,
    last_seq: u64,
    /// A player's: events up to this `seq` have come, live or as late as spectators get
    /// them, ...
    held_seq: u64,
    /// ... and these later ones (oldest first) came live, as it saw them.
    sent_live: VecDeque<u64>,
    /// A player's: the latest spectators' frame with a belief (what its overlay shows).
    held_belief: Option<Arc<Frame>>,
    finished_sent: bool,
    /// A spectator's place in the count, and what the hub knows of its sending.
    spectator: Option<SpectatorSeat>,
    /// A player's recent marks (at most [`marks::MAX_MARKS`] in [`marks::MARK_WINDOW`]).
    marks: marks::MarkRate,
}

impl Connection {
    fn new(sock: Socket, handle: MatchHandle, seated: Seated, config: Config) -> Self {
        let (seat, spectator) = match seated {
            Seated::Player(s) => (Some(s), None),
            Seated::Spectator(s) => (None, Some(s)),
        };
        let lossy = sock.lossy();
        Connection {
            sock,
            watching: seat.is_none(),
            // A person on the robot team hunts with the team's belief; an opponent's player
            // switches the (late) overlay on.
            belief: seat
                .as_ref()
                .is_none_or(|s| matches!(s.body, AgentId::Robot(_))),
            compact: false,
            // Datagrams may be lost: deltas only against what the client acknowledged.
            schedule: Schedule::new(lossy),
            seat,
            handle,
            config,
            last_seq: 0,
            held_seq: 0,
            sent_live: VecDeque::new(),
            held_belief: None,
            finished_sent: false,
            spectator,
            marks: marks::MarkRate::default(),
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
            you: self.seat.as_ref().map(|s| s.body.to_string()),
            team: self.seat.as_ref().map(|s| match s.body {
                AgentId::Opponent(_) => "opponents",
                AgentId::Robot(_) => "robots",
            }),
            name: self.seat.as_ref().map(|s| s.name.clone()),
            map: crate::maps::to_file(&self.handle.hub.arena.def),
            tick_hz: lasertag_core::sim::TICK_HZ,
            time_limit_s: frame.time_limit_s,
            belief_every: BELIEF_EVERY,
            spectator_delay_s: self.handle.hub.delay_ticks as f64
                / lasertag_core::sim::TICK_HZ as f64,
            view_starts_in_s: if self.watching {
                // The match's age says nothing of where anyone is. A head start still being
                // computed counts as done: it runs back to back, and its last tick is a
                // moment away however far the computing has got (on a loaded machine a
                // visitor may join half-way, and should not be told to wait seconds).
                let live = hub
                    .frames
                    .borrow()
                    .tick
                    .max(hub.summary.borrow().meta.head_start_ticks);
                hub.delay_ticks.saturating_sub(live) as f64 / lasertag_core::sim::TICK_HZ as f64
            } else {
                0.0
            },
            kinematics: wire::Kinematics::of(
                &self.handle.hub.physics,
                self.seat.as_ref().map_or(AgentId::Opponent(0), |s| s.body),
            ),
            rated: hub.summary.borrow().meta.rated,
            protocol: 3,
            format: if self.compact { "compact" } else { "json" },
            belief: self.belief,
            limits: Limits {
                reconnect_s: Some(self.config.reconnect_grace.as_secs_f64()),
                ..Limits::of(&self.config)
            },
        };
        self.sock.text(wire::welcome(&welcome)).await?;
        self.last_seq = frame.last_seq;
        // A player also follows the spectators' frames: the events it did not see, and the
        // belief, come from there.
        let mut held = (!self.watching).then(|| hub.spectate.clone());
        if let Some(h) = held.as_mut() {
            let shown = h.borrow_and_update().clone();
            // What happened before it connected is history, not news.
            self.held_seq = frame.last_seq;
            self.keep_belief(&shown);
        }
        self.deliver(&frame, false).await?;
        let shutdown = self.sock.shutdown().clone();
        // The receiver is moved out so the loop can borrow `self` mutably; it lives until
        // this function returns.
        let mut kicked = self
            .seat
            .as_mut()
            .map(|s| std::mem::replace(&mut s.kicked, dummy_receiver()));
        let mut ping = tokio::time::interval(SPECTATOR_PING);
        ping.reset();
        loop {
            tokio::select! {
                _ = ping.tick(), if self.spectator.is_some() => {
                    self.ping().await?;
                }
                changed = frames.changed() => {
                    if changed.is_err() {
                        // The match's task has ended (deleted, cleaned up, or the server is
                        // stopping).
                        let last = frames.borrow().clone();
                        if let Some(to) = self.handle.hub.moved.get() {
                            self.sock.text(wire::moved(to.as_deref())).await?;
                            return Err(End::restarting());
                        }
                        if self.sock.restarting() && last.status != MatchStatus::Finished {
                            return Err(End::restarting());
                        }
                        if !self.finished_sent {
                            self.finished_sent = true;
                            self.sock.text(wire::finished(&last)).await?;
                        }
                        return Err(self.ended());
                    }
                    let frame = frames.borrow_and_update().clone();
                    self.deliver(&frame, true).await?;
                }
                changed = async {
                    match held.as_mut() {
                        Some(h) => h.changed().await,
                        None => std::future::pending().await,
                    }
                } => match changed {
                    Ok(()) => {
                        let shown = held.as_mut().map(|h| h.borrow_and_update().clone());
                        if let Some(shown) = shown {
                            self.deliver_held(&shown).await?;
                        }
                    }
                    // The task has ended; `frames` will say so.
                    Err(_) => held = None,
                },
                msg = self.sock.recv() => {
                    if let (Some(s), Some(Ok(_))) = (&self.spectator, &msg) {
                        s.watcher.heard();
                    }
                    if let Some(m) = self.sock.read(msg, ClientMessage::parse).await? {
                        self.on_message(m).await?;
                    }
                }
                _ = shutdown.cancelled(), if !self.finished_sent => {
                    if self.sock.moved_off_webtransport() {
                        return Err(End::moved_off_webtransport());
                    }
                    if let Some(to) = self.handle.hub.moved.get() {
                        self.sock.text(wire::moved(to.as_deref())).await?;
                        return Err(End::restarting());
                    }
                    if self.sock.restarting() {
                        return Err(End::restarting());
                    }
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
                    Ok(reason) => return Err(End::policy(reason)),
                    Err(_) => kicked = None, // the task ended; `frames` will say so
                },
            }
        }
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
    /// A spectator's hub sees how long that takes: one stuck in it does not read.
    async fn deliver(&mut self, frame: &Arc<Frame>, with_events: bool) -> Result<(), End> {
        if let Some(s) = &self.spectator {
            s.watcher.sending(true);
        }
        let sent = self.deliver_parts(frame, with_events).await;
        if let Some(s) = &self.spectator {
            s.watcher.sending(false);
        }
        sent
    }

    /// A ping (a spectator's: the client answers as it reads), its sending seen by the hub.
    async fn ping(&mut self) -> Result<(), End> {
        if let Some(s) = &self.spectator {
            s.watcher.sending(true);
        }
        let sent = self.sock.send(Message::Ping(Default::default())).await;
        if let Some(s) = &self.spectator {
            s.watcher.sending(false);
        }
        sent
    }

    async fn deliver_parts(&mut self, frame: &Arc<Frame>, with_events: bool) -> Result<(), End> {
        // What a player sees of the live frame; `None` for a spectator, or a player watching.
        let hub = &self.handle.hub;
        let sight = match &self.seat {
            Some(seat) if !self.watching => {
                Some((seat.body, visible_to(frame, &hub.arena, seat.body)))
            }
            _ => None,
        };
        if self.on_robot_team() {
            // The team's belief is its own knowledge: a person on the team sees it live.
            self.keep_belief(frame);
        }
        match &sight {
            Some((you, Some(v))) => self.deliver_player(frame, *you, v).await?,
            Some((_, None)) => {} // a body the match does not have: nothing to show
            None if self.compact => self.deliver_compact(frame).await?,
            None => self.deliver_json(frame).await?,
        }
        let sight = sight.and_then(|(you, v)| Some((you, v?)));
        self.deliver_events(frame, with_events, sight.as_ref())
            .await
    }

    /// A spectator's snapshot of `frame`, compact (see `protocol::compact`).
    async fn deliver_compact(&mut self, frame: &Frame) -> Result<(), End> {
        let finished = frame.status == MatchStatus::Finished;
        let wanted = self.belief && frame.belief.is_some();
        let parts = self.schedule.parts(frame.tick, finished, wanted);
        let whole = wire::spectator_compact(frame, parts.belief, parts.slow);
        let bytes = self
            .schedule
            .sent(frame.tick, parts, whole, self.sock.acks());
        if !self.sock.fits_datagram(bytes.len()) {
            let motion = wire::spectator_compact(frame, false, false);
            self.send_motion_first(motion.into()).await?;
        }
        self.sock.count_snapshot(bytes.len());
        self.sock.snapshot(Message::Binary(bytes)).await
    }

    /// A compact snapshot too large for a datagram (its scans, its belief) goes in two: its
    /// `motion` alone first, as a datagram of kind 3 (what moves is never held up by a loss on the
    /// stream), then the whole on the stream; the page takes the second's scans and belief
    /// and skips a tick it already has.
    async fn send_motion_first(&mut self, motion: Vec<u8>) -> Result<(), End> {
        if !self.sock.fits_datagram(motion.len()) {
            return Ok(());
        }
        self.sock.count_snapshot(motion.len());
        let motion = crate::protocol::compact::as_motion(motion);
        self.sock.snapshot(Message::Binary(motion.into())).await
    }

    /// A spectator's snapshot of `frame`, as JSON.
    async fn deliver_json(&mut self, frame: &Frame) -> Result<(), End> {
        let snapshot = wire::spectator_snapshot(frame, self.belief);
        self.sock.count_snapshot(snapshot.len());
        self.sock.snapshot(Message::Text(snapshot)).await
    }

    /// A player's snapshot of the live `frame`: what `visible` holds, and the belief when
    /// switched on (an opponent's player: the one spectators see, as late; a person on the
    /// robot team: the team's own, live).
    async fn deliver_player(
        &mut self,
        frame: &Frame,
        you: AgentId,
        v: &Visible,
    ) -> Result<(), End> {
        let Some(seat) = &self.seat else {
            return Ok(());
        };
        let held = self.held_belief.as_deref().filter(|_| self.belief);
        if self.compact {
            use crate::protocol::compact;
            let finished = frame.status == MatchStatus::Finished;
            let mut parts = self.schedule.parts(frame.tick, finished, held.is_some());
            // An opponent's player's view has no slow parts: they stay due. A person on the
            // robot team gets their own robot's scan on the spectators' schedule.
            if !self.on_robot_team() {
                parts.slow = false;
            }
            let belief = held
                .and_then(|f| f.own_belief(you).or(f.belief.as_deref()))
                .filter(|_| parts.belief);
            let whole = compact::snapshot(frame, Some(you), Some(v), belief, parts.slow).into();
            let bytes = self
                .schedule
                .sent(frame.tick, parts, whole, self.sock.acks());
            if !self.sock.fits_datagram(bytes.len()) {
                let motion = compact::snapshot(frame, Some(you), Some(v), None, false);
                self.send_motion_first(motion).await?;
            }
            self.sock.count_snapshot(bytes.len());
            self.sock.snapshot(Message::Binary(bytes)).await
        } else {
            // On the live frames' belief ticks, as spectators get theirs.
            let belief = held.filter(|_| frame.belief.is_some());
            let snapshot = wire::player_snapshot(frame, seat.body, v, belief);
            self.sock.count_snapshot(snapshot.len());
            self.sock.snapshot(Message::Text(snapshot)).await
        }
    }

    /// Whether this connection plays a robot (a pursuer slot).
    fn on_robot_team(&self) -> bool {
        self.seat
            .as_ref()
            .is_some_and(|s| matches!(s.body, AgentId::Robot(_)))
    }

    /// Keeps `shown`, a frame that spectators see (or, for a person on the robot team, a
    /// live one), when it carries a belief: a player's overlay.
    fn keep_belief(&mut self, shown: &Arc<Frame>) {
        if shown.belief.is_some() {
            self.held_belief = Some(shown.clone());
        }
    }

    async fn on_message(&mut self, msg: ClientMessage) -> Result<(), End> {
        match msg {
            ClientMessage::Ping { t } => self.sock.text(common::pong(t)).await,
            ClientMessage::Belief { on } => {
                self.belief = on;
                Ok(())
            }
            ClientMessage::Mark { x, y, kind } => {
                let Some(seat) = &self.seat else {
                    return self
                        .sock
                        .strike(Refusal::MessageInvalid, "mark: spectators mark nothing")
                        .await;
                };
                if !self.marks.admit(Instant::now()) {
                    let why = format!(
                        "mark: at most {} marks in {} s",
                        marks::MAX_MARKS,
                        marks::MARK_WINDOW.as_secs()
                    );
                    return self.sock.error(&why).await;
                }
                let input = WorldInput::Mark {
                    by: seat.body,
                    name: seat.name.clone(),
                    at: Point2::new(x as f32, y as f32),
                    kind,
                };
                match self.handle.apply(input).await {
                    Ok(()) => Ok(()),
                    Err(MatchError::Finished(_) | MatchError::Gone(_)) => {
                        Err(End::normal("the match has ended"))
                    }
                    Err(e) => self.sock.error(&format!("mark: {e}")).await,
                }
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
                let (seat_no, generation) = (seat.seat, seat.generation);
                let frame = self.handle.hub.frames.borrow().clone();
                if let AgentId::Opponent(slot) = seat.body
                    && frame.opponents.get(slot).is_some_and(|o| o.tagged)
                {
                    let why = format!("input: {} has been tagged", seat.body);
                    return self.sock.error(&why).await;
                }
                let input = HumanInput {
                    forward: forward as f32,
                    turn: turn as f32,
                    tag,
                    seen_tick: view_tick,
                };
                if !self.handle.input(seat_no, generation, input, seq).await {
                    return Err(End::normal("the match has ended"));
                }
                Ok(())
            }
        }
    }
}

fn dummy_receiver() -> tokio::sync::oneshot::Receiver<&'static str> {
    tokio::sync::oneshot::channel().1
}
