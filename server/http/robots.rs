//! The endpoints of robots driven from outside (`"planner": "api"`): one robot's command,
//! one robot's observation, and the environment step over all of them.

use axum::Json;
use axum::extract::{Path, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};

use crate::access::ClientKey;
use crate::game::MatchHandle;
use crate::game::Sight;
use crate::game::work::RequestBound;
use crate::http::auth::Bearer;
use crate::http::body::JsonBody;
use crate::http::error::ApiError;
use crate::http::handlers::{owned, readable};
use crate::http::limits::ClientIp;
use crate::http::state::AppState;
use crate::protocol::ErrorBody;
use crate::protocol::robots::{
    self, ActRequest, ActResponse, Observation, RobotCommand, robot_index,
};
use lasertag_core::world::{MatchStatus, WorldInput};

/// Charges the path search `inputs` may take to the server's and the client's budgets of
/// it (`game::work`) before the match runs them; the operator pays no client's share.
fn charge(
    state: &AppState,
    bearer: &Bearer,
    ip: std::net::IpAddr,
    handle: &MatchHandle,
    inputs: &[WorldInput],
) -> Result<(), ApiError> {
    let registry = &state.registry;
    let bound = RequestBound(registry.config.max_command_work);
    let work = bound.work(inputs, handle.hub.arena.grid.len());
    let client = (!bearer.is_admin(state)).then(|| ClientKey::of(ip));
    Ok(registry.work.take(&registry.config, client, work)?)
}

/// Refuses orders for robots that are pursuer slots: a person's keys drive those, and the
/// owner's API must not take their body from them (409).
fn not_seats(handle: &MatchHandle, inputs: &[WorldInput]) -> Result<(), ApiError> {
    let config = handle.hub.summary.borrow().config.clone();
    let seats = config.robots.saturating_sub(config.pursuer_slots)..config.robots;
    for input in inputs {
        if let WorldInput::Robot { robot, .. } = input
            && seats.contains(robot)
        {
            return Err(ApiError::new(
                StatusCode::CONFLICT,
                format!("r{robot} is a pursuer slot: a person drives it, not the API"),
            ));
        }
    }
    Ok(())
}

/// The index of robot `rid`, or a 404 naming it.
fn robot(id: &str, rid: &str) -> Result<usize, ApiError> {
    // Like the belief's `?robot=`, anything that is not a robot id names no robot here.
    robot_index(rid)
        .ok_or_else(|| ApiError::not_found(format!("no robot {rid:?} in match {id} (r0, r1, …)")))
}

#[utoipa::path(post, path = "/api/matches/{id}/robots/{rid}/command",
    params(("id" = String, Path), ("rid" = String, Path)), request_body = RobotCommand,
    security(("owner_token" = [])),
    responses((status = 204), (status = 400, body = ErrorBody), (status = 401, body = ErrorBody),
              (status = 403, body = ErrorBody), (status = 404, body = ErrorBody),
              (status = 409, body = ErrorBody, description = "the robot is not driven from outside, or is a person's (a pursuer slot)"),
              (status = 429, body = ErrorBody, description = "this client's share of the path search for waypoints is taken for now"),
              (status = 503, body = ErrorBody, description = "the server's path search for waypoints is taken for now")))]
pub async fn command(
    State(state): State<AppState>,
    bearer: Bearer,
    ClientIp(ip): ClientIp,
    Path((id, rid)): Path<(String, String)>,
    JsonBody(body): JsonBody<RobotCommand>,
) -> Result<StatusCode, ApiError> {
    let handle = owned(&state, &bearer, &id)?;
    let order = body.order("")?;
    let robot = robot(&id, &rid)?;
    let input = WorldInput::Robot { robot, order };
    not_seats(&handle, std::slice::from_ref(&input))?;
    charge(&state, &bearer, ip, &handle, std::slice::from_ref(&input))?;
    handle.apply(input).await?;
    Ok(StatusCode::NO_CONTENT)
}

#[utoipa::path(get, path = "/api/matches/{id}/robots/{rid}/observation",
    params(("id" = String, Path), ("rid" = String, Path)),
    security((), ("owner_token" = [])),
    responses((status = 200, body = Observation), (status = 401, body = ErrorBody),
              (status = 403, body = ErrorBody, description = "people play this match: what its robots know is its owner's until it ends"),
              (status = 404, body = ErrorBody)))]
pub async fn observation(
    State(state): State<AppState>,
    bearer: Bearer,
    Path((id, rid)): Path<(String, String)>,
) -> Result<Json<Observation>, ApiError> {
    let (handle, sight) = readable(&state, &bearer, &id)?;
    // A robot's knowledge includes where it is and whom it sees: live, that would show a
    // person the robots hidden from them, so a match people play keeps it to its owner (the
    // delayed views are built from frames, which do not carry it).
    let running = handle.hub.summary.borrow().status == MatchStatus::Running;
    if sight == Sight::Public && handle.hub.delay_ticks > 0 && running {
        return Err(ApiError::new(
            StatusCode::FORBIDDEN,
            format!(
                "people play match {id}: its robots' observations are its owner's until it ends"
            ),
        ));
    }
    let robot = robot(&id, &rid)?;
    Ok(Json(
        handle.read(sight, robots::read_observation(robot)).await?,
    ))
}

#[utoipa::path(post, path = "/api/matches/{id}/act", params(("id" = String, Path)),
    request_body = ActRequest,
    security(("owner_token" = [])),
    responses((status = 200, body = ActResponse), (status = 400, body = ErrorBody), (status = 401, body = ErrorBody),
              (status = 403, body = ErrorBody), (status = 404, body = ErrorBody),
              (status = 409, body = ErrorBody, description = "a real-time match, one already stepping, or robots not driven from outside"),
              (status = 429, body = ErrorBody, description = "this client's share of the path search for waypoints is taken for now"),
              (status = 503, body = ErrorBody, description = "the server's path search for waypoints is taken for now")))]
pub async fn act(
    State(state): State<AppState>,
    bearer: Bearer,
    ClientIp(ip): ClientIp,
    Path(id): Path<String>,
    JsonBody(body): JsonBody<ActRequest>,
) -> Result<Response, ApiError> {
    let handle = owned(&state, &bearer, &id)?;
    let scans = body.scans;
    let (orders, ticks) = body.orders()?;
    let inputs: Vec<WorldInput> = orders
        .into_iter()
        .map(|(robot, order)| WorldInput::Robot { robot, order })
        .collect();
    not_seats(&handle, &inputs)?;
    charge(&state, &bearer, ip, &handle, &inputs)?;
    let mut answer = handle.step("act", inputs, ticks, robots::read_act).await?;
    answer.encode_scans(scans);
    // Written into a buffer of about the answer's size (axum's `Json` starts at 128 bytes
    // and grows, copying, to the kilobyte or so an observation takes).
    let mut body = Vec::with_capacity(512 + 1536 * answer.observations.len());
    serde_json::to_writer(&mut body, &answer).map_err(|e| {
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("writing the answer: {e}"),
        )
    })?;
    Ok(([(header::CONTENT_TYPE, "application/json")], body).into_response())
}
