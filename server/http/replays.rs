//! The endpoints of history and replays: the finished matches, one replay's summary, and
//! its state and belief at any tick (re-simulated off the async workers).

use std::collections::HashMap;
use std::sync::Arc;

use axum::Json;
use axum::extract::{Path, Query, State};

use crate::game::replay::{HistoryError, Replay};
use crate::game::view::{Frame, Summary};
use crate::http::admit::off_workers;
use crate::http::{ApiError, AppState};
use crate::protocol::replays::{ReplayDetail, ReplayListed};
use crate::protocol::{self, Belief, ErrorBody, MatchState, Winner};
use crate::store::Listed;
use lasertag_core::sim::AgentId;

pub(crate) fn listed(l: &Listed) -> ReplayListed {
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

/// The replay `id`, or a 404 naming it. Loading one from the store is blocking work.
pub(crate) async fn find(state: &AppState, id: &str) -> Result<Arc<Replay>, ApiError> {
    let history = state.registry.history.clone();
    let found = match history.get(id) {
        Some(r) => Some(r),
        None => {
            let key = id.to_string();
            off_workers(state, "loading the replay", move || history.load(&key))
                .await?
                .map_err(history_error)?
        }
    };
    found.ok_or_else(|| {
        ApiError::not_found(format!(
            "no replay {id} (matches are replayable once they have ended)"
        ))
    })
}

/// A store that failed is the server's fault, not the request's.
pub(crate) fn history_error(e: HistoryError) -> ApiError {
    tracing::error!("history: {e}");
    ApiError::new(
        axum::http::StatusCode::INTERNAL_SERVER_ERROR,
        format!("the history could not be read: {e}"),
    )
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

/// `?tick=`: a number (else 400) that is one of the replay's ticks (else 404: a tick past
/// the end is a state the replay does not have).
fn tick(query: &HashMap<String, String>, r: &Replay) -> Result<u64, ApiError> {
    let t = number(query, "tick", u64::MAX, None)?;
    if t > r.last_tick {
        return Err(ApiError::not_found(format!(
            "tick: the replay has ticks 0 to {}, not {t}",
            r.last_tick
        )));
    }
    Ok(t)
}

/// The world of `r` at `tick`, re-simulated off the async workers.
async fn world_at(
    state: &AppState,
    r: Arc<Replay>,
    tick: u64,
) -> Result<lasertag_core::world::World, ApiError> {
    state.registry.history.opened(&r);
    off_workers(state, "replaying the match", move || r.world_at(tick))
        .await?
        .map_err(|e| ApiError::bad_request(e.to_string()))
}

#[utoipa::path(get, path = "/api/replays",
    params(("limit" = Option<u64>, Query, minimum = 1, maximum = 500, description = "at most this many (50)"),
           ("before" = Option<String>, Query, description = "only matches that ended before this one")),
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
    let limit = limit as usize;
    let before = query.get("before").cloned();
    let history = state.registry.history.clone();
    let replays = off_workers(&state, "listing the history", move || {
        history.list(limit, before.as_deref())
    })
    .await?
    .map_err(history_error)?;
    Ok(Json(replays.iter().map(listed).collect()))
}

#[utoipa::path(get, path = "/api/replays/{id}", params(("id" = String, Path)),
    responses((status = 200, body = ReplayDetail), (status = 404, body = ErrorBody)))]
pub async fn detail(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<ReplayDetail>, ApiError> {
    let r = find(&state, &id).await?;
    let last = r.last_tick;
    let world = world_at(&state, r.clone(), last).await?;
    Ok(Json(ReplayDetail {
        listed: listed(&r.listed()),
        settings: protocol::summary(&Summary::of(
            &world,
            &r.meta,
            &Arc::new(world.config.clone()),
        )),
        events: world.events().iter().map(protocol::event).collect(),
    }))
}

#[utoipa::path(get, path = "/api/replays/{id}/state",
    params(("id" = String, Path), ("tick" = u64, Query, description = "a tick of the match, 0 to its last")),
    responses((status = 200, body = MatchState), (status = 400, body = ErrorBody), (status = 404, body = ErrorBody, description = "no such replay, or a tick past its end")))]
pub async fn state_at(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<MatchState>, ApiError> {
    let r = find(&state, &id).await?;
    let tick = tick(&query, &r)?;
    let world = world_at(&state, r.clone(), tick).await?;
    let frame = Frame::build(&world, &[], 0, 0, true);
    Ok(Json(protocol::state(&frame, &r.meta, r.config())))
}

#[utoipa::path(get, path = "/api/replays/{id}/belief",
    params(("id" = String, Path), ("tick" = u64, Query, description = "a tick of the match, 0 to its last"),
           ("robot" = Option<String>, Query, description = "a robot id: that robot's own belief")),
    responses((status = 200, body = Belief), (status = 400, body = ErrorBody), (status = 404, body = ErrorBody)))]
pub async fn belief_at(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<Belief>, ApiError> {
    let r = find(&state, &id).await?;
    let tick = tick(&query, &r)?;
    let robot = match query.get("robot") {
        None => None,
        Some(v) => match v.parse() {
            Ok(AgentId::Robot(i)) => Some(i),
            _ => {
                return Err(ApiError::not_found(format!(
                    "robot: no robot {v:?} in this match (r0, r1, …)"
                )));
            }
        },
    };
    let world = world_at(&state, r, tick).await?;
    protocol::belief_of(&world, robot)
        .map(Json)
        .ok_or_else(|| ApiError::not_found("robot: no such robot in this match"))
}
