//! The history's use cases: the finished matches, one replay, and its state and belief at
//! any tick, re-simulated (and loaded from the store) on the replays' own bounded pool.

use std::sync::Arc;

use crate::access::ClientKey;
use crate::game::replay::{HistoryError, Replay, ReplayError};
use crate::game::view::{Frame, Summary};
use crate::protocol::replays::{ReplayDetail, ReplayListed};
use crate::protocol::{self, Belief, MatchState, Winner};
use crate::service::{PoolError, ReplayBusy, Service};
use crate::store::Listed;
use lasertag_core::world::World;

/// Why the history did not answer.
#[derive(Debug, thiserror::Error)]
pub enum ReplaysError {
    #[error("no replay {0} (matches are replayable once they have ended)")]
    NotFound(String),
    /// A tick past the end is a state the replay does not have.
    #[error("tick: the replay has ticks 0 to {last}, not {tick}")]
    PastTheEnd { tick: u64, last: u64 },
    #[error("robot: no such robot in this match")]
    NoRobot,
    /// The replay could not be re-simulated to the tick.
    #[error(transparent)]
    Replay(#[from] ReplayError),
    /// The store failed: the server's fault, not the request's.
    #[error("the history could not be read: {0}")]
    History(#[from] HistoryError),
    #[error(transparent)]
    Pool(#[from] PoolError),
    /// The replays' pool is busy, or the client has its share of it in flight.
    #[error(transparent)]
    Busy(#[from] ReplayBusy),
}

/// A finished match as lists show it.
pub fn listed(l: &Listed) -> ReplayListed {
    let secs = |ms: i64| ms as f64 / 1000.0;
    ReplayListed {
        id: l.id.clone(),
        map: l.map.clone(),
        started_at: secs(l.started_at_ms),
        ended_at: secs(l.ended_at_ms.unwrap_or(l.started_at_ms)),
        ticks: l.ticks,
        winner: match l.winner.as_deref() {
            Some("robots") => Some(Winner::Robots),
            Some("opponents") => Some(Winner::Opponents),
            _ => None,
        },
        reason: l.reason.clone(),
        complete: l.complete,
        players: l.players.clone(),
    }
}

/// At most `limit` finished matches, the last to end first; with `before`, those that
/// ended before it; without the showcase's runs unless `showcases`.
pub async fn list(
    service: Service<'_>,
    limit: usize,
    before: Option<String>,
    showcases: bool,
) -> Result<Vec<ReplayListed>, ReplaysError> {
    let history = service.registry.history.clone();
    let without = (!showcases).then_some(crate::game::showcase::SHOWCASE_PREFIX);
    let replays = service
        .pool
        .run("listing the history", move || {
            history.list(limit, before.as_deref(), without)
        })
        .await??;
    Ok(replays.iter().map(listed).collect())
}

/// The replay `id`: from memory, or loaded from the store.
pub async fn find(service: Service<'_>, id: &str) -> Result<Arc<Replay>, ReplaysError> {
    let history = service.registry.history.clone();
    let found = match history.get(id) {
        Some(r) => Some(r),
        None => {
            let key = id.to_string();
            service
                .replays
                .run(None, "loading the replay", move || history.load(&key))
                .await??
        }
    };
    found.ok_or_else(|| ReplaysError::NotFound(id.to_string()))
}

/// `tick`, when it is one of `r`'s ticks.
pub fn tick(r: &Replay, tick: u64) -> Result<u64, ReplaysError> {
    if tick > r.last_tick {
        return Err(ReplaysError::PastTheEnd {
            tick,
            last: r.last_tick,
        });
    }
    Ok(tick)
}

/// The world of `r` at `tick`, re-simulated on the replays' pool for `client`.
async fn world_at(
    service: Service<'_>,
    client: Option<ClientKey>,
    r: Arc<Replay>,
    tick: u64,
) -> Result<World, ReplaysError> {
    service.registry.history.opened(&r);
    Ok(service
        .replays
        .run(client, "replaying the match", move || r.world_at(tick))
        .await??)
}

/// `r`'s listing, settings and events.
pub async fn detail(
    service: Service<'_>,
    client: Option<ClientKey>,
    r: Arc<Replay>,
) -> Result<ReplayDetail, ReplaysError> {
    let world = world_at(service, client, r.clone(), r.last_tick).await?;
    Ok(ReplayDetail {
        listed: listed(&r.listed()),
        // The match has ended: its seed is everyone's now.
        settings: protocol::owners_summary(&Summary::of(
            &world,
            &r.meta,
            &std::sync::Arc::new(world.config.clone()),
        )),
        events: world.events().iter().map(protocol::event).collect(),
    })
}

/// The state of `r` at `tick` (one of its ticks, see [`tick`]).
pub async fn state_at(
    service: Service<'_>,
    client: Option<ClientKey>,
    r: Arc<Replay>,
    tick: u64,
) -> Result<MatchState, ReplaysError> {
    let world = world_at(service, client, r.clone(), tick).await?;
    let frame = Frame::build(&world, &Default::default(), 0, 0, true);
    Ok(protocol::state(&frame, &r.meta, r.config()))
}

/// The team's belief in `r` at `tick`, or with `robot` that robot's own.
pub async fn belief_at(
    service: Service<'_>,
    client: Option<ClientKey>,
    r: Arc<Replay>,
    tick: u64,
    robot: Option<usize>,
) -> Result<Belief, ReplaysError> {
    let world = world_at(service, client, r, tick).await?;
    protocol::belief_of(&world, robot).ok_or(ReplaysError::NoRobot)
}
