//! Everything that changes a match from outside, as one type: a match is a function of its
//! map, its settings, its seed and the [`WorldInput`]s applied between its ticks, so a log
//! of them (with the tick each was applied at) replays it exactly.
//!
//! The shell applies every outside change through [`World::apply`] and records what it
//! applied; a replay applies the same inputs at the same ticks.

use super::*;

/// One change from outside, applied between two ticks.
#[derive(Debug, Clone, PartialEq)]
pub enum WorldInput {
    /// A person's keys for the opponent in `slot`.
    Keys { slot: usize, input: HumanInput },
    /// An order for an API-driven opponent.
    Opponent { slot: usize, order: OpponentOrder },
    /// An order for a robot driven from outside.
    Robot { robot: usize, order: RobotOrder },
    /// A person named `name` takes the opponent in `slot` (a bot there is kept aside).
    Seat { slot: usize, name: String },
    /// The person leaves `slot` (a bot kept aside comes back).
    Unseat { slot: usize, name: String },
    /// A person named `name` takes the seat of robot `robot` (one of the team's pursuer
    /// slots, which the team's planner drives while it is free); it stands still until
    /// their keys come, as [`WorldInput::RobotKeys`].
    SeatRobot { robot: usize, name: String },
    /// A person's keys for robot `robot`, a pursuer slot: its drive order, and with the
    /// trigger pulled the tick their screen showed.
    RobotKeys { robot: usize, input: HumanInput },
    /// The person leaves robot `robot`'s seat: the team's planner drives it again.
    UnseatRobot { robot: usize, name: String },
    /// The person in `by`'s seat, named `name`, marks `at` for their side (nothing in the
    /// world changes; the log carries an [`EventKind::Mark`]).
    Mark {
        by: AgentId,
        name: String,
        at: Point2<f32>,
        kind: MarkKind,
    },
    /// The match ends from outside.
    End(FinishReason),
}

/// Why an input was refused (nothing changed).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputError {
    #[error(transparent)]
    Opponent(#[from] OrderError),
    #[error(transparent)]
    Robot(#[from] RobotOrderError),
    #[error("no opponent slot {0} takes keys")]
    NotHuman(usize),
    #[error("no opponent slot {0} in this match")]
    NoSlot(usize),
    #[error("robot {0} is not a seat for a person (the match's pursuer_slots)")]
    NoRobotSeat(usize),
    /// Only robots' orders apply all or none (`World::apply_all`).
    #[error("only robots' orders apply all or none")]
    NotAllOrNone,
    #[error("a mark must name a point inside the arena")]
    MarkOutside,
    #[error("no agent {0} in this match")]
    NoAgent(AgentId),
}

impl World {
    /// Applies one change from outside (see the module docs).
    pub fn apply(&mut self, input: &WorldInput) -> Result<(), InputError> {
        match input {
            WorldInput::Keys { slot, input } => {
                if self.set_human_input(*slot, *input) {
                    Ok(())
                } else {
                    Err(InputError::NotHuman(*slot))
                }
            }
            WorldInput::Opponent { slot, order } => Ok(self.order_opponent(*slot, order.clone())?),
            WorldInput::Robot { robot, order } => Ok(self.order_robot(*robot, order.clone())?),
            WorldInput::Seat { slot, name } => {
                let o = self
                    .opponents
                    .get_mut(*slot)
                    .ok_or(InputError::NoSlot(*slot))?;
                if let Control::Bot(_) = o.control {
                    let bot =
                        std::mem::replace(&mut o.control, Control::Human(HumanInput::default()));
                    if let Control::Bot(bot) = bot {
                        o.bench = Some(bot);
                    }
                }
                self.log_player(AgentId::Opponent(*slot), name.clone(), true);
                Ok(())
            }
            WorldInput::Unseat { slot, name } => {
                let o = self
                    .opponents
                    .get_mut(*slot)
                    .ok_or(InputError::NoSlot(*slot))?;
                match o.bench.take() {
                    Some(bot) => o.control = Control::Bot(bot),
                    None => {
                        if let Control::Human(keys) = &mut o.control {
                            *keys = HumanInput::default();
                        }
                    }
                }
                self.log_player(AgentId::Opponent(*slot), name.clone(), false);
                Ok(())
            }
            WorldInput::RobotKeys { robot, input } => self.robot_keys(*robot, *input),
            WorldInput::SeatRobot { robot, name } => {
                if !self.robot_seat(*robot) {
                    return Err(InputError::NoRobotSeat(*robot));
                }
                self.robots[*robot].seated = true;
                self.order_robot(*robot, RobotOrder::Stop)?;
                self.log_player(AgentId::Robot(*robot), name.clone(), true);
                Ok(())
            }
            WorldInput::UnseatRobot { robot, name } => {
                if !self.robot_seat(*robot) {
                    return Err(InputError::NoRobotSeat(*robot));
                }
                self.order_robot(*robot, RobotOrder::Stop)?;
                self.robots[*robot].seated = false;
                self.log_player(AgentId::Robot(*robot), name.clone(), false);
                Ok(())
            }
            WorldInput::Mark { by, name, at, kind } => {
                let exists = match *by {
                    AgentId::Robot(i) => i < self.robots.len(),
                    AgentId::Opponent(i) => i < self.opponents.len(),
                };
                if !exists {
                    return Err(InputError::NoAgent(*by));
                }
                let inside = at.x.is_finite()
                    && at.y.is_finite()
                    && (0.0..=self.arena.width()).contains(&at.x)
                    && (0.0..=self.arena.height()).contains(&at.y);
                if !inside {
                    return Err(InputError::MarkOutside);
                }
                self.push(EventKind::Mark {
                    by: *by,
                    name: name.clone(),
                    at: *at,
                    kind: *kind,
                });
                Ok(())
            }
            WorldInput::End(reason) => {
                self.end(*reason);
                Ok(())
            }
        }
    }

    /// Applies every input or none: robots' orders only (each replaces its robot's order,
    /// so a refused one puts back the orders before it), as an environment step gives them.
    pub fn apply_all(&mut self, inputs: &[WorldInput]) -> Result<(), InputError> {
        if !inputs.iter().all(|i| matches!(i, WorldInput::Robot { .. })) {
            return Err(InputError::NotAllOrNone);
        }
        let before: Vec<_> = self.robots.iter().map(|r| r.api.clone()).collect();
        for input in inputs {
            if let Err(e) = self.apply(input) {
                for (robot, api) in self.robots.iter_mut().zip(before) {
                    robot.api = api;
                }
                return Err(e);
            }
        }
        Ok(())
    }

    /// The keys the person in `slot` holds now, if a person plays it.
    pub fn human_input(&self, slot: usize) -> Option<HumanInput> {
        match self.opponents.get(slot).map(|o| &o.control) {
            Some(Control::Human(keys)) => Some(*keys),
            _ => None,
        }
    }
}
