//! The shell around the core: one tokio task per match, and the registry that finds them.
//!
//! A [`MatchHandle`] is the only way to reach a match: handlers send it a [`Request`] and await
//! the reply, so only the match's own task ever touches its [`World`] (no locks around a
//! world, no torn reads). A real-time match ticks on a 50 ms interval; a manual one advances
//! only when asked, in chunks between which it keeps answering other requests.

pub mod showcase;
pub mod snapshot;
mod task;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, RwLock};
use std::time::Duration;

use tokio::sync::{mpsc, oneshot, watch};

use crate::maps::MapStore;
use crate::protocol::{self, Belief, Clock, Events, Joined, MatchState, MatchStats, MatchSummary};
use crate::sim::World;
use crate::sim::arena::Arena;
use crate::sim::world::{HumanInput, OpponentOrder};
use snapshot::Frame;

pub use task::{TaskSettings, spawn_match};

/// A request refused by a match, mapped to an HTTP status at the edge.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MatchError {
    #[error("{0}")]
    BadRequest(String),
    #[error("{0}")]
    NotFound(String),
    #[error("{0}")]
    Conflict(String),
    #[error("match {0} has ended")]
    Gone(String),
    #[error("{0}")]
    Unauthorized(String),
}

/// What a handler may ask of a match task.
#[derive(Debug)]
pub enum Request {
    Summary(oneshot::Sender<MatchSummary>),
    State(oneshot::Sender<MatchState>),
    /// One robot's belief (by index), or the team's merged one.
    Belief {
        robot: Option<usize>,
        reply: oneshot::Sender<Result<Belief, MatchError>>,
    },
    Events {
        since: u64,
        reply: oneshot::Sender<Events>,
    },
    Step {
        ticks: u64,
        reply: oneshot::Sender<Result<MatchState, MatchError>>,
    },
    Order {
        opponent: String,
        order: OpponentOrder,
        reply: oneshot::Sender<Result<(), MatchError>>,
    },
    Join {
        name: String,
        reply: oneshot::Sender<Result<Joined, MatchError>>,
    },
    Stats(oneshot::Sender<MatchStats>),
    /// A WebSocket connection wants to play the slot `token` belongs to.
    Connect {
        token: String,
        reply: oneshot::Sender<Result<Seat, MatchError>>,
    },
    /// A seated connection's latest keys (ignored unless `generation` is the slot's current one).
    Input {
        slot: usize,
        generation: u64,
        input: HumanInput,
    },
    /// End the match (it was deleted or the server is shutting down).
    Stop,
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

/// What viewers of a match share: the latest published frame, the arena (for line of
/// sight) and the count of spectators.
#[derive(Debug, Clone)]
pub struct Hub {
    pub frames: watch::Receiver<Arc<Frame>>,
    pub arena: Arc<Arena>,
    pub spectators: Arc<AtomicUsize>,
}

/// The way to one match's task.
#[derive(Debug, Clone)]
pub struct MatchHandle {
    pub id: String,
    /// Creation order, for stable listings.
    pub order: u64,
    pub clock: Clock,
    pub hub: Hub,
    tx: mpsc::Sender<Request>,
}

impl MatchHandle {
    async fn ask<T>(
        &self,
        make: impl FnOnce(oneshot::Sender<T>) -> Request,
    ) -> Result<T, MatchError> {
        let (reply, rx) = oneshot::channel();
        self.tx
            .send(make(reply))
            .await
            .map_err(|_| MatchError::Gone(self.id.clone()))?;
        rx.await.map_err(|_| MatchError::Gone(self.id.clone()))
    }

    pub async fn summary(&self) -> Result<MatchSummary, MatchError> {
        self.ask(Request::Summary).await
    }

    pub async fn state(&self) -> Result<MatchState, MatchError> {
        self.ask(Request::State).await
    }

    /// Robot `robot`'s own belief, or the team's merged view when `None`.
    pub async fn belief(&self, robot: Option<usize>) -> Result<Belief, MatchError> {
        self.ask(|reply| Request::Belief { robot, reply }).await?
    }

    pub async fn events(&self, since: u64) -> Result<Events, MatchError> {
        self.ask(|reply| Request::Events { since, reply }).await
    }

    pub async fn step(&self, ticks: u64) -> Result<MatchState, MatchError> {
        self.ask(|reply| Request::Step { ticks, reply }).await?
    }

    pub async fn order(&self, opponent: String, order: OpponentOrder) -> Result<(), MatchError> {
        self.ask(|reply| Request::Order {
            opponent,
            order,
            reply,
        })
        .await?
    }

    pub async fn join(&self, name: String) -> Result<Joined, MatchError> {
        self.ask(|reply| Request::Join { name, reply }).await?
    }

    pub async fn stats(&self) -> Result<MatchStats, MatchError> {
        self.ask(Request::Stats).await
    }

    pub async fn connect(&self, token: String) -> Result<Seat, MatchError> {
        self.ask(|reply| Request::Connect { token, reply }).await?
    }

    /// Forwards a player's keys; waits only for room in the task's queue.
    pub async fn input(&self, slot: usize, generation: u64, input: HumanInput) -> bool {
        self.tx
            .send(Request::Input {
                slot,
                generation,
                input,
            })
            .await
            .is_ok()
    }

    pub async fn stop(&self) {
        let _ = self.tx.send(Request::Stop).await;
    }
}

/// Settings of the server's matches that are not part of a match's own settings.
#[derive(Debug, Clone)]
pub struct GameSettings {
    /// How long a player who dropped may take to come back with the same token (30 s).
    pub reconnect_grace: Duration,
}

impl Default for GameSettings {
    fn default() -> Self {
        GameSettings {
            reconnect_grace: Duration::from_secs(30),
        }
    }
}

/// Everything the server shares between requests: the maps and the running matches.
#[derive(Debug, Default)]
pub struct Registry {
    pub maps: RwLock<MapStore>,
    pub settings: GameSettings,
    matches: RwLock<BTreeMap<String, MatchHandle>>,
    next_order: AtomicU64,
}

impl Registry {
    pub fn new(maps: MapStore) -> Arc<Registry> {
        Registry::with_settings(maps, GameSettings::default())
    }

    pub fn with_settings(maps: MapStore, settings: GameSettings) -> Arc<Registry> {
        Arc::new(Registry {
            maps: RwLock::new(maps),
            settings,
            ..Registry::default()
        })
    }

    /// Starts a task for `world` and registers it.
    pub fn start(&self, world: World, meta: protocol::MatchMeta) -> MatchHandle {
        let id = meta.id.clone();
        let clock = meta.clock;
        let (tx, hub) = spawn_match(
            world,
            meta,
            TaskSettings {
                reconnect_grace: self.settings.reconnect_grace,
            },
        );
        let handle = MatchHandle {
            id: id.clone(),
            order: self.next_order.fetch_add(1, Ordering::Relaxed),
            clock,
            hub,
            tx,
        };
        self.matches
            .write()
            .unwrap_or_else(|e| e.into_inner())
            .insert(id, handle.clone());
        handle
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
                h.stop().await;
                true
            }
            None => false,
        }
    }

    pub async fn stop_all(&self) {
        for h in self.all() {
            h.stop().await;
        }
    }
}

/// A fresh random identifier of `bytes` random bytes, hex-encoded (ids and secret tokens).
pub fn random_id(bytes: usize) -> String {
    let mut buf = vec![0u8; bytes];
    if getrandom::fill(&mut buf).is_err() {
        // The OS RNG failing is not something to limp on with predictable tokens.
        panic!("the operating system's random number generator failed");
    }
    buf.iter().map(|b| format!("{b:02x}")).collect()
}
