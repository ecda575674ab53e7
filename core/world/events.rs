//! What happens in a match, as the event log records it: sides, statuses, why a match
//! ended, and every event kind.

use super::*;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    Robots,
    Opponents,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MatchStatus {
    Running,
    Finished,
}

/// Why a match ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FinishReason {
    AllTagged,
    TimeLimit,
    /// Ended from outside (deleted through the API).
    Stopped,
    /// The server is shutting down: nobody won.
    ServerShutdown,
    /// Nobody took part for too long (the server's clean-up): nobody won.
    Abandoned,
    /// Its ticks took longer than the server could give them, again and again (the
    /// server's protection of its other matches): nobody won.
    Overloaded,
    /// The server that ran it stopped, and the next could not rebuild it from its record
    /// (a damaged or foreign store): nobody won.
    Lost,
}

impl FinishReason {
    /// Every reason, in declaration order.
    pub const ALL: [FinishReason; 7] = [
        FinishReason::AllTagged,
        FinishReason::TimeLimit,
        FinishReason::Stopped,
        FinishReason::ServerShutdown,
        FinishReason::Abandoned,
        FinishReason::Overloaded,
        FinishReason::Lost,
    ];

    /// Its name, as the API, the history and the logs spell it.
    pub fn name(self) -> &'static str {
        match self {
            FinishReason::AllTagged => "all_tagged",
            FinishReason::TimeLimit => "time_limit",
            FinishReason::Stopped => "stopped",
            FinishReason::ServerShutdown => "server_shutdown",
            FinishReason::Abandoned => "abandoned",
            FinishReason::Overloaded => "overloaded",
            FinishReason::Lost => "lost",
        }
    }

    /// Who wins a match that ends for this reason: the robots by tagging every opponent;
    /// the opponents by lasting (the time limit) or when the match is stopped before they
    /// were all caught; nobody when the server shuts down or abandons it.
    pub fn winner(self) -> Option<Side> {
        match self {
            FinishReason::AllTagged => Some(Side::Robots),
            FinishReason::TimeLimit | FinishReason::Stopped => Some(Side::Opponents),
            FinishReason::ServerShutdown
            | FinishReason::Abandoned
            | FinishReason::Overloaded
            | FinishReason::Lost => None,
        }
    }
}

/// Points within a tick where [`World::step_marked`] calls its observer, so that the shell
/// can time the team's halves without the core reading a clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepMark {
    /// The tracker's update is about to start.
    Tracker,
    /// The tracker is done; the planner is about to start.
    Planner,
    /// The planner is done.
    Planned,
}

#[derive(Debug, Clone, PartialEq)]
pub enum EventKind {
    /// A tag device fired; `hit` is the agent it hit, if any.
    Shot {
        by: AgentId,
        hit: Option<AgentId>,
    },
    /// A robot tagged an opponent, eliminating it.
    Tag {
        by: AgentId,
        target: AgentId,
    },
    /// An opponent tagged a robot, freezing it.
    RobotTagged {
        by: AgentId,
        target: AgentId,
    },
    /// The tracker split role `role` off role `from` for one newly seen opponent.
    RoleSplit {
        role: u64,
        from: u64,
    },
    /// The tracker merged role `from` into `role`, which now stands for `count` opponents.
    RoleMerge {
        role: u64,
        from: u64,
        count: u32,
    },
    /// A person took `agent`'s seat: an opponent slot, or a robot of the team
    /// (`MatchConfig::pursuer_slots`).
    PlayerJoined {
        agent: AgentId,
        name: String,
    },
    PlayerLeft {
        agent: AgentId,
        name: String,
    },
    Finished {
        winner: Option<Side>,
        reason: FinishReason,
    },
}

#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    pub seq: u64,
    pub tick: u64,
    pub kind: EventKind,
}
