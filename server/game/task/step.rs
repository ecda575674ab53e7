//! Manual steps (`step`, and `act` for robots driven from outside): inputs applied all or
//! none, then ticks run in chunks by the task's loop, then the answer reads the match.

use std::sync::atomic::Ordering;

use super::{Answer, MatchTask, PendingStep, Reading};
use crate::game::error::MatchError;
use crate::game::view::Sight;
use lasertag_core::world::{MatchStatus, WorldInput};

impl MatchTask {
    /// Applies every input or none, then runs `ticks` like a manual step; the answer goes
    /// out when the last tick has run.
    pub(super) fn begin_step(
        &mut self,
        inputs: Vec<WorldInput>,
        ticks: u64,
        what: &'static str,
        answer: Answer,
        realtime: bool,
        pending: &mut Option<PendingStep>,
    ) {
        let id = &self.meta.id;
        if realtime {
            return answer(Err(MatchError::Realtime {
                id: id.clone(),
                what,
            }));
        }
        if pending.is_some() {
            return answer(Err(MatchError::Stepping(id.clone())));
        }
        if let Err(full) = self.recording.room_for(&inputs) {
            return answer(Err(full.into()));
        }
        let searches = self.budget_routes(&inputs);
        let world = &mut self.world;
        if let Err(e) = super::off_the_workers(searches, || world.apply_all(&inputs)) {
            return answer(Err(MatchError::Input(e)));
        }
        for input in inputs {
            self.recording.note(&self.world, input);
        }
        let since = self.world.events().len() as u64;
        *pending = Some(PendingStep {
            remaining: ticks,
            unpublished: 0,
            since,
            answer,
        });
    }

    /// After ticks of a manual step: publishes the frame when someone may be watching (a
    /// spectator, a player, a held-back view) or the match has finished; otherwise only
    /// notes that the last frame is behind. An environment stepping thousands of times a
    /// second has nobody watching, and a frame costs about as much as an observation; the
    /// state (`refresh_frame`) and housekeeping catch up.
    pub(super) fn publish_stepped(&mut self) {
        let watched = self.held.is_some()
            || self.spectators.load(Ordering::Relaxed) > 0
            || self.players.iter().any(Option::is_some);
        if watched || self.world.status == MatchStatus::Finished {
            self.publish();
        } else {
            self.frame_stale = true;
        }
    }

    /// Publishes the frame of the world now if the last one is behind it.
    pub(super) fn refresh_frame(&mut self) {
        if self.frame_stale {
            self.publish();
        }
    }

    /// Sends a finished manual step its answer: the match read live, with the events since
    /// the step began.
    pub(super) fn answer_step(&mut self, step: PendingStep) {
        (step.answer)(Ok(&mut Reading::new(self, Sight::Live, step.since)));
    }
}
