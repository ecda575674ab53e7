//! `JsonBody<T>`: the request-body extractor of every POST. It enforces the size limit and
//! turns every parse failure into a 400 that names the field (axum's own `Json` answers in
//! plain text and without the path).

use axum::body::Body;
use axum::extract::{FromRequest, Request};
use serde::de::DeserializeOwned;

use crate::http::error::ApiError;
use crate::http::state::AppState;
use crate::metrics::Refusal;
use crate::protocol;

pub struct JsonBody<T>(pub T);

impl<T> FromRequest<AppState> for JsonBody<T>
where
    T: DeserializeOwned,
{
    type Rejection = ApiError;

    async fn from_request(req: Request<Body>, state: &AppState) -> Result<Self, Self::Rejection> {
        let max = state.registry.config.max_body_bytes;
        let bytes = axum::body::to_bytes(req.into_body(), max)
            .await
            .map_err(|_| {
                state.registry.metrics.refuse(Refusal::BodyTooLarge);
                ApiError::new(
                    axum::http::StatusCode::PAYLOAD_TOO_LARGE,
                    format!("body: larger than the limit of {max} bytes"),
                )
            })?;
        Ok(JsonBody(protocol::parse(&bytes)?))
    }
}
