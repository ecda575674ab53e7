//! Player statistics from the history: one name's totals and latest matches, and the
//! leaderboard. Names are not accounts (see `store::results`).

use std::collections::HashMap;

use axum::Json;
use axum::extract::{Path, Query, State};

use crate::http::admit::off_workers;
use crate::http::replays::{history_error, listed};
use crate::http::{ApiError, AppState};
use crate::protocol::ErrorBody;
use crate::protocol::replays::{Leaderboard, PlayerDetail, PlayerTotals};
use crate::store::{LeaderOrder, PlayerStats};
use lasertag_core::sim::TICK_HZ;

/// Latest matches `GET /api/players/{name}` shows.
const RECENT: usize = 20;
/// Most names a leaderboard shows.
const MAX_LEADERS: usize = 100;

fn totals(p: &PlayerStats) -> PlayerTotals {
    PlayerTotals {
        name: p.name.clone(),
        matches: p.matches,
        wins: p.wins,
        tags: p.tags,
        longest_survival_s: p.longest_survival_ticks as f64 / TICK_HZ as f64,
    }
}

fn no_statistics() -> ApiError {
    ApiError::not_found("no statistics: this server keeps no history (it runs without a store)")
}

#[utoipa::path(get, path = "/api/players/{name}", params(("name" = String, Path)),
    responses((status = 200, body = PlayerDetail), (status = 404, body = ErrorBody, description = "nobody by that name has finished a match")))]
pub async fn player(
    State(state): State<AppState>,
    Path(name): Path<String>,
) -> Result<Json<PlayerDetail>, ApiError> {
    let history = state.registry.history.clone();
    if history.store().is_none() {
        return Err(no_statistics());
    }
    let key = name.clone();
    let found = off_workers(&state, "reading the statistics", move || {
        let store = history.store().ok_or(crate::store::StoreError::Closed)?;
        store.read(|b| Ok((b.player(&key)?, b.played(&key, RECENT)?)))
    })
    .await?
    .map_err(|e| history_error(e.into()))?;
    match found {
        (Some(stats), recent) => Ok(Json(PlayerDetail {
            totals: totals(&stats),
            recent: recent.iter().map(listed).collect(),
        })),
        (None, _) => Err(ApiError::not_found(format!(
            "no player {name:?} has finished a match here"
        ))),
    }
}

#[utoipa::path(get, path = "/api/leaderboard",
    params(("by" = Option<String>, Query, pattern = "^(wins|tags|survival|matches)$", description = "wins (default), tags, survival or matches"),
           ("limit" = Option<u64>, Query, minimum = 1, maximum = 100, description = "at most this many (20)")),
    responses((status = 200, body = Leaderboard), (status = 400, body = ErrorBody), (status = 404, body = ErrorBody)))]
pub async fn leaderboard(
    State(state): State<AppState>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<Leaderboard>, ApiError> {
    let (by, order) = match query.get("by").map(String::as_str) {
        None | Some("wins") => ("wins", LeaderOrder::Wins),
        Some("tags") => ("tags", LeaderOrder::Tags),
        Some("survival") => ("survival", LeaderOrder::Survival),
        Some("matches") => ("matches", LeaderOrder::Matches),
        Some(other) => {
            return Err(ApiError::bad_request(format!(
                "by: {other:?} is not one of wins, tags, survival, matches"
            )));
        }
    };
    let limit = match query.get("limit") {
        None => 20,
        Some(v) => v
            .parse::<usize>()
            .ok()
            .filter(|n| (1..=MAX_LEADERS).contains(n))
            .ok_or_else(|| {
                ApiError::bad_request(format!(
                    "limit: {v:?} is not an integer in 1..={MAX_LEADERS}"
                ))
            })?,
    };
    let history = state.registry.history.clone();
    if history.store().is_none() {
        return Err(no_statistics());
    }
    let leaders = off_workers(&state, "reading the statistics", move || {
        let store = history.store().ok_or(crate::store::StoreError::Closed)?;
        store.read(|b| b.leaders(order, limit))
    })
    .await?
    .map_err(|e| history_error(e.into()))?;
    Ok(Json(Leaderboard {
        by,
        players: leaders.iter().map(totals).collect(),
    }))
}
