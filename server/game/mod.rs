//! The shell around the core: one tokio task per match, and the registry that finds them.
//!
//! A [`MatchHandle`] is the only way to reach a match: handlers send it a [`Request`] and await
//! the reply, so only the match's own task ever touches its [`World`] (no locks around a
//! world, no torn reads). A real-time match ticks on a 50 ms interval; a manual one advances
//! only when asked, in chunks between which it keeps answering other requests.

pub mod showcase;
mod task;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, RwLock};

use tokio::sync::{mpsc, oneshot};

use crate::maps::MapStore;
use crate::protocol::{self, Belief, Clock, Events, Joined, MatchState, MatchSummary};
use crate::sim::World;
use crate::sim::world::OpponentOrder;

pub use task::spawn_match;

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
}

/// What a handler may ask of a match task.
#[derive(Debug)]
pub enum Request {
    Summary(oneshot::Sender<MatchSummary>),
    State(oneshot::Sender<MatchState>),
    Belief(oneshot::Sender<Belief>),
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
    /// End the match (it was deleted or the server is shutting down).
    Stop,
}

/// The way to one match's task.
#[derive(Debug, Clone)]
pub struct MatchHandle {
    pub id: String,
    /// Creation order, for stable listings.
    pub order: u64,
    pub clock: Clock,
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

    pub async fn belief(&self) -> Result<Belief, MatchError> {
        self.ask(Request::Belief).await
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

    pub async fn stop(&self) {
        let _ = self.tx.send(Request::Stop).await;
    }
}

/// Everything the server shares between requests: the maps and the running matches.
#[derive(Debug, Default)]
pub struct Registry {
    pub maps: RwLock<MapStore>,
    matches: RwLock<BTreeMap<String, MatchHandle>>,
    next_order: AtomicU64,
}

impl Registry {
    pub fn new(maps: MapStore) -> Arc<Registry> {
        Arc::new(Registry {
            maps: RwLock::new(maps),
            ..Registry::default()
        })
    }

    /// Starts a task for `world` and registers it.
    pub fn start(&self, world: World, meta: protocol::MatchMeta) -> MatchHandle {
        let id = meta.id.clone();
        let clock = meta.clock;
        let tx = spawn_match(world, meta);
        let handle = MatchHandle {
            id: id.clone(),
            order: self.next_order.fetch_add(1, Ordering::Relaxed),
            clock,
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
