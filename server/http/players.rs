//! Player statistics from the history: one name's totals and latest matches, and the
//! leaderboard (see [`crate::service::players`]).

use std::collections::HashMap;

use axum::Json;
use axum::extract::{Path, Query, State};

use crate::http::error::ApiError;
use crate::http::state::AppState;
use crate::protocol::ErrorBody;
use crate::protocol::replays::{Leaderboard, PlayerDetail};
use crate::service::players;
use crate::store::LeaderOrder;

/// Most names a leaderboard shows.
const MAX_LEADERS: usize = 100;

#[utoipa::path(get, path = "/api/players/{name}", params(("name" = String, Path)),
    responses((status = 200, body = PlayerDetail), (status = 404, body = ErrorBody, description = "nobody by that name has finished a match")))]
pub async fn player(
    State(state): State<AppState>,
    Path(name): Path<String>,
) -> Result<Json<PlayerDetail>, ApiError> {
    Ok(Json(players::player(state.service(), name).await?))
}

#[utoipa::path(get, path = "/api/leaderboard",
    params(("by" = Option<String>, Query, pattern = "^(wins|tags|survival|matches|rating)$", description = "wins (default), tags, survival, matches or rating (rated names only, by rating less two deviations)"),
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
        Some("rating") => ("rating", LeaderOrder::Rating),
        Some(other) => {
            return Err(ApiError::bad_request(format!(
                "by: {other:?} is not one of wins, tags, survival, matches, rating"
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
    Ok(Json(
        players::leaderboard(state.service(), by, order, limit).await?,
    ))
}
