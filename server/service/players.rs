//! The players' use cases: one name's totals and latest matches, and the leaderboard, read
//! from the history's store on the blocking pool. Only kept names have figures
//! (`service::names`).

use crate::game::replay::HistoryError;
use crate::protocol::replays::{Leaderboard, PlayedMatch, PlayerDetail, PlayerTotals, RatingDto};
use crate::service::replays::listed;
use crate::service::{PoolError, Service};
use crate::store::{LeaderOrder, PlayerStats, StoreError};
use lasertag_core::sim::TICK_HZ;

/// Latest matches a player's detail shows.
const RECENT: usize = 20;

/// Why there are no statistics to show.
#[derive(Debug, thiserror::Error)]
pub enum StatsError {
    #[error("no statistics: this server keeps no history (it runs without a store)")]
    NoHistory,
    #[error("no player {0:?} has finished a match here")]
    NoPlayer(String),
    /// The store failed: the server's fault, not the request's.
    #[error("the history could not be read: {0}")]
    History(#[from] HistoryError),
    #[error(transparent)]
    Pool(#[from] PoolError),
}

impl From<StoreError> for StatsError {
    fn from(e: StoreError) -> StatsError {
        StatsError::History(e.into())
    }
}

fn totals(p: &PlayerStats) -> PlayerTotals {
    PlayerTotals {
        name: p.name.clone(),
        matches: p.matches,
        wins: p.wins,
        tags: p.tags,
        longest_survival_s: p.longest_survival_ticks as f64 / TICK_HZ as f64,
        rating: p.rating.map(|r| RatingDto {
            rating: r.rating.round(),
            deviation: r.deviation.round(),
            matches: r.matches,
        }),
    }
}

/// `name`'s totals and latest matches.
pub async fn player(service: Service<'_>, name: String) -> Result<PlayerDetail, StatsError> {
    let history = service.registry.history.clone();
    if history.store().is_none() {
        return Err(StatsError::NoHistory);
    }
    let key = name.clone();
    let found = service
        .pool
        .run("reading the statistics", move || {
            let store = history.store().ok_or(StoreError::Closed)?;
            store.read(|b| Ok((b.player(&key)?, b.played(&key, RECENT)?)))
        })
        .await??;
    match found {
        (Some(stats), recent) => Ok(PlayerDetail {
            totals: totals(&stats),
            recent: recent
                .iter()
                .map(|p| PlayedMatch {
                    listed: listed(&p.listed),
                    rating_before: p.rating_before.map(f64::round),
                    rating_after: p.rating_after.map(f64::round),
                })
                .collect(),
        }),
        (None, _) => Err(StatsError::NoPlayer(name)),
    }
}

/// The first `limit` names by `order`; `by` names the order in the answer.
pub async fn leaderboard(
    service: Service<'_>,
    by: &'static str,
    order: LeaderOrder,
    limit: usize,
) -> Result<Leaderboard, StatsError> {
    let history = service.registry.history.clone();
    if history.store().is_none() {
        return Err(StatsError::NoHistory);
    }
    let leaders = service
        .pool
        .run("reading the statistics", move || {
            let store = history.store().ok_or(StoreError::Closed)?;
            store.read(|b| b.leaders(order, limit))
        })
        .await??;
    Ok(Leaderboard {
        by,
        players: leaders.iter().map(totals).collect(),
    })
}
