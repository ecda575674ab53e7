//! The shell around the core: one tokio task per match, and the registry that finds them.
//!
//! A [`MatchHandle`] is the only way to reach a match: handlers send it a [`Request`] and await
//! the reply, so only the match's own task ever touches its [`World`] (no locks around a
//! world, no torn reads). A real-time match ticks on a 50 ms interval; a manual one advances
//! only when asked, in chunks between which it keeps answering other requests.

pub mod admission;
pub mod background;
pub mod delay;
pub mod encoded;
pub mod error;
mod handle;
pub mod hub;
pub mod matchmaking;
pub mod party;
pub mod policies;
pub mod queue;
pub mod record;
pub mod replay;
pub mod resume;
pub mod showcase;
mod task;
pub mod view;
pub mod work;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, RwLock, Weak};
use std::time::Duration;

use tokio::sync::watch;
use tokio_util::sync::CancellationToken;

use crate::access::{ClientKey, Owner};
use crate::config::Config;
use crate::game::admission::{NoRoom, Price};
use crate::maps::MapStore;
use crate::metrics::Metrics;
use lasertag_core::world::{FinishReason, World};
use view::MatchMeta;

pub use crate::access::{random_id, random_seed};
pub use error::MatchError;
pub use handle::MatchHandle;
pub use hub::{Hub, Seat, SeatLedger, SpectatorSeat};
pub use task::{
    Answer, Reading, Request, Resumed, ResumedSeat, TaskSettings, spawn_match, spawn_resumed,
};
pub use view::Sight;

type Matches = RwLock<BTreeMap<String, MatchHandle>>;

/// Everything the server shares between requests: its settings, metrics, the maps and the
/// running matches, and the signal that it is shutting down.
#[derive(Debug, Default)]
pub struct Registry {
    pub maps: RwLock<MapStore>,
    /// Trained robot teams (`policies`): the shipped ones, and those uploaded.
    pub policies: RwLock<policies::PolicyStore>,
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
    /// The path search robots' orders may take, server-wide and per client.
    pub work: work::WorkBudget,
    /// The seats each client holds over every match.
    pub seats: Arc<SeatLedger>,
    /// Claims of names, all clients together (`service::names`; made at the first claim,
    /// from `config`).
    pub name_claims: std::sync::Mutex<Option<crate::access::Bucket>>,
    /// Matches a restarted server is still rebuilding from the store (`resume`): requests
    /// for them are answered 503 with `Retry-After` rather than 404.
    resuming: RwLock<std::collections::BTreeSet<String>>,
    /// Whether a stop ends the running matches even though the store could resume them: a
    /// fleet node's own store is not where its matches would be resumed (`fleet`).
    ends_matches_on_stop: std::sync::atomic::AtomicBool,
    /// Held while a showcase starts, so that visitors who all find the showcases full start
    /// one more between them, not one each (`showcase::join_or_create`).
    pub showcase_starting: tokio::sync::Mutex<()>,
    /// Parties' waiting rooms (`party`).
    pub parties: party::Parties,
    /// People waiting to be matched with others (`queue`).
    pub queue: queue::Queue,
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
        let history = Arc::new(history);
        Arc::new(Registry {
            maps: RwLock::new(maps),
            policies: RwLock::new(policies::PolicyStore::shipped()),
            parties: party::Parties::new(&config, Some(history.clone())),
            queue: queue::Queue::new(&config),
            config,
            history,
            ..Registry::default()
        })
    }

    /// Starts a task for `world` and registers it, whatever the number of matches (the
    /// showcase's way in; requests go through [`Registry::try_start`]). Only the operator
    /// may change it.
    pub fn start(&self, world: World, meta: MatchMeta) -> MatchHandle {
        let mut matches = self.matches.write().unwrap_or_else(|e| e.into_inner());
        self.start_with(
            &mut matches,
            world,
            meta,
            Owner::default(),
            Price::default(),
            None,
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
        Ok(self.start_with(&mut matches, world, meta, owner, price, None))
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
            .uploaded_memory(None)
            + self
                .policies
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
        let disk = cfg.disk_budget_mb.saturating_mul(1_000_000);
        // The uploaded policies the store keeps take the disk as long as they are held.
        let held_disk = admitted.disk
            + self
                .policies
                .read()
                .unwrap_or_else(|e| e.into_inner())
                .uploaded_disk();
        if price.disk > 0 && held_disk + price.disk > disk {
            self.metrics.refuse(crate::metrics::Refusal::Budget);
            return Err(NoRoom::Disk {
                held: held_disk,
                asked: price.disk,
                budget: disk,
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
                .uploaded_memory(Some(client))
                + self
                    .policies
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

    /// Starts a match rebuilt from its record under its old id, owner and seats
    /// (`resume`): it was admitted before the restart, so no budget refuses it now.
    pub fn start_resumed(
        &self,
        world: World,
        meta: MatchMeta,
        owner: Owner,
        price: Price,
        resumed: Resumed,
    ) -> MatchHandle {
        let id = meta.id.clone();
        let mut matches = self.matches.write().unwrap_or_else(|e| e.into_inner());
        let handle = self.start_with(&mut matches, world, meta, owner, price, Some(resumed));
        drop(matches);
        self.done_resuming(&id);
        handle
    }

    /// Notes that the matches `ids` are being rebuilt (see [`Registry::is_resuming`]).
    pub fn resuming(&self, ids: &[String]) {
        let mut r = self.resuming.write().unwrap_or_else(|e| e.into_inner());
        r.extend(ids.iter().cloned());
    }

    /// `id` is back, or lost: no longer being rebuilt.
    pub fn done_resuming(&self, id: &str) {
        self.resuming
            .write()
            .unwrap_or_else(|e| e.into_inner())
            .remove(id);
    }

    /// Whether match `id` is being rebuilt from the store after a restart.
    pub fn is_resuming(&self, id: &str) -> bool {
        self.resuming
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .contains(id)
    }

    /// How many matches are still being rebuilt.
    pub fn resuming_count(&self) -> usize {
        self.resuming
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .len()
    }

    /// Whether matches left running in the store come back when a server starts on it.
    pub fn resumes_matches(&self) -> bool {
        self.history.store().is_some_and(|s| s.resumes())
    }

    /// Whether a stop suspends the running matches (the next server on the same store
    /// resumes them) rather than ending them.
    pub fn suspends_on_stop(&self) -> bool {
        self.resumes_matches() && !self.ends_matches_on_stop.load(Ordering::Relaxed)
    }

    /// From now on a stop ends the running matches (`server_shutdown`) rather than
    /// suspending them: for a fleet node, whose own store is not where they would be
    /// resumed.
    pub fn end_matches_on_stop(&self) {
        self.ends_matches_on_stop.store(true, Ordering::Relaxed);
    }

    fn start_with(
        &self,
        matches: &mut BTreeMap<String, MatchHandle>,
        world: World,
        meta: MatchMeta,
        owner: Owner,
        price: Price,
        resumed: Option<Resumed>,
    ) -> MatchHandle {
        let id = meta.id.clone();
        let clock = meta.clock;
        let owner = Arc::new(owner);
        let on_exit = {
            let matches: Weak<Matches> = Arc::downgrade(&self.matches);
            let id = id.clone();
            move || {
                if let Some(m) = matches.upgrade() {
                    m.write().unwrap_or_else(|e| e.into_inner()).remove(&id);
                }
            }
        };
        let settings = TaskSettings {
            reconnect_grace: self.config.reconnect_grace,
            finished_grace: self.config.finished_grace,
            abandoned_after: self.config.abandoned_after,
            idle_manual_after: self.config.idle_manual_after,
            max_players: self.config.max_players_per_match,
            join_hold: self.config.join_hold,
            max_holds: self.config.max_holds_per_address,
            seats: self.seats.clone(),
            max_seats: self.config.max_seats_per_address,
            both_sides: self.config.both_sides_per_address,
            tick_overrun: Duration::from_secs_f64(self.config.tick_overrun_ms / 1e3),
            max_command_work: self.config.max_command_work,
            metrics: self.metrics.clone(),
            history: self.history.clone(),
            owner: owner.clone(),
            policy: policies::policy_for(
                &self.policies.read().unwrap_or_else(|e| e.into_inner()),
                &world,
            ),
            on_exit: Box::new(on_exit),
        };
        let (tx, hub) = match resumed {
            Some(resumed) => spawn_resumed(world, meta, settings, resumed),
            None => spawn_match(world, meta, settings),
        };
        let handle = MatchHandle {
            id: id.clone(),
            owner,
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
    /// Stops every match by handing it to the server at `url`: each running match's viewers
    /// are told to go there (`moved`) and its task suspended, its record whole in the
    /// shared store; the caller then hands the matches' leases over (`Store::hand_over`).
    pub async fn begin_shutdown_moving_to(&self, url: &str) {
        for h in self.all() {
            if h.hub.frames.borrow().status != lasertag_core::world::MatchStatus::Finished {
                let _ = h.hub.moved.set(Some(url.to_string()));
            }
        }
        self.draining.cancel();
        self.shutdown.cancel();
        for h in self.all() {
            h.suspend().await;
        }
    }

    /// Stops every match: suspended, to be resumed by the next server on the same store
    /// ([`Registry::resumes_matches`]), or else ended with reason `server_shutdown`.
    pub async fn begin_shutdown(&self) {
        self.draining.cancel();
        self.shutdown.cancel();
        let suspend = self.suspends_on_stop();
        for h in self.all() {
            if suspend {
                h.suspend().await;
            } else {
                h.stop(FinishReason::ServerShutdown).await;
            }
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
