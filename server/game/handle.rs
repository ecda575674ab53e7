//! A [`MatchHandle`]: the way to one match's task. Each method sends the task a
//! [`Request`] and awaits its reply.

use std::sync::Arc;

use tokio::sync::{mpsc, oneshot};

use super::{Hub, MatchError, Request, Seat, Sight};
use crate::access::{ClientKey, Owner};
use crate::admission::Price;
use crate::protocol::robots::{ActResponse, Observation};
use crate::protocol::{Belief, Clock, Events, Joined, MatchState, MatchStats, MatchSummary};
use lasertag_core::world::{FinishReason, HumanInput, OpponentOrder, RobotOrder};

/// The way to one match's task.
#[derive(Debug, Clone)]
pub struct MatchHandle {
    pub id: String,
    /// Who may change it (step, commands, delete).
    pub owner: Arc<Owner>,
    /// What it was priced at when admitted.
    pub price: Price,
    /// Creation order, for stable listings.
    pub order: u64,
    pub clock: Clock,
    pub hub: Hub,
    pub(super) tx: mpsc::Sender<Request>,
}

impl MatchHandle {
    async fn ask<T>(
        &self,
        make: impl FnOnce(oneshot::Sender<T>) -> Request,
    ) -> Result<T, MatchError> {
        let (reply, rx) = oneshot::channel();
        self.tx
            .send(make(reply))
            .await
            .map_err(|_| MatchError::Gone(self.id.clone()))?;
        rx.await.map_err(|_| MatchError::Gone(self.id.clone()))
    }

    pub async fn summary(&self) -> Result<MatchSummary, MatchError> {
        self.ask(Request::Summary).await
    }

    pub async fn state(&self, sight: Sight) -> Result<MatchState, MatchError> {
        self.ask(|reply| Request::State { sight, reply }).await
    }

    /// Robot `robot`'s own belief, or the team's merged view when `None`.
    pub async fn belief(&self, robot: Option<usize>, sight: Sight) -> Result<Belief, MatchError> {
        self.ask(|reply| Request::Belief {
            robot,
            sight,
            reply,
        })
        .await?
    }

    pub async fn events(&self, since: u64, sight: Sight) -> Result<Events, MatchError> {
        self.ask(|reply| Request::Events {
            since,
            sight,
            reply,
        })
        .await
    }

    pub async fn step(&self, ticks: u64) -> Result<MatchState, MatchError> {
        self.ask(|reply| Request::Step { ticks, reply }).await?
    }

    pub async fn order(&self, opponent: usize, order: OpponentOrder) -> Result<(), MatchError> {
        self.ask(|reply| Request::Order {
            opponent,
            order,
            reply,
        })
        .await?
    }

    pub async fn order_robot(&self, robot: usize, order: RobotOrder) -> Result<(), MatchError> {
        self.ask(|reply| Request::RobotOrder {
            robot,
            order,
            reply,
        })
        .await?
    }

    pub async fn observation(&self, robot: usize) -> Result<Observation, MatchError> {
        self.ask(|reply| Request::Observation { robot, reply })
            .await?
    }

    pub async fn act(
        &self,
        orders: Vec<(usize, RobotOrder)>,
        ticks: u64,
    ) -> Result<ActResponse, MatchError> {
        self.ask(|reply| Request::Act {
            orders,
            ticks,
            reply,
        })
        .await?
    }

    pub async fn join(
        &self,
        name: String,
        client: Option<ClientKey>,
    ) -> Result<Joined, MatchError> {
        self.ask(|reply| Request::Join {
            name,
            client,
            reply,
        })
        .await?
    }

    pub async fn stats(&self) -> Result<MatchStats, MatchError> {
        self.ask(Request::Stats).await
    }

    pub async fn connect(&self, token: String) -> Result<Seat, MatchError> {
        self.ask(|reply| Request::Connect { token, reply }).await?
    }

    /// Forwards a player's keys; waits only for room in the task's queue.
    pub async fn input(
        &self,
        slot: usize,
        generation: u64,
        input: HumanInput,
        seq: Option<u64>,
    ) -> bool {
        self.tx
            .send(Request::Input {
                slot,
                generation,
                input,
                seq,
            })
            .await
            .is_ok()
    }

    /// Ends the match (for `reason`) and its task.
    /// Ends the match and waits for its task to finish (so that it is in the history when
    /// this returns).
    pub async fn stop(&self, reason: FinishReason) {
        let _ = self.tx.send(Request::Stop(reason)).await;
        self.tx.closed().await;
    }
}
