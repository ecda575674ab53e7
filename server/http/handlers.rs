//! One function per endpoint of `docs/api.md`.

use std::collections::HashMap;
use std::sync::Arc;

use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
use axum::response::IntoResponse;

use crate::access::{ClientKey, Owner};
use crate::admission;
use crate::game::{MatchHandle, Sight, random_id};
use crate::http::admit::{no_room, off_workers, within_request_limits};
use crate::http::auth::Bearer;
use crate::http::body::JsonBody;
use crate::http::limits::ClientIp;
use crate::http::{ApiError, AppState};
use crate::maps::{self, MapFile};
use crate::metrics::Refusal;
use crate::protocol::fleet::{Elsewhere, Listed, Place};
use crate::protocol::{
    Belief, CreateMatch, ErrorBody, Events, Health, JoinRequest, Joined, MapCreated, MapInfo,
    MatchCreated, MatchMeta, MatchState, MatchStats, MatchSummary, OpponentCommand, StepRequest,
};
use lasertag_core::sim::AgentId;
use lasertag_core::sim::arena::Arena;
use lasertag_core::world::World;

/// The match `id` for a request that changes it: the token is checked first (see
/// [`Bearer::may_change`]), then whether the match exists.
pub(super) fn owned(state: &AppState, bearer: &Bearer, id: &str) -> Result<MatchHandle, ApiError> {
    let handle = state.registry.get(id);
    bearer.may_change(
        state,
        handle.as_ref().map(|h| &*h.owner),
        &format!("match {id}"),
    )?;
    handle.ok_or_else(|| ApiError::not_found(format!("no match {id}")))
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
        .ok_or_else(|| ApiError::not_found(format!("no match {id}")))
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
    let maps = state
        .registry
        .maps
        .read()
        .unwrap_or_else(|e| e.into_inner());
    Json(
        maps.iter()
            .map(|m| MapInfo {
                name: m.arena.def.name.clone(),
                width: m.arena.def.width as f64,
                height: m.arena.def.height as f64,
            })
            .collect(),
    )
}

#[utoipa::path(get, path = "/api/maps/{name}", params(("name" = String, Path)),
    responses((status = 200, body = MapFile), (status = 404, body = ErrorBody)))]
pub async fn get_map(
    State(state): State<AppState>,
    Path(name): Path<String>,
) -> Result<Json<MapFile>, ApiError> {
    let maps = state
        .registry
        .maps
        .read()
        .unwrap_or_else(|e| e.into_inner());
    maps.get(&name)
        .map(|m| Json(maps::to_file(&m.arena.def)))
        .ok_or_else(|| ApiError::not_found(format!("no map {name:?}")))
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
    let def = off_workers(&state, "validating the map", move || {
        maps::from_value(value)
    })
    .await?
    .map_err(|e| ApiError::bad_request(e.to_string()))?;
    let client = ClientKey::of(ip);
    map_room(&state, &def.name, client)?;
    let price = admission::map(&def);
    within_request_limits(&state, "the map", price)?;
    state
        .registry
        .has_budget(price, Some(client))
        .map_err(no_room)?;
    let name = def.name.clone();
    let info = MapInfo {
        name: def.name.clone(),
        width: def.width as f64,
        height: def.height as f64,
    };
    let arena = off_workers(&state, "building the map", move || {
        Arc::new(Arena::new(def))
    })
    .await?;
    // Checked again: others may have uploaded while this one was built.
    map_room(&state, &name, client)?;
    let owner = Owner::new(Some(client));
    let owner_token = owner.token.clone().unwrap_or_default();
    let mut store = state
        .registry
        .maps
        .write()
        .unwrap_or_else(|e| e.into_inner());
    if !store.insert_owned(arena, owner, price.memory) {
        return Err(ApiError::conflict(format!("a map named {name:?} exists")));
    }
    Ok((
        StatusCode::CREATED,
        Json(MapCreated {
            map: info,
            owner_token,
        }),
    ))
}

/// Refuses a map upload whose name is taken, past the server's most maps, or past the
/// client's quota.
fn map_room(state: &AppState, name: &str, client: ClientKey) -> Result<(), ApiError> {
    let cfg = &state.registry.config;
    let store = state
        .registry
        .maps
        .read()
        .unwrap_or_else(|e| e.into_inner());
    if store.contains(name) {
        return Err(ApiError::conflict(format!("a map named {name:?} exists")));
    }
    if store.len() >= cfg.max_maps {
        state.registry.metrics.refuse(Refusal::MapsFull);
        return Err(ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "the server holds {} maps, its most; uploaded maps can be deleted by their owners",
                cfg.max_maps
            ),
        ));
    }
    if store.uploaded_by(client) >= cfg.max_maps_per_address {
        state.registry.metrics.refuse(Refusal::ClientQuota);
        return Err(ApiError::new(
            StatusCode::TOO_MANY_REQUESTS,
            format!(
                "{client} has uploaded {} maps, the most one client may keep; delete one (DELETE /api/maps/{{name}} with its owner_token)",
                cfg.max_maps_per_address
            ),
        ));
    }
    Ok(())
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
    let stored = state
        .registry
        .maps
        .read()
        .unwrap_or_else(|e| e.into_inner())
        .get(&name)
        .cloned();
    bearer.may_change(
        &state,
        stored.as_ref().map(|m| &m.owner),
        &format!("map {name:?}"),
    )?;
    let stored = stored.ok_or_else(|| ApiError::not_found(format!("no map {name:?}")))?;
    if stored.owner.token.is_none() {
        return Err(ApiError::new(
            StatusCode::FORBIDDEN,
            format!("map {name:?} is shipped with the server and cannot be removed"),
        ));
    }
    let in_use = state.registry.all().into_iter().any(|h| {
        Arc::ptr_eq(&h.hub.arena, &stored.arena)
            && h.hub.frames.borrow().status == lasertag_core::world::MatchStatus::Running
    });
    if in_use {
        return Err(ApiError::conflict(format!(
            "map {name:?} is in use by a running match; delete it when the match has ended"
        )));
    }
    let mut maps = state
        .registry
        .maps
        .write()
        .unwrap_or_else(|e| e.into_inner());
    // Only the map that was checked: a new one under the same name is not this request's.
    if maps
        .get(&name)
        .is_some_and(|m| Arc::ptr_eq(&m.arena, &stored.arena))
    {
        maps.remove(&name);
    }
    Ok(StatusCode::NO_CONTENT)
}

#[utoipa::path(get, path = "/api/matches",
    description = "This server's matches; in a fleet (`--fleet`), every node's, each with the `node` that hosts it.",
    responses((status = 200, body = [MatchSummary])))]
pub async fn list_matches(State(state): State<AppState>) -> Json<Vec<Listed>> {
    // Published summaries, not a question to each task: a match busy stepping thousands of
    // ticks must not hold up the lobby.
    let local: Vec<MatchSummary> = state
        .registry
        .all()
        .iter()
        .map(|h| MatchSummary::clone(&h.hub.summary.borrow()))
        .collect();
    // Other nodes' from the fleet's last read of the directory: never a wait on Redis.
    Json(match &state.fleet {
        Some(fleet) => fleet.listing(local),
        None => local
            .into_iter()
            .map(|s| Listed::Local(Box::new(s)))
            .collect(),
    })
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
) -> Result<axum::response::Response, ApiError> {
    let place = match query.get("place") {
        None => Place::Fleet,
        Some(p) => Place::parse(p).ok_or_else(|| {
            ApiError::bad_request(format!("place: {p:?} is not a placement (fleet or local)"))
        })?,
    };
    // Placed before anything is checked or built: the node it goes to checks it.
    if let Some(fleet) = &state.fleet
        && place == Place::Fleet
        && let crate::fleet::Placement::Remote(node) = fleet.place()
    {
        let message = format!("node {} has more room for a new match", node.id);
        if let Some(moved) = crate::http::fleet::redirect(node, "/api/matches?place=local", message)
        {
            return Ok(moved);
        }
    }
    // The operator's matches count against no address's quota.
    let client = (!bearer.is_admin(&state)).then(|| ClientKey::of(ip));
    let req = body
        .validate()
        .map_err(|e| ApiError::bad_request(e.to_string()))?;
    let cfg = &state.registry.config;
    let metrics = &state.registry.metrics;
    let agents = req.config.robots + req.config.opponents;
    if agents > cfg.max_agents_per_match {
        metrics.refuse(Refusal::TooManyAgents);
        return Err(ApiError::bad_request(format!(
            "robots + opponents: {} + {} = {agents} agents is over this server's limit of {} per match",
            req.config.robots, req.config.opponents, cfg.max_agents_per_match
        )));
    }
    // The tracker holds at most one role per opponent.
    let particles = req.config.tracker.particles_per_role * req.config.opponents;
    if particles > cfg.max_particles_per_match {
        metrics.refuse(Refusal::TooManyParticles);
        return Err(ApiError::bad_request(format!(
            "tracker.particles_per_role: {} per role × {} opponents = {particles} particles is over this server's limit of {} per match",
            req.config.tracker.particles_per_role,
            req.config.opponents,
            cfg.max_particles_per_match
        )));
    }
    // Refused before anything is built; `try_start` checks again under the lock.
    state.registry.has_room(client).map_err(no_room)?;
    // A stored map is built already (and was priced when it was added); an inline one is
    // validated, priced with the match and built for it alone.
    let source = match req.map {
        serde_json::Value::String(name) => {
            let maps = state
                .registry
                .maps
                .read()
                .unwrap_or_else(|e| e.into_inner());
            let arena = maps
                .get(&name)
                .map(|m| m.arena.clone())
                .ok_or_else(|| ApiError::not_found(format!("map: no map {name:?}")))?;
            MapSource::Stored(arena)
        }
        value @ serde_json::Value::Object(_) => {
            let def = off_workers(&state, "validating the map", move || {
                maps::from_value(value)
            })
            .await?
            .map_err(|e| {
                // Name the field as the request has it: `map.obstacles[2]`, or `map`.
                let path = if e.path == "map" {
                    e.path
                } else {
                    format!("map.{}", e.path)
                };
                ApiError::bad_request(format!("{path}: {}", e.message))
            })?;
            MapSource::Inline(def)
        }
        _ => {
            return Err(ApiError::bad_request(
                "map: must be a map name or a map object",
            ));
        }
    };
    let held = admission::held_back(&req.config, req.spectator_delay_ticks);
    let price = held
        + match &source {
            MapSource::Stored(arena) => admission::match_on(&arena.def, &req.config),
            MapSource::Inline(def) => admission::map(def) + admission::match_on(def, &req.config),
        };
    within_request_limits(&state, "the match", price)?;
    state.registry.has_budget(price, client).map_err(no_room)?;
    let config = req.config;
    let world = off_workers(&state, "setting up the match", move || {
        let arena = match source {
            MapSource::Stored(arena) => arena,
            MapSource::Inline(def) => Arc::new(Arena::new(def)),
        };
        World::new(arena, config)
    })
    .await?
    .map_err(|e| ApiError::bad_request(e.to_string()))?;
    let map_name = world.arena.def.name.clone();
    let meta = MatchMeta {
        id: random_id(8),
        map: map_name,
        clock: req.clock,
        players: 0,
        spectators: 0,
        free_slots: 0,
        bots_joinable: req.bots_joinable,
        spectator_delay_ticks: req.spectator_delay_ticks,
    };
    let owner = Owner::new(client);
    let owner_token = owner.token.clone().unwrap_or_default();
    let handle = state
        .registry
        .try_start(world, meta, owner, price)
        .map_err(no_room)?;
    // Asked of the task so that fields it owns (free slots) are filled in.
    let mut summary = handle.summary().await?;
    summary.node = state.fleet.as_ref().map(|f| f.me());
    Ok((
        StatusCode::CREATED,
        Json(MatchCreated {
            summary,
            owner_token,
        }),
    )
        .into_response())
}

/// Where a new match's map comes from.
enum MapSource {
    /// A map the server holds, built already.
    Stored(Arc<Arena>),
    /// A map in the request, validated and to be built for this match alone.
    Inline(lasertag_core::sim::arena::MapDef),
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
    Ok(Json(handle.state(sight).await?))
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
    let handle = state.registry.get(&id);
    let owner = handle.as_ref().map(|h| &*h.owner);
    bearer.may_change(&state, owner, &format!("match {id}"))?;
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
    Ok(Json(handle.step(ticks).await?))
}

#[utoipa::path(get, path = "/api/matches/{id}/belief",
    params(("id" = String, Path), ("robot" = Option<String>, Query, description = "a robot id (r0, r1, …): that robot's own belief (404 for anything that is not one of the match's robots); without it the team's merged view")),
    security((), ("owner_token" = [])),
    responses((status = 200, body = Belief), (status = 400, body = ErrorBody), (status = 401, body = ErrorBody),
              (status = 403, body = ErrorBody), (status = 404, body = ErrorBody)))]
pub async fn belief(
    State(state): State<AppState>,
    bearer: Bearer,
    Path(id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<Belief>, ApiError> {
    let (handle, sight) = readable(&state, &bearer, &id)?;
    let robot = match query.get("robot") {
        None => None,
        // Anything that is not one of the match's robots is a robot it does not have: 404,
        // like `r9` in a two-robot match. (A 400 for a malformed id made schema-valid strings
        // fail schemathesis, and a `pattern` on the parameter crashed its generator.)
        Some(r) => match r.parse() {
            Ok(AgentId::Robot(i)) => Some(i),
            _ => {
                return Err(ApiError::not_found(format!(
                    "robot: no robot {r:?} in this match (r0, r1, …)"
                )));
            }
        },
    };
    Ok(Json(handle.belief(robot, sight).await?))
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
    Ok(Json(handle.events(since, sight).await?))
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
    handle.order(opponent, order).await?;
    Ok(StatusCode::NO_CONTENT)
}

#[utoipa::path(post, path = "/api/matches/{id}/players", params(("id" = String, Path)), request_body = JoinRequest,
    responses((status = 201, body = Joined), (status = 400, body = ErrorBody), (status = 404, body = ErrorBody),
              (status = 409, body = ErrorBody, description = "no free slot, or the match is at the server's limit of players"),
              (status = 429, body = ErrorBody, description = "this client holds as many slots of the match as it may without playing them")))]
pub async fn join(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    Path(id): Path<String>,
    JsonBody(body): JsonBody<JoinRequest>,
) -> Result<impl IntoResponse, ApiError> {
    let handle = find(&state, &id)?;
    let joined = handle.join(body.name, Some(ClientKey::of(ip))).await?;
    Ok((StatusCode::CREATED, Json(joined)))
}

#[utoipa::path(get, path = "/api/matches/{id}/stats", params(("id" = String, Path)),
    responses((status = 200, body = MatchStats), (status = 404, body = ErrorBody)))]
pub async fn stats(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<MatchStats>, ApiError> {
    Ok(Json(find(&state, &id)?.stats().await?))
}
