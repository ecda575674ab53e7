//! The endpoints of trained robot teams (docs/api.md, "Trained robot teams"): list, upload
//! (an ONNX file as the body, `?name=`), remove.

use std::collections::HashMap;

use axum::Json;
use axum::body::Body;
use axum::extract::{Path, Query, Request, State};
use axum::http::StatusCode;
use axum::response::IntoResponse;

use crate::access::ClientKey;
use crate::http::auth::Bearer;
use crate::http::error::ApiError;
use crate::http::limits::ClientIp;
use crate::http::state::AppState;
use crate::metrics::Refusal;
use crate::protocol::{ErrorBody, PolicyCreated, PolicyInfo};
use crate::service::policies::{self, PoliciesError};

#[utoipa::path(get, path = "/api/policies", responses((status = 200, body = [PolicyInfo])))]
pub async fn list_policies(State(state): State<AppState>) -> Json<Vec<PolicyInfo>> {
    Json(policies::list(state.service()))
}

#[utoipa::path(post, path = "/api/policies",
    params(("name" = String, Query, description = "the policy's name: 1 to 64 letters, digits, '-' and '_'; matches name it as `\"planner\": \"policy:<name>\"`"),
        ("decide_every" = Option<u64>, Query, minimum = 1, maximum = 20, description = "ticks between its decisions (2 when not given): a policy trained at the environment's `ticks_per_step` k plays as trained at k")),
    request_body(content = Vec<u8>, content_type = "application/onnx",
        description = "An ONNX model: a chain of Gemm (or MatMul and Add), Relu, Tanh, Sigmoid, Identity and Flatten on 32-bit floats, from a robot observation of the research environment to its action (forward, turn, tag)"),
    responses((status = 201, body = PolicyCreated, links(
                  ("DeletePolicy" = (operation_id = "delete_policy", parameters(("name" = "$response.body#/name")))))),
              (status = 400, body = ErrorBody), (status = 409, body = ErrorBody),
              (status = 413, body = ErrorBody), (status = 429, body = ErrorBody), (status = 503, body = ErrorBody)))]
pub async fn add_policy(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    Query(query): Query<HashMap<String, String>>,
    req: Request<Body>,
) -> Result<impl IntoResponse, ApiError> {
    let name = query.get("name").cloned().unwrap_or_default();
    policies::check_name(&name)?;
    let every = policies::check_every(query.get("decide_every").map(String::as_str))?;
    let max = state.registry.config.max_policy_bytes;
    let bytes = axum::body::to_bytes(req.into_body(), max)
        .await
        .map_err(|_| {
            state.registry.metrics.refuse(Refusal::BodyTooLarge);
            PoliciesError::TooLarge { got: max + 1, max }
        })?;
    let created = policies::add(
        state.service(),
        ClientKey::of(ip),
        name,
        every,
        bytes.to_vec(),
    )
    .await?;
    Ok((StatusCode::CREATED, Json(created)))
}

#[utoipa::path(delete, path = "/api/policies/{name}", params(("name" = String, Path)),
    security(("owner_token" = [])),
    responses((status = 204), (status = 401, body = ErrorBody), (status = 403, body = ErrorBody),
              (status = 404, body = ErrorBody), (status = 409, body = ErrorBody)))]
pub async fn delete_policy(
    State(state): State<AppState>,
    bearer: Bearer,
    Path(name): Path<String>,
) -> Result<StatusCode, ApiError> {
    let stored = policies::stored(state.service(), &name)?;
    bearer.may_change(&state, &stored.owner, &format!("policy {name:?}"))?;
    policies::delete(state.service(), &name, stored)?;
    Ok(StatusCode::NO_CONTENT)
}
