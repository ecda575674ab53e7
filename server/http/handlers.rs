//! One function per endpoint of `docs/api.md`.

use std::collections::HashMap;

use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};

use crate::access::ClientKey;
use crate::game::{MatchHandle, Sight};
use crate::http::auth::Bearer;
use crate::http::body::JsonBody;
use crate::http::error::ApiError;
use crate::http::fleet;
use crate::http::limits::ClientIp;
use crate::http::state::AppState;
use crate::maps::MapFile;
use crate::protocol::fleet::{Elsewhere, Listed, NodeRef, Place};
use crate::protocol::{
    self, CreateMatch, ErrorBody, Events, Health, JoinRequest, Joined, MapCreated, MapInfo,
    MatchCreated, MatchState, MatchStats, MatchSummary, OpponentCommand, ShowcaseJoinRequest,
    ShowcaseSeat, StepRequest,
};
use crate::service::maps;
use crate::service::matches::{self, Created};
use lasertag_core::sim::AgentId;
use lasertag_core::world::WorldInput;

/// The match `id` for a request that changes it: 404 when there is no such match (its
/// existence is public), then the token is checked (see [`Bearer::may_change`]).
pub(super) fn owned(state: &AppState, bearer: &Bearer, id: &str) -> Result<MatchHandle, ApiError> {
    let handle = find(state, id)?;
    bearer.may_change(state, &handle.owner, &format!("match {id}"))?;
    Ok(handle)
}

/// The match `id` for a read of its truth, and how the reader sees it (see
/// [`Bearer::sight`]).
pub(super) fn readable(
    state: &AppState,
    bearer: &Bearer,
    id: &str,
) -> Result<(MatchHandle, Sight), ApiError> {
    let handle = find(state, id)?;
    let sight = bearer.sight(state, &handle.owner, &format!("match {id}"))?;
    Ok((handle, sight))
}

fn find(state: &AppState, id: &str) -> Result<MatchHandle, ApiError> {
    state
        .registry
        .get(id)
        .ok_or_else(|| ApiError::no_match(&state.registry, id))
}

#[utoipa::path(get, path = "/api/health", responses((status = 200, body = Health)))]
pub async fn health() -> Json<Health> {
    Json(Health {
        status: "ok",
        version: env!("CARGO_PKG_VERSION"),
    })
}

#[utoipa::path(get, path = "/api/maps", responses((status = 200, body = [MapInfo])))]
pub async fn list_maps(State(state): State<AppState>) -> Json<Vec<MapInfo>> {
    Json(maps::list(state.service()))
}

#[utoipa::path(get, path = "/api/maps/{name}", params(("name" = String, Path)),
    responses((status = 200, body = MapFile), (status = 404, body = ErrorBody)))]
pub async fn get_map(
    State(state): State<AppState>,
    Path(name): Path<String>,
) -> Result<Json<MapFile>, ApiError> {
    Ok(Json(maps::get(state.service(), &name)?))
}

#[utoipa::path(post, path = "/api/maps", request_body = MapFile,
    responses((status = 201, body = MapCreated, links(
                  ("GetMap" = (operation_id = "get_map", parameters(("name" = "$response.body#/name")))),
                  ("DeleteMap" = (operation_id = "delete_map", parameters(("name" = "$response.body#/name")))))),
              (status = 400, body = ErrorBody), (status = 409, body = ErrorBody),
              (status = 413, body = ErrorBody), (status = 429, body = ErrorBody), (status = 503, body = ErrorBody)))]
pub async fn add_map(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    JsonBody(value): JsonBody<serde_json::Value>,
) -> Result<impl IntoResponse, ApiError> {
    let created = maps::add(state.service(), ClientKey::of(ip), value).await?;
    Ok((StatusCode::CREATED, Json(created)))
}

#[utoipa::path(delete, path = "/api/maps/{name}", params(("name" = String, Path)),
    security(("owner_token" = [])),
    responses((status = 204), (status = 401, body = ErrorBody), (status = 403, body = ErrorBody),
              (status = 404, body = ErrorBody), (status = 409, body = ErrorBody)))]
pub async fn delete_map(
    State(state): State<AppState>,
    bearer: Bearer,
    Path(name): Path<String>,
) -> Result<StatusCode, ApiError> {
    let stored = maps::stored(state.service(), &name)
        .ok_or_else(|| maps::MapsError::NotFound(name.clone()))?;
    bearer.may_change(&state, &stored.owner, &format!("map {name:?}"))?;
    maps::delete(state.service(), &name, stored)?;
    Ok(StatusCode::NO_CONTENT)
}

#[utoipa::path(get, path = "/api/matches",
    description = "This server's matches; in a fleet (`--fleet`), every node's, each with the `node` that hosts it. The secret seed of a running match people may join is null, except with its owner_token or the admin token.",
    security((), ("owner_token" = [])),
    responses((status = 200, body = [MatchSummary]), (status = 401, body = ErrorBody)))]
pub async fn list_matches(State(state): State<AppState>, bearer: Bearer) -> Json<Vec<Listed>> {
    Json(matches::list(state.service(), |owner| {
        bearer.opens(&state, owner)
    }))
}

#[utoipa::path(post, path = "/api/matches", request_body = CreateMatch,
    params(("place" = Option<Place>, Query, description = "in a fleet: `fleet` (the default) places the match on the least-loaded node with room, answering 307 when that is another node; `local` creates it here")),
    responses((status = 201, body = MatchCreated, links(
                  ("GetMatch" = (operation_id = "get_match", parameters(("id" = "$response.body#/id")))),
                  ("DeleteMatch" = (operation_id = "delete_match", parameters(("id" = "$response.body#/id")))),
                  ("Step" = (operation_id = "step", parameters(("id" = "$response.body#/id")))),
                  ("Belief" = (operation_id = "belief", parameters(("id" = "$response.body#/id")))),
                  ("Events" = (operation_id = "events", parameters(("id" = "$response.body#/id")))),
                  ("Command" = (operation_id = "command", parameters(("id" = "$response.body#/id")))),
                  ("Join" = (operation_id = "join", parameters(("id" = "$response.body#/id")))),
                  ("Stats" = (operation_id = "stats", parameters(("id" = "$response.body#/id")))))),
              (status = 307, body = Elsewhere, description = "in a fleet: another node has more room; the same request to `Location` creates the match there"),
              (status = 400, body = ErrorBody), (status = 404, body = ErrorBody),
              (status = 413, body = ErrorBody), (status = 429, body = ErrorBody), (status = 503, body = ErrorBody)))]
pub async fn create_match(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    bearer: Bearer,
    Query(query): Query<HashMap<String, String>>,
    JsonBody(body): JsonBody<CreateMatch>,
) -> Result<Response, ApiError> {
    let place = match query.get("place") {
        None => Place::Fleet,
        Some(p) => Place::parse(p).ok_or_else(|| {
            ApiError::bad_request(format!("place: {p:?} is not a placement (fleet or local)"))
        })?,
    };
    // The operator's matches count against no address's quota.
    let client = (!bearer.is_admin(&state)).then(|| ClientKey::of(ip));
    // A node whose URL makes no header takes no redirect: the match is created here.
    let redirect = |node: NodeRef| {
        let message = format!("node {} has more room for a new match", node.id);
        fleet::redirect(node, "/api/matches?place=local", message)
    };
    Ok(
        match matches::create(state.service(), client, place, body, redirect).await? {
            Created::Here(created) => (StatusCode::CREATED, Json(created)).into_response(),
            Created::Elsewhere(moved) => moved,
        },
    )
}

#[utoipa::path(get, path = "/api/matches/{id}", params(("id" = String, Path)),
    security((), ("owner_token" = [])),
    responses((status = 200, body = MatchState), (status = 401, body = ErrorBody), (status = 403, body = ErrorBody),
              (status = 404, body = ErrorBody)))]
pub async fn get_match(
    State(state): State<AppState>,
    bearer: Bearer,
    Path(id): Path<String>,
) -> Result<Json<MatchState>, ApiError> {
    let (handle, sight) = readable(&state, &bearer, &id)?;
    Ok(Json(handle.read(sight, protocol::read_state).await?))
}

#[utoipa::path(delete, path = "/api/matches/{id}", params(("id" = String, Path)),
    security(("owner_token" = [])),
    responses((status = 204), (status = 401, body = ErrorBody), (status = 403, body = ErrorBody),
              (status = 404, body = ErrorBody)))]
pub async fn delete_match(
    State(state): State<AppState>,
    bearer: Bearer,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    owned(&state, &bearer, &id)?;
    if state.registry.remove(&id).await {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::not_found(format!("no match {id}")))
    }
}

#[utoipa::path(post, path = "/api/matches/{id}/step", params(("id" = String, Path)), request_body = StepRequest,
    security(("owner_token" = [])),
    responses((status = 200, body = MatchState), (status = 400, body = ErrorBody), (status = 401, body = ErrorBody),
              (status = 403, body = ErrorBody), (status = 404, body = ErrorBody),
              (status = 409, body = ErrorBody)))]
pub async fn step(
    State(state): State<AppState>,
    bearer: Bearer,
    Path(id): Path<String>,
    JsonBody(body): JsonBody<StepRequest>,
) -> Result<Json<MatchState>, ApiError> {
    let handle = owned(&state, &bearer, &id)?;
    let ticks = body.ticks()?;
    let state = handle.step("step", Vec::new(), ticks, protocol::read_state);
    Ok(Json(state.await?))
}

#[utoipa::path(get, path = "/api/matches/{id}/events",
    params(("id" = String, Path), ("since" = Option<i64>, Query, minimum = 0, description = "only events with a greater seq")),
    security((), ("owner_token" = [])),
    responses((status = 200, body = Events), (status = 400, body = ErrorBody), (status = 401, body = ErrorBody),
              (status = 403, body = ErrorBody), (status = 404, body = ErrorBody)))]
pub async fn events(
    State(state): State<AppState>,
    bearer: Bearer,
    Path(id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<Events>, ApiError> {
    let (handle, sight) = readable(&state, &bearer, &id)?;
    let since = match query.get("since") {
        None => 0,
        // 0..=i64::MAX, as the OpenAPI document states (`format: int64`; schemathesis sent
        // 2^63 and saw it accepted). Event numbers never come near it.
        Some(s) => s
            .parse::<i64>()
            .ok()
            .and_then(|v| u64::try_from(v).ok())
            .ok_or_else(|| {
                ApiError::bad_request(format!(
                    "since: {s:?} is not an integer in 0..=9223372036854775807"
                ))
            })?,
    };
    Ok(Json(
        handle.read(sight, protocol::read_events(since)).await?,
    ))
}

#[utoipa::path(post, path = "/api/matches/{id}/opponents/{oid}/command",
    params(("id" = String, Path), ("oid" = String, Path)), request_body = OpponentCommand,
    security(("owner_token" = [])),
    responses((status = 204), (status = 400, body = ErrorBody), (status = 401, body = ErrorBody),
              (status = 403, body = ErrorBody), (status = 404, body = ErrorBody),
              (status = 409, body = ErrorBody)))]
pub async fn command(
    State(state): State<AppState>,
    bearer: Bearer,
    Path((id, oid)): Path<(String, String)>,
    JsonBody(body): JsonBody<OpponentCommand>,
) -> Result<StatusCode, ApiError> {
    let handle = owned(&state, &bearer, &id)?;
    let order = body.order()?;
    // Like an unknown robot, anything that is not an opponent id names no opponent here.
    let Ok(AgentId::Opponent(opponent)) = oid.parse() else {
        return Err(ApiError::not_found(format!(
            "no opponent {oid:?} in match {id} (o0, o1, …)"
        )));
    };
    handle
        .apply(WorldInput::Opponent {
            slot: opponent,
            order,
        })
        .await?;
    Ok(StatusCode::NO_CONTENT)
}

#[utoipa::path(post, path = "/api/matches/{id}/players", params(("id" = String, Path)), request_body = JoinRequest,
    responses((status = 201, body = Joined), (status = 400, body = ErrorBody), (status = 404, body = ErrorBody),
              (status = 403, body = ErrorBody, description = "somebody keeps that name (POST /api/names): join with its name_token"),
              (status = 409, body = ErrorBody, description = "no free slot on that team, or the match is at the server's limit of players"),
              (status = 429, body = ErrorBody, description = "this client holds as many slots of the match as it may without playing them")))]
pub async fn join(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    Path(id): Path<String>,
    JsonBody(body): JsonBody<JoinRequest>,
) -> Result<impl IntoResponse, ApiError> {
    let handle = find(&state, &id)?;
    let team = crate::protocol::JoinTeam::team(body.team);
    let name =
        crate::service::names::check_join(state.service(), &body.name, body.name_token.as_deref())
            .await?;
    let joined = handle.join(name, team, Some(ClientKey::of(ip))).await?;
    Ok((StatusCode::CREATED, Json(Joined::from(joined))))
}

/// `POST /api/showcase/players`: a seat in a showcase, in one more started for it when
/// every running one is full (join-or-create).
#[utoipa::path(post, path = "/api/showcase/players", request_body = ShowcaseJoinRequest,
    responses((status = 201, body = ShowcaseSeat), (status = 400, body = ErrorBody),
              (status = 403, body = ErrorBody, description = "somebody keeps that name (POST /api/names): join with its name_token"),
              (status = 429, body = ErrorBody, description = "this client holds as many seats as it may"),
              (status = 503, body = ErrorBody, description = "every showcase is full and the server has no room for another")))]
pub async fn join_showcase(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    JsonBody(body): JsonBody<ShowcaseJoinRequest>,
) -> Result<impl IntoResponse, ApiError> {
    let name =
        crate::service::names::check_join(state.service(), &body.name, body.name_token.as_deref())
            .await?;
    let (match_id, joined) =
        crate::game::showcase::join_or_create(&state.registry, name, ClientKey::of(ip)).await?;
    Ok((
        StatusCode::CREATED,
        Json(ShowcaseSeat {
            match_id,
            seat: Joined::from(joined),
        }),
    ))
}

#[utoipa::path(get, path = "/api/matches/{id}/stats", params(("id" = String, Path)),
    responses((status = 200, body = MatchStats), (status = 404, body = ErrorBody)))]
pub async fn stats(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<MatchStats>, ApiError> {
    let handle = find(&state, &id)?;
    Ok(Json(handle.read(Sight::Live, protocol::read_stats).await?))
}

/// `GET /metrics`: every metric family in the Prometheus text format (version 0.0.4).
#[utoipa::path(get, path = "/metrics",
    description = "Prometheus text format: lasertag_matches{state}, lasertag_clients{role}, lasertag_tick_seconds{kind,clock}, lasertag_tracker_seconds{kind}, lasertag_planner_seconds{kind}, lasertag_snapshot_bytes_total{role}, lasertag_refused_total{reason}, lasertag_matches_removed_total{reason}, lasertag_late_ticks_total.",
    responses((status = 200, content_type = "text/plain", body = String)))]
pub async fn metrics(State(state): State<AppState>) -> impl IntoResponse {
    state.registry.refresh_metrics();
    (
        [(
            header::CONTENT_TYPE,
            "text/plain; version=0.0.4; charset=utf-8",
        )],
        state.registry.metrics.render(),
    )
}
