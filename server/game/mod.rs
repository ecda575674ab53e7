//! The shell around the core: one tokio task per match, and the registry that finds them.
//!
//! A [`MatchHandle`] is the only way to reach a match: handlers send it a [`Request`] and await
//! the reply, so only the match's own task ever touches its [`World`] (no locks around a
//! world, no torn reads). A real-time match ticks on a 50 ms interval; a manual one advances
//! only when asked, in chunks between which it keeps answering other requests.

pub mod admission;
pub mod delay;
mod handle;
pub mod record;
pub mod replay;
pub mod showcase;
mod task;
pub mod view;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, RwLock, Weak};
use std::time::Duration;

use tokio::sync::{oneshot, watch};
use tokio_util::sync::CancellationToken;

use crate::access::{ClientKey, Owner};
use crate::config::Config;
use crate::game::admission::{NoRoom, Price};
use crate::maps::MapStore;
use crate::metrics::Metrics;
use lasertag_core::sim::Physics;
use lasertag_core::sim::arena::Arena;
use lasertag_core::world::{FinishReason, HumanInput, InputError, World, WorldInput};
use view::{Frame, Joined, MatchMeta, Summary};

pub use crate::access::random_id;
pub use handle::MatchHandle;
pub use task::{Reading, TaskSettings, spawn_match};

/// Why a match refused a request (`http` turns each into a status).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MatchError {
    /// A change from outside the world refused (an unknown agent, an order it cannot take).
    #[error(transparent)]
    Input(#[from] InputError),
    /// A robot index the match does not have.
    #[error("{0}")]
    NoRobot(String),
    /// A request the match cannot take as it is (a name it cannot seat, …).
    #[error("{0}")]
    Invalid(String),
    /// Stepping asked of a match that runs in real time.
    #[error("match {id} runs in real time; {what} works only on manual-clock matches")]
    Realtime { id: String, what: &'static str },
    /// A step asked while another is running.
    #[error("match {0} is already stepping")]
    Stepping(String),
    #[error("match {0} has finished")]
    Finished(String),
    /// Every seat a person could take is taken (or the server's per-match limit is met).
    #[error("{0}")]
    Full(String),
    /// The asking client holds as much of the match as it may.
    #[error("{0}")]
    Quota(String),
    /// A token that names no player of the match.
    #[error("{0}")]
    NotAPlayer(String),
    #[error("match {0} has ended")]
    Gone(String),
}

/// Whether a reader may see a match's truth as it is now, or only as long ago as the match
/// holds it back (see [`delay`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sight {
    /// The owner, the operator, or the server itself.
    Live,
    /// Everybody else.
    Public,
}

/// What a match's task does with the match once it has done what was asked: reads it (the
/// caller's conversion, run on the task) or tells why it refused.
pub type Answer = Box<dyn FnOnce(Result<&mut Reading<'_>, MatchError>) + Send>;

/// What a handler may ask of a match task.
pub enum Request {
    /// Read the match as a reader with `sight` may see it.
    Read { sight: Sight, answer: Answer },
    /// One change from outside (an opponent's or a robot's order), applied at once.
    Apply {
        input: WorldInput,
        reply: oneshot::Sender<Result<(), MatchError>>,
    },
    /// A step of a manual-clock match: every input of `inputs` (all or none), then `ticks`
    /// ticks; the answer reads the match live once the last has run. `what` names the
    /// request in refusals (`step`, `act`).
    Step {
        inputs: Vec<WorldInput>,
        ticks: u64,
        what: &'static str,
        answer: Answer,
    },
    Join {
        name: String,
        /// Who asks (for the rule of one unplayed hold per client).
        client: Option<ClientKey>,
        reply: oneshot::Sender<Result<Joined, MatchError>>,
    },
    /// A WebSocket connection wants to play the slot `token` belongs to.
    Connect {
        token: String,
        reply: oneshot::Sender<Result<Seat, MatchError>>,
    },
    /// A seated connection's keys (ignored unless `generation` is the slot's current one):
    /// numbered ones are queued and applied one per tick; others hold until the next.
    Input {
        slot: usize,
        generation: u64,
        input: HumanInput,
        seq: Option<u64>,
    },
    /// End the match for this reason (deleted, or the server is shutting down) and its task.
    Stop(FinishReason),
}

impl Request {
    /// Whether answering it may change what listings show (seats, orders, steps).
    fn changes_listing(&self) -> bool {
        !matches!(self, Request::Input { .. } | Request::Read { .. })
    }

    /// Whether it counts as a client's activity (keys do not: a connected player is
    /// counted already).
    fn is_activity(&self) -> bool {
        !matches!(self, Request::Input { .. })
    }

    /// Whether it changes the match (what keeps a manual match alive).
    fn is_change(&self) -> bool {
        matches!(self, Request::Apply { .. } | Request::Step { .. })
    }
}

impl std::fmt::Debug for Request {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Request::Read { sight, .. } => f.debug_struct("Read").field("sight", sight).finish(),
            Request::Apply { input, .. } => f.debug_struct("Apply").field("input", input).finish(),
            Request::Step { ticks, what, .. } => f
                .debug_struct("Step")
                .field("what", what)
                .field("ticks", ticks)
                .finish(),
            Request::Join { name, .. } => f.debug_struct("Join").field("name", name).finish(),
            Request::Connect { .. } => f.write_str("Connect"),
            Request::Input { slot, seq, .. } => f
                .debug_struct("Input")
                .field("slot", slot)
                .field("seq", seq)
                .finish(),
            Request::Stop(reason) => f.debug_tuple("Stop").field(reason).finish(),
        }
    }
}

/// A connection's place at a match: the opponent slot it plays.
#[derive(Debug)]
pub struct Seat {
    pub slot: usize,
    pub opponent_id: String,
    pub name: String,
    pub generation: u64,
    /// Resolves when a newer connection with the same token takes the seat. Dropping it
    /// (the connection ended) tells the task that the player has gone.
    pub kicked: oneshot::Receiver<()>,
}

/// What viewers of a match share: the latest published frame, the one spectators may see,
/// the arena (for line of sight) and the count of spectators.
#[derive(Debug, Clone)]
pub struct Hub {
    /// The match as it is now (players filter it to their own line of sight).
    pub frames: watch::Receiver<Arc<Frame>>,
    /// What spectators see: `frames` again, or `delay_ticks` behind when people play.
    pub spectate: watch::Receiver<Arc<Frame>>,
    pub delay_ticks: u64,
    /// How its agents move (players are told how, and predict their own motion).
    pub physics: Arc<Physics>,
    /// The match's summary as of its latest frame (what listings show).
    pub summary: watch::Receiver<Arc<Summary>>,
    pub arena: Arc<Arena>,
    pub spectators: Arc<AtomicUsize>,
}

impl Hub {
    /// Counts one more spectator unless there are `max` already; the count falls back when
    /// the returned guard is dropped.
    pub fn add_spectator(&self, max: usize) -> Option<SpectatorSeat> {
        self.spectators
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < max).then_some(n + 1)
            })
            .ok()
            .map(|_| SpectatorSeat(self.spectators.clone()))
    }
}

/// A spectator counted in its match's [`Hub`] for as long as it lives.
#[derive(Debug)]
pub struct SpectatorSeat(Arc<AtomicUsize>);

impl Drop for SpectatorSeat {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::AcqRel);
    }
}

type Matches = RwLock<BTreeMap<String, MatchHandle>>;

/// Everything the server shares between requests: its settings, metrics, the maps and the
/// running matches, and the signal that it is shutting down.
#[derive(Debug, Default)]
pub struct Registry {
    pub maps: RwLock<MapStore>,
    pub config: Config,
    pub metrics: Metrics,
    /// Cancelled when the server starts shutting down.
    pub shutdown: CancellationToken,
    /// Cancelled when the server starts draining (before it shuts down): it takes no new
    /// matches, and the running ones may finish (see [`Registry::begin_drain`]).
    pub draining: CancellationToken,
    /// WebSocket connections open now (shutdown waits for it to reach 0).
    connections: watch::Sender<usize>,
    matches: Arc<Matches>,
    next_order: AtomicU64,
    /// Finished matches, for replay.
    pub history: Arc<replay::History>,
}

/// Counts an open WebSocket connection until dropped.
#[derive(Debug)]
pub struct ConnectionGuard(watch::Sender<usize>);

impl Drop for ConnectionGuard {
    fn drop(&mut self) {
        self.0.send_modify(|n| *n = n.saturating_sub(1));
    }
}

impl Registry {
    pub fn new(maps: MapStore) -> Arc<Registry> {
        Registry::with_config(maps, Config::default())
    }

    pub fn with_config(maps: MapStore, config: Config) -> Arc<Registry> {
        Registry::with_history(maps, config, replay::History::default())
    }

    /// A registry whose finished matches go to `history` (a store on disk, or memory).
    pub fn with_history(maps: MapStore, config: Config, history: replay::History) -> Arc<Registry> {
        Arc::new(Registry {
            maps: RwLock::new(maps),
            config,
            history: Arc::new(history),
            ..Registry::default()
        })
    }

    /// Starts a task for `world` and registers it, whatever the number of matches (the
    /// showcase's way in; requests go through [`Registry::try_start`]). Only the operator
    /// may change it.
    pub fn start(&self, world: World, meta: MatchMeta) -> MatchHandle {
        let mut matches = self.matches.write().unwrap_or_else(|e| e.into_inner());
        self.start_locked(
            &mut matches,
            world,
            meta,
            Owner::default(),
            Price::default(),
        )
    }

    /// Starts a match for `owner` unless the server holds `config.max_matches` already or
    /// the owner's client holds `config.max_matches_per_address`.
    pub fn try_start(
        &self,
        world: World,
        meta: MatchMeta,
        owner: Owner,
        price: Price,
    ) -> Result<MatchHandle, NoRoom> {
        let mut matches = self.matches.write().unwrap_or_else(|e| e.into_inner());
        self.room_in(&matches, owner.client)?;
        self.budget_in(&matches, price, owner.client)?;
        // Last, under the lock: a drain that began while this match was built keeps it out.
        if self.draining.is_cancelled() {
            return Err(NoRoom::Draining);
        }
        Ok(self.start_locked(&mut matches, world, meta, owner, price))
    }

    /// Whether `price` fits in what the server has left of its budgets, and in `client`'s
    /// share of them (see `Config`).
    pub fn has_budget(&self, price: Price, client: Option<ClientKey>) -> Result<(), NoRoom> {
        let matches = self.matches.read().unwrap_or_else(|e| e.into_inner());
        self.budget_in(&matches, price, client)
    }

    fn budget_in(
        &self,
        matches: &BTreeMap<String, MatchHandle>,
        price: Price,
        client: Option<ClientKey>,
    ) -> Result<(), NoRoom> {
        let cfg = &self.config;
        let admitted: Price = matches.values().map(|h| h.price).sum();
        let maps = self
            .maps
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .uploaded_memory(None);
        let memory = admitted.memory + maps + price.memory;
        if memory > cfg.memory_budget_mb * 1_000_000 {
            self.metrics.refuse(crate::metrics::Refusal::Budget);
            return Err(NoRoom::Memory {
                held: admitted.memory + maps,
                asked: price.memory,
                budget: cfg.memory_budget_mb * 1_000_000,
            });
        }
        if price.tick_ms > 0.0 && admitted.tick_ms + price.tick_ms > cfg.tick_budget_ms {
            self.metrics.refuse(crate::metrics::Refusal::Budget);
            return Err(NoRoom::Cpu {
                held_ms: admitted.tick_ms,
                asked_ms: price.tick_ms,
                budget_ms: cfg.tick_budget_ms,
            });
        }
        // Then the client's share (a server that is full says so first).
        if let Some(client) = client {
            let maps = self
                .maps
                .read()
                .unwrap_or_else(|e| e.into_inner())
                .uploaded_memory(Some(client));
            let held: Price = matches
                .values()
                .filter(|h| h.owner.client == Some(client))
                .map(|h| h.price)
                .sum();
            let memory = (cfg.memory_budget_mb as f64 * 1e6 * cfg.client_budget_share) as u64;
            let tick_ms = cfg.tick_budget_ms * cfg.client_budget_share;
            if held.memory + maps + price.memory > memory
                || (price.tick_ms > 0.0 && held.tick_ms + price.tick_ms > tick_ms)
            {
                self.metrics.refuse(crate::metrics::Refusal::ClientQuota);
                return Err(NoRoom::ClientBudget {
                    client,
                    held: Price {
                        memory: held.memory + maps,
                        ..held
                    },
                    asked: price,
                    memory,
                    tick_ms,
                });
            }
        }
        Ok(())
    }

    /// Whether a new match from `client` would be let in now (a cheap check before
    /// building one; [`Registry::try_start`] checks again).
    pub fn has_room(&self, client: Option<ClientKey>) -> Result<(), NoRoom> {
        let matches = self.matches.read().unwrap_or_else(|e| e.into_inner());
        self.room_in(&matches, client)
    }

    fn room_in(
        &self,
        matches: &BTreeMap<String, MatchHandle>,
        client: Option<ClientKey>,
    ) -> Result<(), NoRoom> {
        use crate::metrics::Refusal;
        if self.draining.is_cancelled() {
            return Err(NoRoom::Draining);
        }
        if matches.len() >= self.config.max_matches {
            self.metrics.refuse(Refusal::MatchesFull);
            return Err(NoRoom::Server(self.config.max_matches));
        }
        if let Some(client) = client {
            let held = matches
                .values()
                .filter(|h| h.owner.client == Some(client))
                .count();
            if held >= self.config.max_matches_per_address {
                self.metrics.refuse(Refusal::ClientQuota);
                return Err(NoRoom::Client {
                    client,
                    max: self.config.max_matches_per_address,
                });
            }
        }
        Ok(())
    }

    fn start_locked(
        &self,
        matches: &mut BTreeMap<String, MatchHandle>,
        world: World,
        meta: MatchMeta,
        owner: Owner,
        price: Price,
    ) -> MatchHandle {
        let id = meta.id.clone();
        let clock = meta.clock;
        let on_exit = {
            let matches: Weak<Matches> = Arc::downgrade(&self.matches);
            let id = id.clone();
            move || {
                if let Some(m) = matches.upgrade() {
                    m.write().unwrap_or_else(|e| e.into_inner()).remove(&id);
                }
            }
        };
        let (tx, hub) = spawn_match(
            world,
            meta,
            TaskSettings {
                reconnect_grace: self.config.reconnect_grace,
                finished_grace: self.config.finished_grace,
                abandoned_after: self.config.abandoned_after,
                idle_manual_after: self.config.idle_manual_after,
                max_players: self.config.max_players_per_match,
                join_hold: self.config.join_hold,
                max_holds: self.config.max_holds_per_address,
                tick_overrun: Duration::from_secs_f64(self.config.tick_overrun_ms / 1e3),
                metrics: self.metrics.clone(),
                history: self.history.clone(),
                on_exit: Box::new(on_exit),
            },
        );
        let handle = MatchHandle {
            id: id.clone(),
            owner: Arc::new(owner),
            price,
            order: self.next_order.fetch_add(1, Ordering::Relaxed),
            clock,
            hub,
            tx,
        };
        matches.insert(id, handle.clone());
        handle
    }

    /// Matches held now.
    pub fn len(&self) -> usize {
        self.matches.read().unwrap_or_else(|e| e.into_inner()).len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Counts a WebSocket connection until the guard is dropped.
    pub fn connection(&self) -> ConnectionGuard {
        self.connections.send_modify(|n| *n += 1);
        ConnectionGuard(self.connections.clone())
    }

    /// Resolves when no WebSocket connection is open.
    pub async fn connections_closed(&self) {
        let mut rx = self.connections.subscribe();
        let _ = rx.wait_for(|n| *n == 0).await;
    }

    /// Starts draining: no new match is let in (the showcase starts no new round), while
    /// the running ones go on and their clients keep playing and watching.
    pub fn begin_drain(&self) {
        self.draining.cancel();
    }

    /// Whether every match held has finished (nothing left for a drain to wait for).
    pub fn all_finished(&self) -> bool {
        self.all()
            .iter()
            .all(|h| h.hub.frames.borrow().status == lasertag_core::world::MatchStatus::Finished)
    }

    /// Starts shutting down: cancels [`Registry::shutdown`] (and [`Registry::draining`]) and
    /// ends every match with reason `server_shutdown` (their connections send `finished`
    /// and close).
    pub async fn begin_shutdown(&self) {
        self.draining.cancel();
        self.shutdown.cancel();
        for h in self.all() {
            h.stop(FinishReason::ServerShutdown).await;
        }
    }

    /// Refreshes the gauges that are read from the matches themselves.
    pub fn refresh_metrics(&self) {
        let (mut running, mut finished) = (0, 0);
        for h in self.all() {
            if h.hub.frames.borrow().status == lasertag_core::world::MatchStatus::Finished {
                finished += 1;
            } else {
                running += 1;
            }
        }
        let m = &self.metrics.matches;
        m.with_label_values(&["running"]).set(running);
        m.with_label_values(&["finished"]).set(finished);
    }

    pub fn get(&self, id: &str) -> Option<MatchHandle> {
        self.matches
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .get(id)
            .cloned()
    }

    /// Every match, oldest first.
    pub fn all(&self) -> Vec<MatchHandle> {
        let mut all: Vec<MatchHandle> = self
            .matches
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .values()
            .cloned()
            .collect();
        all.sort_by_key(|h| h.order);
        all
    }

    /// Unregisters a match and tells its task to end.
    pub async fn remove(&self, id: &str) -> bool {
        let handle = self
            .matches
            .write()
            .unwrap_or_else(|e| e.into_inner())
            .remove(id);
        match handle {
            Some(h) => {
                self.metrics
                    .matches_removed
                    .with_label_values(&["deleted"])
                    .inc();
                h.stop(FinishReason::Stopped).await;
                true
            }
            None => false,
        }
    }
}
