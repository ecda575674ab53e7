//! The endpoints of history and replays: the finished matches, one replay's summary, and
//! its state and belief at any tick (see [`crate::service::replays`]).

use std::collections::HashMap;
use std::sync::Arc;

use axum::Json;
use axum::extract::{Path, Query, State};

use crate::access::ClientKey;
use crate::game::replay::Replay;
use crate::http::error::ApiError;
use crate::http::limits::ClientIp;
use crate::http::state::AppState;
use crate::protocol::replays::{ReplayDetail, ReplayListed};
use crate::protocol::{Belief, ErrorBody, MatchState};
use crate::service::replays;
use lasertag_core::sim::AgentId;

/// The replay `id`, or a 404 naming it.
pub(crate) async fn find(state: &AppState, id: &str) -> Result<Arc<Replay>, ApiError> {
    Ok(replays::find(state.service(), id).await?)
}

/// `?name=` as an integer in `0..=max`, or `default` when absent.
pub(crate) fn number(
    query: &HashMap<String, String>,
    name: &str,
    max: u64,
    default: Option<u64>,
) -> Result<u64, ApiError> {
    match (query.get(name), default) {
        (None, Some(d)) => Ok(d),
        (None, None) => Err(ApiError::bad_request(format!(
            "{name}: required (an integer in 0..={max})"
        ))),
        (Some(v), _) => v.parse::<u64>().ok().filter(|n| *n <= max).ok_or_else(|| {
            ApiError::bad_request(format!("{name}: {v:?} is not an integer in 0..={max}"))
        }),
    }
}

/// `?robot=` as a robot's index, or `None` when absent. Anything that is not a robot id is a
/// robot the match does not have: 404, like `r9` in a two-robot match (a 400 for a
/// malformed id made schema-valid strings fail schemathesis, and a `pattern` on the
/// parameter crashed its generator).
pub(crate) fn robot(query: &HashMap<String, String>) -> Result<Option<usize>, ApiError> {
    match query.get("robot") {
        None => Ok(None),
        Some(v) => match v.parse() {
            Ok(AgentId::Robot(i)) => Ok(Some(i)),
            _ => Err(ApiError::not_found(format!(
                "robot: no robot {v:?} in this match (r0, r1, …)"
            ))),
        },
    }
}

#[utoipa::path(get, path = "/api/replays",
    params(("limit" = Option<u64>, Query, minimum = 1, maximum = 500, description = "at most this many (50)"),
           ("before" = Option<String>, Query, description = "only matches that ended before this one"),
           ("showcase" = Option<bool>, Query, description = "whether the showcase's runs are listed (true)")),
    responses((status = 200, body = [ReplayListed]), (status = 400, body = ErrorBody)))]
pub async fn list(
    State(state): State<AppState>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<Vec<ReplayListed>>, ApiError> {
    let limit = number(&query, "limit", 500, Some(50))?;
    if limit == 0 {
        return Err(ApiError::bad_request(
            "limit: 0 is not an integer in 1..=500",
        ));
    }
    let before = query.get("before").cloned();
    let showcases = match query.get("showcase").map(String::as_str) {
        None | Some("true") => true,
        Some("false") => false,
        Some(other) => {
            return Err(ApiError::bad_request(format!(
                "showcase: {other:?} is not true or false"
            )));
        }
    };
    Ok(Json(
        replays::list(state.service(), limit as usize, before, showcases).await?,
    ))
}

#[utoipa::path(get, path = "/api/replays/{id}", params(("id" = String, Path)),
    responses((status = 200, body = ReplayDetail), (status = 404, body = ErrorBody),
              (status = 429, body = ErrorBody, description = "this client has its share of the replays' pool in flight"), (status = 503, body = ErrorBody, description = "the replays' pool is busy")))]
pub async fn detail(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    Path(id): Path<String>,
) -> Result<Json<ReplayDetail>, ApiError> {
    let r = find(&state, &id).await?;
    let client = Some(ClientKey::of(ip));
    Ok(Json(replays::detail(state.service(), client, r).await?))
}

#[utoipa::path(get, path = "/api/replays/{id}/state",
    params(("id" = String, Path), ("tick" = u64, Query, description = "a tick of the match, 0 to its last")),
    responses((status = 200, body = MatchState), (status = 400, body = ErrorBody), (status = 404, body = ErrorBody, description = "no such replay, or a tick past its end"),
              (status = 429, body = ErrorBody, description = "this client has its share of the replays' pool in flight"), (status = 503, body = ErrorBody, description = "the replays' pool is busy")))]
pub async fn state_at(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    Path(id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<MatchState>, ApiError> {
    let r = find(&state, &id).await?;
    let tick = replays::tick(&r, number(&query, "tick", u64::MAX, None)?)?;
    let client = Some(ClientKey::of(ip));
    Ok(Json(
        replays::state_at(state.service(), client, r, tick).await?,
    ))
}

#[utoipa::path(get, path = "/api/replays/{id}/belief",
    params(("id" = String, Path), ("tick" = u64, Query, description = "a tick of the match, 0 to its last"),
           ("robot" = Option<String>, Query, description = "a robot id: that robot's own belief")),
    responses((status = 200, body = Belief), (status = 400, body = ErrorBody), (status = 404, body = ErrorBody),
              (status = 429, body = ErrorBody, description = "this client has its share of the replays' pool in flight"), (status = 503, body = ErrorBody, description = "the replays' pool is busy")))]
pub async fn belief_at(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    Path(id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<Belief>, ApiError> {
    let r = find(&state, &id).await?;
    let tick = replays::tick(&r, number(&query, "tick", u64::MAX, None)?)?;
    let robot = robot(&query)?;
    Ok(Json(
        replays::belief_at(state.service(), Some(ClientKey::of(ip)), r, tick, robot).await?,
    ))
}
