//! `GET /ws/replays/{id}`: a finished match played back over a WebSocket, with play, pause,
//! seek and speed.
//!
//! A connection holds a [`Cursor`] into the replay and moves it forward one tick per step
//! (`speed × 20` ticks a second; above 1× each snapshot covers several ticks, so a page gets
//! at most 20 a second), or jumps with a seek. Stepping and seeking re-simulate the match,
//! which is blocking work: each runs on the replays' own bounded pool (`admit::off_workers`),
//! the cursor moved into the job and back. A slow pool makes playback slower, never a burst.
//!
//! What is sent is what the live sockets sent: the spectators' snapshot (or, with `?as=o0`,
//! what that person's own socket showed: only what its opponent had in line of sight) and
//! the events of the ticks played, so a page draws a replay with the renderer it draws a
//! match with. Messages are size-capped, rate-limited and parsed strictly as on every
//! socket ([`crate::http::socket`]); seeks past [`SEEKS_PER_S`] are coalesced (only the latest waiting one is shown).

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::Arc;
use std::time::Duration;

use axum::extract::State;
use axum::extract::ws::Message;
use axum::http::StatusCode;
use axum::response::Response;
use tokio::time::Instant;

use crate::game::admission;
use crate::game::replay::{Cursor, Replay};
use crate::game::view::BELIEF_EVERY;
use crate::http::admit::off_workers;
use crate::http::error::ApiError;
use crate::http::limits::{CURSOR_BYTES, CursorHold, CursorsFull};
use crate::http::replays::find;
use crate::http::socket::{self, Asked, End, Manner, Socket};
use crate::http::state::AppState;
use crate::metrics::Refusal;
use crate::protocol::replay_ws::{self as rwire, ReplayControl, ReplayWelcome};
use crate::protocol::socket::{self as common, Limits};
use crate::protocol::ws as wire;
use frames::{Show, Shown, seats, show};
use lasertag_core::sim::{AgentId, TICK_HZ};

mod frames;

/// Seeks carried out per second at most; a scrubbing page sends more, and only the latest
/// waiting one matters.
pub const SEEKS_PER_S: f64 = 10.0;
/// Snapshots per second at most: above 1× a step covers several ticks.
const STEPS_PER_S: f64 = TICK_HZ as f64;

/// How long a closing connection waits for the client's close reply.
const CLOSE_DRAIN: Duration = Duration::from_secs(1);

/// Checks everything a refusal can name before the upgrade (the replay, the query, the
/// address's open sockets), then serves the connection in its own task.
pub async fn upgrade(
    State(state): State<AppState>,
    Asked { id, query, ip, ws }: Asked,
) -> Result<Response, ApiError> {
    socket::refuse_while_stopping(&state.registry)?;
    socket::only_params(&query, &["tick", "speed", "as", "format"])?;
    let replay = find(&state, &id).await?;
    let options = Options::of(&query, &replay)?;
    let cursor = hold_cursor(&state, ip, &replay)?;
    let admitted = socket::admit(&state, ip, ws)?;
    let span = tracing::info_span!("replay_ws", replay_id = %id, %ip);
    let manner = Manner {
        role: "replay",
        close_drain: CLOSE_DRAIN,
        error: common::error_with_message,
    };
    let app = state.clone();
    Ok(admitted.open(&state, manner, span, move |sock| async move {
        let _cursor = cursor;
        Viewer::new(sock, app, replay, options).run().await
    }))
}

/// Counts the copy of the match's world the socket will play from against its client's
/// share of [`CURSOR_BYTES`] and the server's whole.
fn hold_cursor(state: &AppState, ip: IpAddr, replay: &Replay) -> Result<CursorHold, ApiError> {
    let bytes = replay.world_bytes();
    let share = (CURSOR_BYTES as f64 * state.registry.config.client_budget_share) as u64;
    state
        .limits
        .open_cursor(ip, bytes, CURSOR_BYTES, share.max(bytes))
        .map_err(|full| {
            let (status, whose, most) = match full {
                CursorsFull::Client => (StatusCode::TOO_MANY_REQUESTS, "this client's", share),
                CursorsFull::Server => (StatusCode::SERVICE_UNAVAILABLE, "this server's", CURSOR_BYTES),
            };
            ApiError::new(
                status,
                format!(
                    "replays: this replay's socket would hold {} and take {whose} open replay sockets past {}; close one or try again later",
                    admission::mb(bytes),
                    admission::mb(most)
                ),
            )
        })
}

/// What the query asked for, checked before the upgrade.
struct Options {
    tick: u64,
    speed: f64,
    /// The agent whose view is shown (an opponent, or a robot), or everything.
    view: Option<AgentId>,
    compact: bool,
}

impl Options {
    /// Errors as the REST endpoints give them: 400 for what is not a value, 404 for a tick
    /// or an opponent the replay does not have.
    fn of(query: &HashMap<String, String>, replay: &Replay) -> Result<Options, ApiError> {
        let tick = match query.get("tick") {
            None => 0,
            Some(v) => v.parse::<u64>().map_err(|_| {
                ApiError::bad_request(format!("tick: {v:?} is not an integer in 0..={}", u64::MAX))
            })?,
        };
        if tick > replay.last_tick {
            return Err(ApiError::not_found(format!(
                "tick: the replay has ticks 0 to {}, not {tick}",
                replay.last_tick
            )));
        }
        let speed = match query.get("speed") {
            None => 1.0,
            Some(v) => {
                let n = v
                    .parse::<f64>()
                    .map_err(|_| ApiError::bad_request(format!("speed: {v:?} is not a number")))?;
                rwire::check_speed("speed", n)?
            }
        };
        let config = replay.config();
        let view = match query.get("as") {
            None => None,
            Some(v) => match v.parse::<AgentId>() {
                Ok(AgentId::Opponent(i)) if i < config.opponents => Some(AgentId::Opponent(i)),
                Ok(AgentId::Opponent(_)) => {
                    return Err(ApiError::not_found(format!(
                        "as: no opponent {v} in this match (o0 to o{})",
                        config.opponents.saturating_sub(1)
                    )));
                }
                // A robot's view is a person's on the robot team: its laser and the belief.
                Ok(AgentId::Robot(i)) if i < config.robots => Some(AgentId::Robot(i)),
                Ok(AgentId::Robot(_)) => {
                    return Err(ApiError::not_found(format!(
                        "as: no robot {v} in this match (r0 to r{})",
                        config.robots.saturating_sub(1)
                    )));
                }
                Err(_) => {
                    return Err(ApiError::bad_request(format!(
                        "as: {v:?} is not an agent id (o0, o1, … or r0, r1, …)"
                    )));
                }
            },
        };
        let compact = socket::compact_format(query)?;
        Ok(Options {
            tick,
            speed,
            view,
            compact,
        })
    }
}

/// Time between two steps at `speed`, and ticks per step.
fn pace(speed: f64) -> (Duration, f64) {
    let per_tick = 1.0 / (TICK_HZ as f64 * speed);
    let period = per_tick.max(1.0 / STEPS_PER_S);
    (Duration::from_secs_f64(period), period / per_tick)
}

/// One replay connection: its cursor, what it plays and how fast.
struct Viewer {
    sock: Socket,
    state: AppState,
    replay: Arc<Replay>,
    options: Options,
    /// Taken while a job moves it.
    cursor: Option<Cursor>,
    tick: u64,
    playing: bool,
    speed: f64,
    belief: bool,
    belief_at: Option<u64>,
    last_seq: u64,
    /// Ticks owed by past steps' fractions (speeds that are not whole numbers).
    carry: f64,
    next_step: Instant,
    pending_seek: Option<u64>,
    next_seek: Instant,
}

impl Viewer {
    fn new(sock: Socket, state: AppState, replay: Arc<Replay>, options: Options) -> Viewer {
        let now = Instant::now();
        Viewer {
            sock,
            cursor: None,
            tick: options.tick,
            playing: options.tick < replay.last_tick,
            speed: options.speed,
            // As on the live socket: spectators and people on the robot team start with the
            // belief, opponents' players without.
            belief: !matches!(options.view, Some(AgentId::Opponent(_))),
            belief_at: None,
            last_seq: 0,
            carry: 0.0,
            next_step: now,
            pending_seek: None,
            next_seek: now,
            state,
            replay,
            options,
        }
    }

    async fn run(mut self) {
        let end = self.serve().await;
        self.sock.close(end).await;
    }

    fn show_options(&self, fresh: bool, events: bool) -> Show {
        Show {
            view: self.options.view,
            compact: self.options.compact,
            belief: self.belief,
            belief_at: self.belief_at,
            fresh,
            events_after: events.then_some(self.last_seq),
        }
    }

    /// Moves the cursor `steps` ticks on (from a new one at `seek`, or from the one held)
    /// off the async workers, then sends what it shows there.
    async fn job(&mut self, seek: Option<u64>, steps: u64, show_how: Show) -> Result<Shown, End> {
        let replay = self.replay.clone();
        let held = self.cursor.take();
        let current = self.tick;
        let work = move || {
            let mut cursor = match (seek, held) {
                (None, Some(c)) => c,
                // No cursor held (only after a job that failed): start again where it was.
                (Some(_), _) | (None, None) => replay
                    .cursor(seek.unwrap_or(current))
                    .map_err(|e| e.to_string())?,
            };
            for _ in 0..steps {
                if !replay.advance(&mut cursor).map_err(|e| e.to_string())? {
                    break;
                }
            }
            let shown = show(&replay, cursor.world(), show_how);
            Ok::<_, String>((cursor, shown))
        };
        let (cursor, shown) = blocking(self.state.clone(), work).await?;
        self.cursor = Some(cursor);
        self.tick = shown.tick;
        self.last_seq = shown.last_seq;
        self.belief_at = shown.belief_at;
        let bytes: usize = shown
            .messages
            .iter()
            .map(|m| match m {
                Message::Text(t) => t.len(),
                Message::Binary(b) => b.len(),
                _ => 0,
            })
            .sum();
        self.sock.count_snapshot(bytes);
        // The snapshot first (a datagram over WebTransport), then the ticks' events.
        let mut messages = shown.messages.iter().cloned();
        if let Some(snapshot) = messages.next() {
            self.sock.snapshot(snapshot).await?;
        }
        for m in messages {
            self.sock.send(m).await?;
        }
        Ok(shown)
    }

    async fn status(&mut self) -> Result<(), End> {
        let tick = self.pending_seek.unwrap_or(self.tick);
        self.sock
            .text(rwire::status(tick, self.playing, self.speed))
            .await
    }

    async fn serve(&mut self) -> Result<(), End> {
        self.state.registry.history.opened(&self.replay);
        // The first cursor: the whole match is re-simulated once if nobody watched it lately.
        let first = self.show_options(true, false);
        let replay = self.replay.clone();
        let start = self.options.tick;
        let view = self.options.view;
        let (cursor, welcome) = blocking(self.state.clone(), move || {
            let cursor = replay.cursor(start).map_err(|e| e.to_string())?;
            let w = cursor.world();
            let map = crate::maps::to_file(&w.arena.def);
            let kinematics =
                wire::Kinematics::of(&w.config.physics, view.unwrap_or(AgentId::Opponent(0)));
            let time_limit_s = w.config.time_limit_ticks as f64 / TICK_HZ as f64;
            let seated = seats(w);
            Ok::<_, String>((cursor, (map, kinematics, time_limit_s, seated)))
        })
        .await?;
        let (map, kinematics, time_limit_s, seated) = welcome;
        let you = self.options.view.map(|a| a.to_string());
        let welcome = ReplayWelcome {
            kind: "replay",
            id: &self.replay.meta.id,
            map,
            ticks: self.replay.last_tick,
            tick: start,
            tick_hz: TICK_HZ,
            time_limit_s,
            speed: self.speed,
            playing: self.playing,
            view: you.clone().unwrap_or_else(|| "full".into()),
            role: if you.is_some() { "player" } else { "spectator" },
            name: self
                .options
                .view
                .and_then(|a| match a {
                    AgentId::Opponent(i) => seated.opponents.get(i).cloned().flatten(),
                    AgentId::Robot(i) => seated.robots.get(i).cloned().flatten(),
                })
                .map(|s| s.name.to_string()),
            you,
            belief_every: BELIEF_EVERY,
            belief: self.belief,
            kinematics,
            protocol: 3,
            format: if self.options.compact {
                "compact"
            } else {
                "json"
            },
            limits: Limits {
                seeks_per_s: Some(SEEKS_PER_S),
                ..Limits::of(&self.state.registry.config)
            },
        };
        self.sock.text(rwire::welcome(&welcome)).await?;
        self.cursor = Some(cursor);
        self.job(None, 0, first).await?;
        self.next_step = Instant::now() + pace(self.speed).0;
        let shutdown = self.sock.shutdown().clone();
        loop {
            tokio::select! {
                biased;
                _ = shutdown.cancelled() => {
                    if self.sock.moved_off_webtransport() {
                        return Err(End::moved_off_webtransport());
                    }
                    return Err(End::going_away());
                }
                msg = self.sock.recv() => {
                    if let Some(c) = self.sock.read(msg, ReplayControl::parse).await? {
                        self.on_control(c).await?;
                    }
                }
                _ = tokio::time::sleep_until(self.next_seek), if self.pending_seek.is_some() => {
                    self.seek().await?;
                }
                _ = tokio::time::sleep_until(self.next_step), if self.playing && self.pending_seek.is_none() => {
                    self.step().await?;
                }
            }
        }
    }

    /// Shows the latest seek asked for.
    async fn seek(&mut self) -> Result<(), End> {
        let Some(tick) = self.pending_seek.take() else {
            return Ok(());
        };
        self.state.registry.history.opened(&self.replay);
        self.next_seek = Instant::now() + Duration::from_secs_f64(1.0 / SEEKS_PER_S);
        let how = self.show_options(true, false);
        let shown = self.job(Some(tick), 0, how).await?;
        self.carry = 0.0;
        self.next_step = Instant::now() + pace(self.speed).0;
        if self.playing && shown.at_end {
            self.playing = false;
            self.status().await?;
        }
        Ok(())
    }

    /// Plays the ticks due, and pauses at the end.
    async fn step(&mut self) -> Result<(), End> {
        let (period, ticks) = pace(self.speed);
        self.carry += ticks;
        let steps = self.carry.floor().max(1.0);
        self.carry = (self.carry - steps).max(0.0);
        let how = self.show_options(false, true);
        let shown = self.job(None, steps as u64, how).await?;
        // Never a burst to catch up: a slow pool plays slower.
        let now = Instant::now();
        self.next_step = (self.next_step + period).max(now);
        if shown.at_end {
            self.playing = false;
            self.status().await?;
        }
        Ok(())
    }

    async fn on_control(&mut self, control: ReplayControl) -> Result<(), End> {
        let last = self.replay.last_tick;
        match control {
            ReplayControl::Ping { t } => self.sock.text(common::pong(t)).await,
            ReplayControl::Play => {
                if !self.playing && self.pending_seek.is_none() && self.tick >= last {
                    // Play at the end starts again, as a video player does.
                    self.pending_seek = Some(0);
                }
                self.playing = true;
                self.next_step = Instant::now() + pace(self.speed).0;
                self.status().await
            }
            ReplayControl::Pause => {
                self.playing = false;
                self.status().await
            }
            ReplayControl::Speed { speed } => {
                self.speed = speed;
                self.carry = 0.0;
                self.next_step = self.next_step.min(Instant::now() + pace(speed).0);
                self.status().await
            }
            ReplayControl::Seek { tick } if tick > last => {
                let why = format!("tick: {tick} is past the replay's last tick, {last}");
                self.sock.strike(Refusal::MessageInvalid, &why).await
            }
            ReplayControl::Seek { tick } => {
                // Coalesced: a later seek replaces one not shown yet.
                self.pending_seek = Some(tick);
                Ok(())
            }
            ReplayControl::Belief { on } => {
                let was = self.belief;
                self.belief = on;
                if on && !was && !self.playing && self.pending_seek.is_none() {
                    // Paused: show this tick's belief now rather than at the next step.
                    let how = self.show_options(true, false);
                    self.job(None, 0, how).await?;
                }
                Ok(())
            }
        }
    }
}

/// Runs `work` on the blocking pool. A connection does not wait for it past the server's
/// shutdown (a first re-simulation of a long match takes seconds, and shutdown waits for
/// every connection to close).
async fn blocking<T: Send + 'static>(
    state: AppState,
    work: impl FnOnce() -> Result<T, String> + Send + 'static,
) -> Result<T, End> {
    let shutdown = state.registry.shutdown.clone();
    tokio::select! {
        done = off_workers(&state, "replaying the match", work) => done
            .map_err(|e| End::internal(e.message))?
            .map_err(End::internal),
        _ = shutdown.cancelled() => Err(End::going_away()),
    }
}
