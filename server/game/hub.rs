//! What viewers of a match share ([`Hub`]), a spectator counted in it ([`SpectatorSeat`]),
//! a player's connection's place at the match ([`Seat`]), and the seats each client holds
//! over every match ([`SeatLedger`]).

use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, Weak};
use std::time::{Duration, Instant};

use tokio::sync::{oneshot, watch};
use tokio_util::sync::CancellationToken;

use crate::access::ClientKey;
use crate::game::view::{Frame, Summary};
use lasertag_core::sim::Physics;
use lasertag_core::sim::arena::Arena;

/// A spectator whose socket has been sending one message for this long does not read: at
/// the cap, it makes way for a newcomer.
pub const SPECTATOR_STALLED: Duration = Duration::from_secs(2);
/// Nor does one that has answered nothing (not even the socket's pings, every 2 s, which a
/// client answers as it reads) for this long: while a match is held back, or quiet, nothing
/// else would fill its buffers. Two pings and 1 s of round trip: a reader on a slow
/// network is not taken for one that stopped, and a newcomer at the cap waits seconds, not
/// a quarter of a minute, for a silent one's place.
pub const SPECTATOR_SILENT: Duration = Duration::from_secs(5);

/// A connection's place at a match: the seat it holds and the body it plays there.
#[derive(Debug)]
pub struct Seat {
    /// The task's number for the seat (what its inputs name).
    pub seat: usize,
    /// An opponent, or a robot of the team's pursuer slots.
    pub body: lasertag_core::sim::AgentId,
    pub name: String,
    pub generation: u64,
    /// Resolves, with the reason, when the connection must close: a newer connection with
    /// the same token took the seat, or the seat lapsed unplayed. Dropping it (the
    /// connection ended) tells the task that the player has gone.
    pub kicked: oneshot::Receiver<&'static str>,
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
    /// The spectators counted in `spectators`, to find those that do not read.
    pub watchers: Arc<Mutex<Vec<Weak<Watcher>>>>,
    /// Set when the match goes on on another server: its URL when known (a node that
    /// hands its matches over), none when the lobby must say (a lease that ran out).
    pub moved: Arc<std::sync::OnceLock<Option<String>>>,
    /// Encodings its readers share, each made once a tick (`game::encoded`).
    pub encoded: Arc<crate::game::encoded::EncodedCache>,
}

impl Hub {
    /// Counts one more spectator of `client` unless it watches `per_client` times already,
    /// or there are `max` spectators and none of them has stopped reading (one that has is
    /// told to go, and makes way at once); the count falls back when the returned guard is
    /// dropped. The per-client count keeps a few addresses from filling every place of a
    /// match: a visitor finds one while fewer than `max / per_client` addresses crowd it.
    pub fn add_spectator(
        &self,
        client: ClientKey,
        max: usize,
        per_client: usize,
    ) -> Result<SpectatorSeat, SpectatorsRefused> {
        let watching = {
            let mut watchers = self.watchers.lock().unwrap_or_else(|e| e.into_inner());
            watchers.retain(|w| w.strong_count() > 0);
            (watchers.iter().filter_map(Weak::upgrade))
                .filter(|w| w.client == client && !w.released.load(Ordering::Acquire))
                .count()
        };
        if watching >= per_client {
            return Err(SpectatorsRefused::Client {
                watching,
                max: per_client,
            });
        }
        if !self.count_one(max) {
            let stalled = {
                let watchers = self.watchers.lock().unwrap_or_else(|e| e.into_inner());
                watchers
                    .iter()
                    .filter_map(Weak::upgrade)
                    .find(|w| w.stalled())
            };
            let stalled = stalled.ok_or(SpectatorsRefused::Full { max })?;
            stalled.release(&self.spectators);
            if !self.count_one(max) {
                return Err(SpectatorsRefused::Full { max });
            }
        }
        let watcher = Arc::new(Watcher::of(client));
        self.watchers
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(Arc::downgrade(&watcher));
        Ok(SpectatorSeat {
            count: self.spectators.clone(),
            watcher,
        })
    }

    fn count_one(&self, max: usize) -> bool {
        self.spectators
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < max).then_some(n + 1)
            })
            .is_ok()
    }
}

/// Why a spectator was not counted in: its client watches the match as often as one may
/// (with how often), or every place is taken by spectators who read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SpectatorsRefused {
    #[error(
        "spectators: this address watches this match {watching} times already (at most {max} per address)"
    )]
    Client { watching: usize, max: usize },
    #[error("spectators: this match is at this server's limit of {max} spectators")]
    Full { max: usize },
}

/// What the hub knows of one spectator's socket: since when it has been sending one
/// message (a socket that does not read blocks there), when the client last sent
/// anything, and the signal to go.
#[derive(Debug)]
pub struct Watcher {
    sending_since: Mutex<Option<Instant>>,
    heard_at: Mutex<Instant>,
    /// Cancelled when the spectator must make way for a newcomer.
    pub dropped: CancellationToken,
    /// Set once its place in the count was given up (by [`Watcher::release`] or the drop).
    released: std::sync::atomic::AtomicBool,
    /// Whose socket it is.
    client: ClientKey,
}

impl Watcher {
    fn of(client: ClientKey) -> Watcher {
        Watcher {
            sending_since: Mutex::new(None),
            heard_at: Mutex::new(Instant::now()),
            dropped: CancellationToken::new(),
            released: Default::default(),
            client,
        }
    }

    /// The client sent something (a pong, a message): it reads.
    pub fn heard(&self) {
        *self.heard_at.lock().unwrap_or_else(|e| e.into_inner()) = Instant::now();
    }

    /// The socket starts (`true`) or has finished (`false`) sending a message.
    pub fn sending(&self, busy: bool) {
        *self.sending_since.lock().unwrap_or_else(|e| e.into_inner()) = busy.then(Instant::now);
    }

    fn stalled(&self) -> bool {
        let stuck = self
            .sending_since
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .is_some_and(|t| t.elapsed() >= SPECTATOR_STALLED);
        let silent = self
            .heard_at
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .elapsed()
            >= SPECTATOR_SILENT;
        !self.dropped.is_cancelled() && (stuck || silent)
    }

    /// Gives up its place in `count` (once) and tells its connection to go.
    fn release(&self, count: &AtomicUsize) {
        if !self.released.swap(true, Ordering::AcqRel) {
            count.fetch_sub(1, Ordering::AcqRel);
        }
        self.dropped.cancel();
    }
}

/// A spectator counted in its match's [`Hub`] for as long as it lives.
#[derive(Debug)]
pub struct SpectatorSeat {
    count: Arc<AtomicUsize>,
    pub watcher: Arc<Watcher>,
}

impl Drop for SpectatorSeat {
    fn drop(&mut self) {
        self.watcher.release(&self.count);
    }
}

/// Opponent slots each client (an IPv4 address, or an IPv6 /64) holds over every match of
/// the server, played or not: so that a few addresses cannot take every seat of the
/// matches people are invited to (the showcases among them).
#[derive(Debug, Default)]
pub struct SeatLedger(Mutex<HashMap<ClientKey, usize>>);

impl SeatLedger {
    /// One more seat of `client`, unless it holds `max`; `Err` with how many it holds.
    pub fn take(self: &Arc<Self>, client: ClientKey, max: usize) -> Result<LedgerSeat, usize> {
        let mut map = self.0.lock().unwrap_or_else(|e| e.into_inner());
        let n = map.entry(client).or_default();
        if *n >= max {
            return Err(*n);
        }
        *n += 1;
        Ok(LedgerSeat {
            ledger: self.clone(),
            client,
        })
    }
}

/// One seat in the [`SeatLedger`]; given back when dropped (the slot was freed, or its
/// match ended).
#[derive(Debug)]
pub struct LedgerSeat {
    ledger: Arc<SeatLedger>,
    client: ClientKey,
}

impl Drop for LedgerSeat {
    fn drop(&mut self) {
        let mut map = self.ledger.0.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(n) = map.get_mut(&self.client) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                map.remove(&self.client);
            }
        }
    }
}
