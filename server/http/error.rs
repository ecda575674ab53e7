//! Every error the API returns: a status and `{"error": "..."}`, built in one place.

use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};

use crate::game::MatchError;
use crate::protocol::ErrorBody;

#[derive(Debug, Clone, PartialEq)]
pub struct ApiError {
    pub status: StatusCode,
    pub message: String,
}

impl ApiError {
    pub fn new(status: StatusCode, message: impl Into<String>) -> ApiError {
        ApiError {
            status,
            message: message.into(),
        }
    }

    pub fn bad_request(message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::BAD_REQUEST, message)
    }

    pub fn not_found(message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::NOT_FOUND, message)
    }

    pub fn conflict(message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::CONFLICT, message)
    }
}

impl From<MatchError> for ApiError {
    fn from(e: MatchError) -> ApiError {
        let status = match e {
            MatchError::BadRequest(_) => StatusCode::BAD_REQUEST,
            MatchError::NotFound(_) | MatchError::Gone(_) => StatusCode::NOT_FOUND,
            MatchError::Conflict(_) => StatusCode::CONFLICT,
            MatchError::Unauthorized(_) => StatusCode::UNAUTHORIZED,
            MatchError::TooMany(_) => StatusCode::TOO_MANY_REQUESTS,
        };
        ApiError::new(status, e.to_string())
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        if self.status.is_server_error() {
            tracing::error!(status = %self.status, error = %self.message, "request failed");
        }
        let mut response = (
            self.status,
            Json(ErrorBody {
                error: self.message,
            }),
        )
            .into_response();
        // RFC 9110: a 401 names the scheme that would be accepted.
        if self.status == StatusCode::UNAUTHORIZED {
            response.headers_mut().insert(
                axum::http::header::WWW_AUTHENTICATE,
                axum::http::HeaderValue::from_static("Bearer realm=\"lasertag\""),
            );
        }
        response
    }
}

/// A refused field of a request: always the client's to fix.
impl From<crate::protocol::Invalid> for ApiError {
    fn from(e: crate::protocol::Invalid) -> ApiError {
        ApiError::bad_request(e.to_string())
    }
}
