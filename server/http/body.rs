//! `JsonBody<T>`: the request-body extractor of every POST. It enforces the size limit and
//! turns every parse failure into a 400 that names the field (axum's own `Json` answers in
//! plain text and without the path).

use axum::body::Body;
use axum::extract::{FromRequest, Request};
use serde::de::DeserializeOwned;

use crate::http::{ApiError, MAX_BODY_BYTES};
use crate::protocol;

pub struct JsonBody<T>(pub T);

impl<S, T> FromRequest<S> for JsonBody<T>
where
    S: Send + Sync,
    T: DeserializeOwned,
{
    type Rejection = ApiError;

    async fn from_request(req: Request<Body>, _state: &S) -> Result<Self, Self::Rejection> {
        let bytes = axum::body::to_bytes(req.into_body(), MAX_BODY_BYTES)
            .await
            .map_err(|_| {
                ApiError::new(
                    axum::http::StatusCode::PAYLOAD_TOO_LARGE,
                    format!("body: larger than the limit of {MAX_BODY_BYTES} bytes"),
                )
            })?;
        protocol::parse(&bytes)
            .map(JsonBody)
            .map_err(ApiError::bad_request)
    }
}
