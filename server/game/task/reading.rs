//! [`Reading`]: a match as one reader may see it, lent to the reader's conversion on the
//! match's own task. What it offers follows the reader's [`Sight`]: the truth (frames,
//! beliefs, events) held back from the public while people play, the live world only to
//! those who may see it live.

use std::borrow::Cow;
use std::sync::Arc;

use super::MatchTask;
use crate::game::delay::{HeldBack, HeldBelief};
use crate::game::view::{Frame, MatchMeta, Stats, Summary};
use crate::game::{MatchError, Sight};
use lasertag_core::sim::AgentId;
use lasertag_core::world::{Event, InputError, MatchConfig, MatchStatus, RobotObservation};
use lasertag_core::world::{RobotOrderError, World};

/// A match as a reader with some [`Sight`] may see it (see the module docs).
pub struct Reading<'a> {
    task: &'a mut MatchTask,
    sight: Sight,
    /// The events logged before the step this answers (for a plain read: all of them).
    since: u64,
}

impl<'a> Reading<'a> {
    pub(super) fn new(task: &'a mut MatchTask, sight: Sight, since: u64) -> Reading<'a> {
        Reading { task, sight, since }
    }

    /// What is held back from this reader: nothing for the owner, nor once the match is
    /// over (then nothing is left to hide).
    fn held(&self) -> Option<&HeldBack> {
        match self.sight {
            Sight::Live => None,
            Sight::Public if self.task.world.status == MatchStatus::Finished => None,
            Sight::Public => self.task.held.as_ref(),
        }
    }

    pub fn meta(&self) -> &MatchMeta {
        &self.task.meta
    }

    pub fn config(&self) -> &MatchConfig {
        &self.task.config
    }

    /// The match as listings show it, now (nothing in it is held back).
    pub fn summary(&self) -> Summary {
        Summary::of(&self.task.world, &self.task.meta, &self.task.config)
    }

    /// How the task keeps up.
    pub fn stats(&self) -> Stats {
        self.task.stats()
    }

    /// The newest frame this reader may see: the world as it is now for a live reader
    /// (whatever changes what a frame shows publishes one), the one shown to spectators for
    /// the public.
    pub fn frame(&mut self) -> Arc<Frame> {
        if let Some(held) = self.held() {
            return held.shown().clone();
        }
        self.task.refresh_frame();
        self.task.frames.borrow().clone()
    }

    /// Robot `robot`'s belief as this reader may see it, or the team's merged one when
    /// `None`.
    pub fn belief(&self, robot: Option<usize>) -> Result<Cow<'_, HeldBelief>, MatchError> {
        let belief = match self.held() {
            Some(held) => held.belief(robot).map(Cow::Borrowed),
            None => HeldBelief::of(&self.task.world, robot).map(Cow::Owned),
        };
        belief.ok_or_else(|| {
            MatchError::NoRobot(format!(
                "robot: no robot r{} in this match (it has {})",
                robot.unwrap_or_default(),
                self.task.world.robots.len()
            ))
        })
    }

    /// The events after `since` that this reader may see, oldest first.
    pub fn events(&self, since: u64) -> &[Event] {
        let shown = self.held().map_or(u64::MAX, HeldBack::shown_seq);
        let events = self.task.world.events_since(since);
        let end = events.partition_point(|e| e.seq <= shown);
        &events[..end]
    }

    /// The events logged since the step this answers began (none for a plain read).
    pub fn stepped_events(&self) -> &[Event] {
        self.task.world.events_since(self.since)
    }

    /// The world as it is now, to a reader who may see it live.
    pub fn live(&self) -> Option<&World> {
        (self.sight == Sight::Live).then_some(&self.task.world)
    }

    /// What robot `robot` knows now. It is no frame's: whether a reader may have it while
    /// people play is the caller's rule (its owner only, until the match ends).
    pub fn observation(&self, robot: usize) -> Result<RobotObservation<'_>, MatchError> {
        self.task.world.observation(robot).ok_or_else(|| {
            MatchError::Input(InputError::Robot(RobotOrderError::UnknownRobot(
                AgentId::Robot(robot).to_string(),
            )))
        })
    }

    /// Whether the match has ended.
    pub fn finished(&self) -> bool {
        self.task.world.status == MatchStatus::Finished
    }
}
