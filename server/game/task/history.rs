//! How a match task feeds the history: the match's start (with what resumes it: owner and
//! seats, tokens hashed), its inputs about once a second (and its seats when they change),
//! and its end, handed to the store's writer without ever waiting on it (a full queue
//! means trying again at the next flush), and the finished match kept for replay. After its
//! end nothing more of the match goes to the store.

use std::time::{Duration, Instant, SystemTime};

use super::MatchTask;
use crate::game::replay::Replay;
use crate::store::codec::{StoredLive, StoredSettings};
use crate::store::{Ended, Write, results, unix_ms};
use lasertag_core::world::{FinishReason, MatchStatus};

/// How often a running match's inputs go to the store: what a crash may lose.
pub(super) const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// Ticks of play between a match's checkpoints (30 s): what a resume re-simulates at most,
/// besides a delayed view's delay. The store keeps the newest two, so that one is always at
/// least a delay old (a match whose delay is longer checkpoints once a delay).
pub const CHECKPOINT_EVERY_TICKS: u64 = 600;

impl MatchTask {
    /// What resumes the match besides its settings and inputs: owner and seats.
    fn live_record(&self) -> StoredLive {
        let owner = &self.settings.owner;
        StoredLive {
            owner: owner.token.map(|t| t.to_hex()),
            client: owner.client.map(|c| c.to_string()),
            reads_live: owner.reads_live,
            seats: self.stored_seats(),
            head_start_ticks: self.meta.head_start_ticks,
            people: self.people.stored(),
        }
    }

    /// Sends the match's start, unless the store has it.
    fn store_begin(&mut self) -> bool {
        if self.store.begun {
            return true;
        }
        let settings = StoredSettings::of(
            &self.world.config,
            self.meta.clock.stored(),
            self.meta.bots_joinable,
            self.meta.spectator_delay_ticks,
            self.meta.difficulty,
            self.meta.rated,
        );
        let begin = Write::Begin {
            id: self.meta.id.clone(),
            arena: self.world.arena.clone(),
            settings: Box::new(settings),
            live: Box::new(self.live_record()),
            started_at: self.started_at,
        };
        self.store.begun = self.settings.history.record(begin).is_ok();
        self.store.begun
    }

    /// Sends the inputs since the last flush and the tick reached, when a flush is due (or
    /// `now` is set).
    pub(super) fn store_flush(&mut self, force: bool) {
        if self.store.ended || (!force && self.store.last_flush.elapsed() < FLUSH_EVERY) {
            return;
        }
        self.store.last_flush = Instant::now();
        if !self.store_begin() {
            return;
        }
        let inputs = self.recording.unstored().to_vec();
        // `|` not `||`: the people's change is taken either way.
        let seats_changed = self.people.take_changed() | self.recording.seats_unstored();
        let names = seats_changed.then(|| self.recording.names());
        let live = seats_changed.then(|| Box::new(self.live_record()));
        let n = inputs.len();
        let append = Write::Append {
            id: self.meta.id.clone(),
            inputs,
            names,
            live,
            tick: self.world.tick,
        };
        if self.settings.history.record(append).is_ok() {
            self.recording.mark_stored(n);
            self.store_checkpoint();
        } else {
            tracing::warn!("the history's queue is full: this match's inputs wait a second");
        }
    }

    /// Sends a copy of the world to the store when a checkpoint is due: right after an
    /// append that took every input applied so far, so that the checkpoint's count of them
    /// says where in the record it stands. The copy is encoded on the writer's thread.
    fn store_checkpoint(&mut self) {
        let every = CHECKPOINT_EVERY_TICKS.max(self.meta.spectator_delay_ticks);
        let tick = self.world.tick;
        let due = match self.store.last_checkpoint {
            Some(last) => tick >= last + every,
            None => tick >= every,
        };
        if !due
            || self.world.status != MatchStatus::Running
            || !self.recording.unstored().is_empty()
        {
            return;
        }
        let checkpoint = Write::Checkpoint {
            id: self.meta.id.clone(),
            tick,
            applied: self.recording.recorded() as u64,
            keep_from: self.store.last_checkpoint.unwrap_or(0),
            world: Box::new(self.world.clone()),
            max_bytes: self.store.checkpoint_bytes,
        };
        if self.settings.history.record(checkpoint).is_ok() {
            self.store.last_checkpoint = Some(tick);
        }
    }

    /// Hands a finished match to the history, once: the last inputs and how it ended to
    /// the store, the replay to memory.
    pub(super) fn archive(&mut self) {
        if self.archived || self.world.status != MatchStatus::Finished {
            return;
        }
        self.archived = true;
        self.store_flush(true);
        // A recording that let go of its oldest orders is replayed from the store.
        let inputs = self.recording.inputs().unwrap_or_default().to_vec();
        let replay = Replay::of(
            &self.world,
            self.meta.clone(),
            self.world.arena.clone(),
            self.world.config.clone(),
            inputs,
            self.started_at,
        );
        let listed = replay.listed();
        let ended = Ended {
            ended_at: unix_ms(SystemTime::now()),
            ticks: self.world.tick,
            winner: self.world.winner.map(|w| match w {
                lasertag_core::world::Side::Robots => "robots",
                lasertag_core::world::Side::Opponents => "opponents",
            }),
            reason: replay.reason.map(FinishReason::name),
            players: self.people.kept(results::of(&self.world)),
            // Only an end by the rules rates anyone: a match stopped, abandoned or cut short
            // by the server says nothing about who was stronger.
            rated: self.meta.difficulty.filter(|_| {
                self.meta.rated
                    && matches!(
                        replay.reason,
                        Some(FinishReason::AllTagged | FinishReason::TimeLimit)
                    )
            }),
        };
        debug_assert_eq!(listed.ticks, ended.ticks);
        self.store.ended = true;
        if self.store.begun
            && self
                .settings
                .history
                .record(Write::Finish {
                    id: self.meta.id.clone(),
                    ended,
                })
                .is_err()
        {
            tracing::warn!("the history's queue is full: the match stays incomplete there");
        }
        if self.recording.inputs().is_some() {
            self.settings.history.keep(replay);
        }
    }
}
