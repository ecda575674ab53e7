//! What a planner reads and answers: the team's view of its robots this tick, what the
//! robots know besides (their trackers, what they heard), and each robot's orders.

use std::sync::Arc;

use crate::radio::Message;
use crate::sim::sensors::Detection;
use crate::sim::{Motion, Pose};
use crate::tracker::Tracker;

/// What the team may know about one robot this tick.
#[derive(Debug, Clone, Copy)]
pub struct RobotView<'a> {
    /// The robot's own estimate of its pose (not the truth).
    pub pose: Pose,
    /// How unsure it is of that estimate: the std-dev of its localiser's particle positions
    /// (m; 0 when localisation is off, which is no claim of certainty, only of no knowledge).
    pub spread: f32,
    pub frozen: bool,
    /// True when its tag device has cooled down.
    pub can_fire: bool,
    pub scan: &'a [f32],
    pub detections: &'a [Detection],
    /// True when this robot's shot tagged an opponent this tick (the device reports hits).
    pub hit: bool,
    /// Driven from outside (a person or an API client): the team plans nothing for it, and
    /// the coordinated planner counts it as a teammate that has chosen first (what lies
    /// ahead of it is claimed).
    pub outside: bool,
}

/// What the team knows this tick.
#[derive(Debug, Clone)]
pub struct TeamView<'a> {
    pub tick: u64,
    pub robots: Vec<RobotView<'a>>,
}

/// One robot's orders for the next tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RobotCommand {
    pub motion: Motion,
    pub tag: bool,
    /// Where its planner is sending it (shown in the state), if anywhere.
    pub goal: Option<Pose>,
}

/// What the robots know when they plan, besides their own sensing: their tracker(s) and,
/// with an imperfect radio, what each heard from its teammates.
#[derive(Debug, Clone, Copy)]
pub struct Knowledge<'a> {
    pub(super) trackers: &'a [Tracker],
    /// `None`: a perfect radio, so teammates' plans are read directly (shared memory).
    pub(super) heard: Option<&'a [Vec<Option<Arc<Message>>>]>,
    /// `requests[i]`: teammates whose message of this tick asked robot `i` to step aside.
    pub(super) requests: &'a [Vec<usize>],
}

impl<'a> Knowledge<'a> {
    /// The centralised team: one tracker, plans shared.
    pub fn shared(tracker: &'a Tracker) -> Knowledge<'a> {
        Knowledge {
            trackers: std::slice::from_ref(tracker),
            heard: None,
            requests: &[],
        }
    }

    /// Robot `i`'s tracker (the shared one when there is only one).
    pub fn tracker(&self, i: usize) -> &'a Tracker {
        &self.trackers[i.min(self.trackers.len() - 1)]
    }

    /// Whether teammates' plans are read directly (a perfect radio).
    pub fn shared_memory(&self) -> bool {
        self.heard.is_none()
    }

    /// The last message robot `i` heard from robot `j` (always `None` with shared memory).
    pub fn heard(&self, i: usize, j: usize) -> Option<&'a Message> {
        self.heard
            .and_then(|h| h.get(i))
            .and_then(|row| row.get(j))
            .and_then(|m| m.as_deref())
    }

    /// Teammates that asked robot `i` this tick to step off their path.
    pub fn yield_requests(&self, i: usize) -> &'a [usize] {
        self.requests.get(i).map_or(&[], |v| v.as_slice())
    }
}

crate::checkpoint::plain_struct!(RobotCommand { motion, tag, goal });
