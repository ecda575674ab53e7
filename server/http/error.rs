//! Every error the API returns: a status and `{"error": "..."}`, built in one place.

use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};

use crate::game::MatchError;
use crate::protocol::ErrorBody;
use lasertag_core::world::{InputError, OrderError, RobotOrderError};

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
        let status = match &e {
            MatchError::Input(input) => input_status(input),
            MatchError::NoRobot(_) | MatchError::Gone(_) => StatusCode::NOT_FOUND,
            MatchError::Invalid(_) => StatusCode::BAD_REQUEST,
            MatchError::Realtime { .. }
            | MatchError::Stepping(_)
            | MatchError::Finished(_)
            | MatchError::Full(_) => StatusCode::CONFLICT,
            MatchError::Quota(_) => StatusCode::TOO_MANY_REQUESTS,
            MatchError::NotAPlayer(_) => StatusCode::UNAUTHORIZED,
        };
        ApiError::new(status, e.to_string())
    }
}

/// A refused change from outside: an agent the match does not have is not found, an order
/// the agent cannot take now conflicts with its state, a malformed one is the client's.
fn input_status(e: &InputError) -> StatusCode {
    match e {
        InputError::Opponent(OrderError::UnknownOpponent(_))
        | InputError::Robot(RobotOrderError::UnknownRobot(_))
        | InputError::NoSlot(_) => StatusCode::NOT_FOUND,
        InputError::Opponent(OrderError::OutsideArena { .. }) => StatusCode::BAD_REQUEST,
        InputError::Opponent(_) | InputError::Robot(RobotOrderError::NotApiDriven) => {
            StatusCode::CONFLICT
        }
        InputError::Robot(_) | InputError::NotHuman(_) | InputError::NotAllOrNone => {
            StatusCode::BAD_REQUEST
        }
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
