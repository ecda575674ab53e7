//! Robots driven from outside: orders, observations and environment steps, answered by the
//! match task (the one place that mutates the world).

use std::sync::atomic::Ordering;

use tokio::sync::oneshot;

use super::{MatchTask, PendingStep, StepAnswer};
use crate::game::{MatchError, Sight};
use crate::protocol::robots::{self, ActResponse, Observation};
use lasertag_core::sim::AgentId;
use lasertag_core::world::{InputError, MatchStatus, RobotOrder, RobotOrderError, WorldInput};

impl MatchTask {
    /// Robot `robot`'s new order, from the next tick on.
    pub(super) fn order_robot(
        &mut self,
        robot: usize,
        order: RobotOrder,
    ) -> Result<(), MatchError> {
        self.apply(WorldInput::Robot { robot, order })
            .map_err(input_error)
    }

    /// What robot `robot` knows now.
    pub(super) fn observe(&self, robot: usize) -> Result<Observation, MatchError> {
        self.world
            .observation(robot)
            .map(|o| robots::observation(&o))
            .ok_or_else(|| {
                order_error(RobotOrderError::UnknownRobot(
                    AgentId::Robot(robot).to_string(),
                ))
            })
    }

    /// Applies every order or none, then runs `ticks` like a manual step; the answer goes
    /// out when the last tick has run.
    pub(super) fn act(
        &mut self,
        orders: Vec<(usize, RobotOrder)>,
        ticks: u64,
        realtime: bool,
        pending: &mut Option<PendingStep>,
        reply: oneshot::Sender<Result<ActResponse, MatchError>>,
    ) {
        let id = &self.meta.id;
        if realtime {
            let _ = reply.send(Err(MatchError::Conflict(format!(
                "match {id} runs in real time; act works only on manual-clock matches"
            ))));
            return;
        }
        if pending.is_some() {
            let _ = reply.send(Err(MatchError::Conflict(format!(
                "match {id} is already stepping"
            ))));
            return;
        }
        // Every order is checked on a copy of the robots' orders first: all apply, or none.
        let before: Vec<_> = self.world.robots.iter().map(|r| r.api.clone()).collect();
        for (robot, order) in &orders {
            if let Err(e) = self.world.order_robot(*robot, order.clone()) {
                for (r, api) in self.world.robots.iter_mut().zip(before) {
                    r.api = api;
                }
                let _ = reply.send(Err(order_error(e)));
                return;
            }
        }
        for (robot, order) in orders {
            self.recording
                .note(&self.world, WorldInput::Robot { robot, order });
        }
        let since = self.world.events().len() as u64;
        *pending = Some(PendingStep {
            remaining: ticks,
            unpublished: 0,
            answer: StepAnswer::Act { since, reply },
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

    /// Sends a finished manual step its answer.
    pub(super) fn answer_step(&mut self, answer: StepAnswer) {
        match answer {
            StepAnswer::State(reply) => {
                self.refresh_frame();
                let _ = reply.send(Ok(self.state(Sight::Live)));
            }
            StepAnswer::Act { since, reply } => {
                let _ = reply.send(Ok(self.act_response(since)));
            }
        }
    }

    fn act_response(&self, since: u64) -> ActResponse {
        let w = &self.world;
        ActResponse {
            tick: w.tick,
            status: crate::protocol::status(w.status),
            winner: crate::protocol::winner(w.winner),
            observations: (0..w.robots.len())
                .filter_map(|i| {
                    let o = w.observation(i)?;
                    Some((AgentId::Robot(i).to_string(), robots::observation(&o)))
                })
                .collect(),
            events: w
                .events_since(since)
                .iter()
                .map(crate::protocol::event)
                .collect(),
        }
    }
}

fn input_error(e: InputError) -> MatchError {
    match e {
        InputError::Robot(e) => order_error(e),
        other => MatchError::BadRequest(other.to_string()),
    }
}

/// The HTTP meaning of a refused order.
fn order_error(e: RobotOrderError) -> MatchError {
    match e {
        RobotOrderError::UnknownRobot(_) => MatchError::NotFound(e.to_string()),
        RobotOrderError::NotApiDriven => MatchError::Conflict(e.to_string()),
        _ => MatchError::BadRequest(e.to_string()),
    }
}
