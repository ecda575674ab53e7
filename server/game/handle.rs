//! A [`MatchHandle`]: the way to one match's task. Each method sends the task a
//! [`Request`] and awaits its reply; reads take the caller's conversion, which runs on the
//! task against a [`Reading`] of the match, so the game never names a wire type.

use std::sync::Arc;

use tokio::sync::{mpsc, oneshot};

use super::error::MatchError;
use super::hub::{Hub, Seat};
use super::task::{Answer, Reading, Request};
use super::view::{Clock, Joined, Sight, Team};
use crate::access::{ClientKey, Owner};
use crate::game::admission::Price;
use lasertag_core::world::{FinishReason, HumanInput, WorldInput};

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
    fn gone(&self) -> MatchError {
        MatchError::Gone(self.id.clone())
    }

    async fn ask<T>(
        &self,
        make: impl FnOnce(oneshot::Sender<T>) -> Request,
    ) -> Result<T, MatchError> {
        let (reply, rx) = oneshot::channel();
        self.tx.send(make(reply)).await.map_err(|_| self.gone())?;
        rx.await.map_err(|_| self.gone())
    }

    /// Sends the request `make` builds around an [`Answer`] that runs `read` on the task.
    async fn answered<T: Send + 'static>(
        &self,
        make: impl FnOnce(Answer) -> Request,
        read: impl FnOnce(&mut Reading<'_>) -> Result<T, MatchError> + Send + 'static,
    ) -> Result<T, MatchError> {
        let (reply, rx) = oneshot::channel();
        let answer: Answer = Box::new(move |reading| {
            let _ = reply.send(match reading {
                Ok(reading) => read(reading),
                Err(e) => Err(e),
            });
        });
        self.tx.send(make(answer)).await.map_err(|_| self.gone())?;
        rx.await.map_err(|_| self.gone())?
    }

    /// Reads the match as a reader with `sight` may see it: `read` runs on the match's
    /// task (keep it to a conversion).
    pub async fn read<T: Send + 'static>(
        &self,
        sight: Sight,
        read: impl FnOnce(&mut Reading<'_>) -> Result<T, MatchError> + Send + 'static,
    ) -> Result<T, MatchError> {
        self.answered(|answer| Request::Read { sight, answer }, read)
            .await
    }

    /// Applies every input of `inputs` (all or none), runs `ticks` ticks of a manual-clock
    /// match, then reads it live; `what` names the request in refusals.
    pub async fn step<T: Send + 'static>(
        &self,
        what: &'static str,
        inputs: Vec<WorldInput>,
        ticks: u64,
        read: impl FnOnce(&mut Reading<'_>) -> Result<T, MatchError> + Send + 'static,
    ) -> Result<T, MatchError> {
        self.answered(
            |answer| Request::Step {
                inputs,
                ticks,
                what,
                answer,
            },
            read,
        )
        .await
    }

    /// One change from outside (an order for an opponent or a robot), from the next tick on.
    pub async fn apply(&self, input: WorldInput) -> Result<(), MatchError> {
        self.ask(|reply| Request::Apply { input, reply }).await?
    }

    pub async fn join(
        &self,
        name: crate::names::JoinName,
        team: Team,
        client: Option<ClientKey>,
    ) -> Result<Joined, MatchError> {
        self.ask(|reply| Request::Join {
            name,
            team,
            client,
            reply,
        })
        .await?
    }

    pub async fn connect(&self, token: String) -> Result<Seat, MatchError> {
        self.ask(|reply| Request::Connect { token, reply }).await?
    }

    /// Forwards a player's keys; waits only for room in the task's queue.
    pub async fn input(
        &self,
        seat: usize,
        generation: u64,
        input: HumanInput,
        seq: Option<u64>,
    ) -> bool {
        self.tx
            .send(Request::Input {
                seat,
                generation,
                input,
                seq,
            })
            .await
            .is_ok()
    }

    /// Ends the match and waits for its task to finish (so that it is in the history when
    /// this returns).
    pub async fn stop(&self, reason: FinishReason) {
        let _ = self.tx.send(Request::Stop(reason)).await;
        self.tx.closed().await;
    }

    /// Ends the match's task but not the match, its record whole in the store, and waits
    /// for the task to end.
    pub async fn suspend(&self) {
        let _ = self.tx.send(Request::Suspend).await;
        self.tx.closed().await;
    }
}
