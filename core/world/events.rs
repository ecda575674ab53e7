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
    /// A person pointed at `at` for their side (`kind`: what they mean). It changes
    /// nothing in the world: the log carries it so that their teammates see it, spectators
    /// as late as the rest, and replays draw it.
    Mark {
        by: AgentId,
        name: String,
        at: Point2<f32>,
        kind: MarkKind,
    },
}

/// What a person's mark says about the point it names.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MarkKind {
    /// A robot was seen there.
    Robot,
    /// Go there.
    Go,
    /// Keep away.
    Danger,
}

impl MarkKind {
    pub const ALL: [MarkKind; 3] = [MarkKind::Robot, MarkKind::Go, MarkKind::Danger];

    pub fn name(self) -> &'static str {
        match self {
            MarkKind::Robot => "robot",
            MarkKind::Go => "go",
            MarkKind::Danger => "danger",
        }
    }

    pub fn parse(name: &str) -> Option<MarkKind> {
        MarkKind::ALL.into_iter().find(|k| k.name() == name)
    }
}

impl Plain for MarkKind {
    fn save(&self, w: &mut crate::checkpoint::Writer) {
        (*self as u8).save(w);
    }
    fn load(r: &mut crate::checkpoint::Reader) -> Result<Self, CheckpointError> {
        MarkKind::ALL
            .get(u8::load(r)? as usize)
            .copied()
            .ok_or(CheckpointError::BadValue("a mark kind"))
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    pub seq: u64,
    pub tick: u64,
    pub kind: EventKind,
}

crate::checkpoint::plain_struct!(Event { seq, tick, kind });

impl Plain for Side {
    fn save(&self, w: &mut crate::checkpoint::Writer) {
        (*self as u8).save(w);
    }
    fn load(r: &mut crate::checkpoint::Reader) -> Result<Self, CheckpointError> {
        match u8::load(r)? {
            0 => Ok(Side::Robots),
            1 => Ok(Side::Opponents),
            _ => Err(CheckpointError::BadValue("a side")),
        }
    }
}

impl Plain for MatchStatus {
    fn save(&self, w: &mut crate::checkpoint::Writer) {
        (*self as u8).save(w);
    }
    fn load(r: &mut crate::checkpoint::Reader) -> Result<Self, CheckpointError> {
        match u8::load(r)? {
            0 => Ok(MatchStatus::Running),
            1 => Ok(MatchStatus::Finished),
            _ => Err(CheckpointError::BadValue("a match status")),
        }
    }
}

impl Plain for FinishReason {
    fn save(&self, w: &mut crate::checkpoint::Writer) {
        (*self as u8).save(w);
    }
    fn load(r: &mut crate::checkpoint::Reader) -> Result<Self, CheckpointError> {
        FinishReason::ALL
            .get(u8::load(r)? as usize)
            .copied()
            .ok_or(CheckpointError::BadValue("a finish reason"))
    }
}

impl Plain for EventKind {
    fn save(&self, w: &mut crate::checkpoint::Writer) {
        match self {
            EventKind::Shot { by, hit } => {
                0u8.save(w);
                by.save(w);
                hit.save(w);
            }
            EventKind::Tag { by, target } => {
                1u8.save(w);
                by.save(w);
                target.save(w);
            }
            EventKind::RobotTagged { by, target } => {
                2u8.save(w);
                by.save(w);
                target.save(w);
            }
            EventKind::RoleSplit { role, from } => {
                3u8.save(w);
                role.save(w);
                from.save(w);
            }
            EventKind::RoleMerge { role, from, count } => {
                4u8.save(w);
                role.save(w);
                from.save(w);
                count.save(w);
            }
            EventKind::PlayerJoined { agent, name } => {
                5u8.save(w);
                agent.save(w);
                name.save(w);
            }
            EventKind::PlayerLeft { agent, name } => {
                6u8.save(w);
                agent.save(w);
                name.save(w);
            }
            EventKind::Finished { winner, reason } => {
                7u8.save(w);
                winner.save(w);
                reason.save(w);
            }
            EventKind::Mark { by, name, at, kind } => {
                8u8.save(w);
                by.save(w);
                name.save(w);
                at.x.save(w);
                at.y.save(w);
                kind.save(w);
            }
        }
    }
    fn load(r: &mut crate::checkpoint::Reader) -> Result<Self, CheckpointError> {
        Ok(match u8::load(r)? {
            0 => EventKind::Shot {
                by: Plain::load(r)?,
                hit: Plain::load(r)?,
            },
            1 => EventKind::Tag {
                by: Plain::load(r)?,
                target: Plain::load(r)?,
            },
            2 => EventKind::RobotTagged {
                by: Plain::load(r)?,
                target: Plain::load(r)?,
            },
            3 => EventKind::RoleSplit {
                role: Plain::load(r)?,
                from: Plain::load(r)?,
            },
            4 => EventKind::RoleMerge {
                role: Plain::load(r)?,
                from: Plain::load(r)?,
                count: Plain::load(r)?,
            },
            5 => EventKind::PlayerJoined {
                agent: Plain::load(r)?,
                name: Plain::load(r)?,
            },
            6 => EventKind::PlayerLeft {
                agent: Plain::load(r)?,
                name: Plain::load(r)?,
            },
            7 => EventKind::Finished {
                winner: Plain::load(r)?,
                reason: Plain::load(r)?,
            },
            8 => EventKind::Mark {
                by: Plain::load(r)?,
                name: Plain::load(r)?,
                at: Point2::new(Plain::load(r)?, Plain::load(r)?),
                kind: Plain::load(r)?,
            },
            _ => return Err(CheckpointError::BadValue("an event")),
        })
    }
}
