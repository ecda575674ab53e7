//! What viewers of a match share ([`Hub`]), a spectator counted in it ([`SpectatorSeat`]),
//! and a player's connection's place at the match ([`Seat`]).

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use tokio::sync::{oneshot, watch};

use crate::game::view::{Frame, Summary};
use lasertag_core::sim::Physics;
use lasertag_core::sim::arena::Arena;

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
