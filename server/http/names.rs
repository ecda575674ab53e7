//! Names people keep: `POST /api/names` claims one, `DELETE /api/names/{name}` gives it up
//! (see [`crate::service::names`]).

use axum::Json;
use axum::extract::{Path, State};
use axum::http::StatusCode;

use crate::access::ClientKey;
use crate::http::auth::Bearer;
use crate::http::body::JsonBody;
use crate::http::error::ApiError;
use crate::http::limits::ClientIp;
use crate::http::state::AppState;
use crate::protocol::{ClaimRequest, ErrorBody, NameKept};
use crate::service::names;

#[utoipa::path(post, path = "/api/names", request_body = ClaimRequest,
    responses((status = 201, body = NameKept, description = "the name is yours: keep `name_token` (it is shown once)"),
              (status = 400, body = ErrorBody, description = "not a name (the message names the character or the length)"),
              (status = 409, body = ErrorBody, description = "the name, or a look-alike of it, is kept by somebody"),
              (status = 429, body = ErrorBody, description = "this client keeps as many names as it may, or the server takes no more claims this minute"),
              (status = 503, body = ErrorBody, description = "the server keeps no history, or as many names as it may")))]
pub async fn claim(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    JsonBody(body): JsonBody<ClaimRequest>,
) -> Result<(StatusCode, Json<NameKept>), ApiError> {
    let kept = names::claim(state.service(), body.name, ClientKey::of(ip)).await?;
    Ok((
        StatusCode::CREATED,
        Json(NameKept {
            name: kept.name,
            name_token: kept.token,
        }),
    ))
}

#[utoipa::path(delete, path = "/api/names/{name}", params(("name" = String, Path)),
    responses((status = 204, description = "given up: anyone may claim it, and its rating is gone"),
              (status = 400, body = ErrorBody), (status = 401, body = ErrorBody, description = "no name token"),
              (status = 403, body = ErrorBody, description = "not the name's token"),
              (status = 404, body = ErrorBody, description = "nobody keeps that name")),
    security(("owner_token" = [])))]
pub async fn release(
    State(state): State<AppState>,
    bearer: Bearer,
    Path(name): Path<String>,
) -> Result<StatusCode, ApiError> {
    let Some(token) = bearer.token() else {
        return Err(ApiError::new(
            StatusCode::UNAUTHORIZED,
            "authorization: giving a name up needs `Bearer <name_token>`",
        ));
    };
    names::release(state.service(), name, token).await?;
    Ok(StatusCode::NO_CONTENT)
}
