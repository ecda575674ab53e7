//! Every error the API returns: a status and `{"error": "..."}`, built in one place.

use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};

use crate::game::MatchError;
use crate::game::admission::NoRoom;
use crate::game::hub::SpectatorsRefused;
use crate::game::party::PartyError;
use crate::game::queue::QueueError;
use crate::game::replay::{HistoryError, InputsError, ReplayError};
use crate::game::showcase::{NoSeat, NoShowcase};
use crate::http::limits::BeliefRefused;
use crate::protocol::ErrorBody;
use crate::service::admit::OverLimit;
use crate::service::maps::MapsError;
use crate::service::matches::CreateError;
use crate::service::names::NamesError;
use crate::service::parties::PartiesError;
use crate::service::players::StatsError;
use crate::service::policies::PoliciesError;
use crate::service::queue::QueueRefused;
use crate::service::replays::ReplaysError;
use crate::service::{PoolError, ReplayBusy};
use lasertag_core::world::{InputError, OrderError, RobotOrderError};

#[derive(Debug, Clone, PartialEq)]
pub struct ApiError {
    pub status: StatusCode,
    pub message: String,
    /// Seconds after which the same request may succeed (`Retry-After`).
    pub retry_after: Option<u32>,
}

impl ApiError {
    pub fn new(status: StatusCode, message: impl Into<String>) -> ApiError {
        ApiError {
            status,
            message: message.into(),
            retry_after: None,
        }
    }

    /// The match `id` is there, but a server that restarted is still rebuilding it from its
    /// record (`game::resume`): 503, and when to ask again.
    pub fn resuming(id: &str) -> ApiError {
        ApiError {
            retry_after: Some(1),
            ..ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                format!("match {id} is being resumed after a restart; try again in a second"),
            )
        }
    }

    /// The match `id` as the registry has it: 503 while it is being resumed, 404 when it
    /// has none.
    pub fn no_match(registry: &crate::game::Registry, id: &str) -> ApiError {
        if registry.is_resuming(id) {
            ApiError::resuming(id)
        } else {
            ApiError::not_found(format!("no match {id}"))
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
            | MatchError::Full(_)
            | MatchError::RecordingFull(_) => StatusCode::CONFLICT,
            MatchError::Quota(_) | MatchError::WorkShare { .. } => StatusCode::TOO_MANY_REQUESTS,
            MatchError::WorkBusy { .. } => StatusCode::SERVICE_UNAVAILABLE,
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
        | InputError::NoSlot(_)
        | InputError::NoAgent(_) => StatusCode::NOT_FOUND,
        InputError::NoRobotSeat(_) => StatusCode::CONFLICT,
        InputError::Opponent(OrderError::OutsideArena { .. }) => StatusCode::BAD_REQUEST,
        InputError::Opponent(_) | InputError::Robot(RobotOrderError::NotApiDriven) => {
            StatusCode::CONFLICT
        }
        InputError::Robot(_)
        | InputError::NotHuman(_)
        | InputError::NotAllOrNone
        | InputError::MarkOutside => StatusCode::BAD_REQUEST,
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        // A 503 is a refusal the server means (full, draining, a match being resumed), told
        // to the client with when to try again and counted in `lasertag_refused_total`: not
        // an error to act on, and a crowd of them would bury the log's real ones.
        if self.status == StatusCode::SERVICE_UNAVAILABLE {
            tracing::debug!(error = %self.message, "refused with 503");
        } else if self.status.is_server_error() {
            tracing::error!(status = %self.status, error = %self.message, "request failed");
        }
        let mut response = (
            self.status,
            Json(ErrorBody {
                error: self.message,
            }),
        )
            .into_response();
        if let Some(s) = self.retry_after {
            response
                .headers_mut()
                .insert(axum::http::header::RETRY_AFTER, s.into());
        }
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

/// The server's or the client's room or budgets taken: the server's limits are 503 (try
/// again later), a client's share 429 (its own matches and maps are in the way).
impl From<NoRoom> for ApiError {
    fn from(e: NoRoom) -> ApiError {
        let status = match e {
            NoRoom::Client { .. } | NoRoom::ClientBudget { .. } => StatusCode::TOO_MANY_REQUESTS,
            NoRoom::Server(_)
            | NoRoom::Memory { .. }
            | NoRoom::Disk { .. }
            | NoRoom::Cpu { .. }
            | NoRoom::Draining => StatusCode::SERVICE_UNAVAILABLE,
        };
        ApiError::new(status, e.to_string())
    }
}

/// A spectator past its address's share of a match's places (429: its own sockets are in
/// the way), or past the match's (503: try again, or watch another).
impl From<SpectatorsRefused> for ApiError {
    fn from(e: SpectatorsRefused) -> ApiError {
        let status = match e {
            SpectatorsRefused::Client { .. } => StatusCode::TOO_MANY_REQUESTS,
            SpectatorsRefused::Full { .. } => StatusCode::SERVICE_UNAVAILABLE,
        };
        ApiError::new(status, e.to_string())
    }
}

/// No showcase seat: the join's own refusal, the server's room (503), or every showcase
/// full at the most the server runs (503).
impl From<NoSeat> for ApiError {
    fn from(e: NoSeat) -> ApiError {
        match e {
            NoSeat::Join(e) => e.into(),
            NoSeat::NoShowcase(NoShowcase::NoRoom(e)) => e.into(),
            NoSeat::NoShowcase(NoShowcase::NoMap) | NoSeat::AllFull => {
                ApiError::new(StatusCode::SERVICE_UNAVAILABLE, e.to_string())
            }
        }
    }
}

/// A belief read past a share of belief bytes: the client's (429) or everyone's (503),
/// with when to read again; or a belief that moved on mid-read (503).
impl From<BeliefRefused> for ApiError {
    fn from(e: BeliefRefused) -> ApiError {
        let (status, retry_after) = match e {
            BeliefRefused::Client { retry_s, .. } => (StatusCode::TOO_MANY_REQUESTS, Some(retry_s)),
            BeliefRefused::Server { retry_s, .. } => {
                (StatusCode::SERVICE_UNAVAILABLE, Some(retry_s))
            }
            BeliefRefused::MovedOn => (StatusCode::SERVICE_UNAVAILABLE, None),
        };
        ApiError {
            retry_after,
            ..ApiError::new(status, e.to_string())
        }
    }
}

/// A request priced past a per-request limit is the client's to shrink.
impl From<OverLimit> for ApiError {
    fn from(e: OverLimit) -> ApiError {
        ApiError::bad_request(e.to_string())
    }
}

/// A job of the blocking pool that did not finish is the server's fault.
impl From<PoolError> for ApiError {
    fn from(e: PoolError) -> ApiError {
        ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string())
    }
}

/// A store that failed is the server's fault, not the request's.
fn history(e: HistoryError) -> ApiError {
    tracing::error!("history: {e}");
    ApiError::new(
        StatusCode::INTERNAL_SERVER_ERROR,
        format!("the history could not be read: {e}"),
    )
}

impl From<CreateError> for ApiError {
    fn from(e: CreateError) -> ApiError {
        match e {
            CreateError::NoRoom(e) => e.into(),
            CreateError::OverLimit(e) => e.into(),
            CreateError::Pool(e) => e.into(),
            CreateError::Match(e) => e.into(),
            CreateError::NoMap(_) => ApiError::not_found(e.to_string()),
            CreateError::Invalid(_)
            | CreateError::TooManyAgents { .. }
            | CreateError::TooManyParticles { .. }
            | CreateError::BadMap(_)
            | CreateError::NotAMap
            | CreateError::NoPolicy(_)
            | CreateError::PolicyMisfit { .. }
            | CreateError::Setup(_) => ApiError::bad_request(e.to_string()),
        }
    }
}

impl From<PoliciesError> for ApiError {
    fn from(e: PoliciesError) -> ApiError {
        match e {
            PoliciesError::NoRoom(e) => e.into(),
            PoliciesError::OverLimit(e) => e.into(),
            PoliciesError::Pool(e) => e.into(),
            PoliciesError::NotFound(_) => ApiError::not_found(e.to_string()),
            PoliciesError::Invalid(_)
            | PoliciesError::BadName(_)
            | PoliciesError::BadEvery(_)
            | PoliciesError::TooSlow { .. }
            | PoliciesError::Misfit(_) => ApiError::bad_request(e.to_string()),
            PoliciesError::TooLarge { .. } => {
                ApiError::new(StatusCode::PAYLOAD_TOO_LARGE, e.to_string())
            }
            PoliciesError::Taken(_) | PoliciesError::InUse(_) => ApiError::conflict(e.to_string()),
            PoliciesError::Full(_) => ApiError::new(StatusCode::SERVICE_UNAVAILABLE, e.to_string()),
            PoliciesError::Quota { .. } => {
                ApiError::new(StatusCode::TOO_MANY_REQUESTS, e.to_string())
            }
            PoliciesError::Shipped(_) => ApiError::new(StatusCode::FORBIDDEN, e.to_string()),
            PoliciesError::Store(_) => {
                tracing::error!("policies: {e}");
                ApiError::new(StatusCode::SERVICE_UNAVAILABLE, e.to_string())
            }
        }
    }
}

impl From<MapsError> for ApiError {
    fn from(e: MapsError) -> ApiError {
        match e {
            MapsError::NoRoom(e) => e.into(),
            MapsError::OverLimit(e) => e.into(),
            MapsError::Pool(e) => e.into(),
            MapsError::NotFound(_) => ApiError::not_found(e.to_string()),
            MapsError::Invalid(_) => ApiError::bad_request(e.to_string()),
            MapsError::Taken(_) | MapsError::InUse(_) => ApiError::conflict(e.to_string()),
            MapsError::Full(_) => ApiError::new(StatusCode::SERVICE_UNAVAILABLE, e.to_string()),
            MapsError::Quota { .. } => ApiError::new(StatusCode::TOO_MANY_REQUESTS, e.to_string()),
            MapsError::Shipped(_) => ApiError::new(StatusCode::FORBIDDEN, e.to_string()),
        }
    }
}

impl From<ReplaysError> for ApiError {
    fn from(e: ReplaysError) -> ApiError {
        match e {
            ReplaysError::History(e) => history(e),
            ReplaysError::Pool(e) => e.into(),
            ReplaysError::NotFound(_) | ReplaysError::PastTheEnd { .. } | ReplaysError::NoRobot => {
                ApiError::not_found(e.to_string())
            }
            // The store could not give a window of a long record's inputs: its trouble, not
            // the request's (the record gone from the store is gone for good).
            ReplaysError::Replay(ReplayError::Inputs(InputsError::Gone)) => {
                ApiError::not_found(e.to_string())
            }
            ReplaysError::Replay(ReplayError::Inputs(_)) => {
                ApiError::new(StatusCode::SERVICE_UNAVAILABLE, e.to_string())
            }
            ReplaysError::Replay(_) => ApiError::bad_request(e.to_string()),
            ReplaysError::Busy(busy) => {
                let status = match busy {
                    ReplayBusy::Client { .. } => StatusCode::TOO_MANY_REQUESTS,
                    ReplayBusy::Server { .. } => StatusCode::SERVICE_UNAVAILABLE,
                    ReplayBusy::Failed(_) => StatusCode::INTERNAL_SERVER_ERROR,
                };
                ApiError::new(status, busy.to_string())
            }
        }
    }
}

impl From<StatsError> for ApiError {
    fn from(e: StatsError) -> ApiError {
        match e {
            StatsError::History(e) => history(e),
            StatsError::Pool(e) => e.into(),
            StatsError::NoHistory | StatsError::NoPlayer(_) => ApiError::not_found(e.to_string()),
        }
    }
}

impl From<NamesError> for ApiError {
    fn from(e: NamesError) -> ApiError {
        let status = match &e {
            NamesError::History(_) => {
                tracing::error!("names: {e}");
                StatusCode::INTERNAL_SERVER_ERROR
            }
            NamesError::Pool(e) => return e.clone().into(),
            NamesError::Invalid(_) => StatusCode::BAD_REQUEST,
            NamesError::Taken { .. } => StatusCode::CONFLICT,
            NamesError::ClientFull { .. } => StatusCode::TOO_MANY_REQUESTS,
            NamesError::Busy { wait, .. } => {
                let mut error = ApiError::new(StatusCode::TOO_MANY_REQUESTS, e.to_string());
                error.retry_after = Some(wait.as_secs().clamp(1, u64::from(u32::MAX)) as u32);
                return error;
            }
            NamesError::NoHistory | NamesError::ServerFull(_) => StatusCode::SERVICE_UNAVAILABLE,
            NamesError::NotClaimed(_) => StatusCode::NOT_FOUND,
            NamesError::NeedsToken(_) | NamesError::WrongToken(_) => StatusCode::FORBIDDEN,
        };
        ApiError::new(status, e.to_string())
    }
}

impl From<PartiesError> for ApiError {
    fn from(e: PartiesError) -> ApiError {
        let status = match &e {
            PartiesError::Name(_) | PartiesError::Create(_) => {
                return match e {
                    PartiesError::Name(e) => e.into(),
                    PartiesError::Create(e) => e.into(),
                    _ => ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
                };
            }
            PartiesError::Seat { error, .. } => ApiError::from(error.clone()).status,
            PartiesError::NoMap(_) => StatusCode::BAD_REQUEST,
            PartiesError::Party(p) => match p {
                PartyError::NoParty(_) | PartyError::NoMember(..) => StatusCode::NOT_FOUND,
                PartyError::Full(_)
                | PartyError::NotReady(_)
                | PartyError::Playing(_)
                | PartyError::HostLeaves => StatusCode::CONFLICT,
                PartyError::NotMember(_) | PartyError::NotHost(_) | PartyError::NotYours(_) => {
                    StatusCode::FORBIDDEN
                }
                PartyError::TooManyMisses(wait) => {
                    let mut error = ApiError::new(StatusCode::TOO_MANY_REQUESTS, e.to_string());
                    error.retry_after = Some((*wait).clamp(1, u64::from(u32::MAX)) as u32);
                    return error;
                }
                PartyError::TooManyHosted(_) => StatusCode::TOO_MANY_REQUESTS,
                PartyError::ServerFull(_) => StatusCode::SERVICE_UNAVAILABLE,
                PartyError::Invalid(_) => StatusCode::BAD_REQUEST,
            },
        };
        ApiError::new(status, e.to_string())
    }
}

impl From<QueueRefused> for ApiError {
    fn from(e: QueueRefused) -> ApiError {
        let status = match &e {
            QueueRefused::Name(_) => {
                return match e {
                    QueueRefused::Name(e) => e.into(),
                    QueueRefused::Queue(_) => {
                        ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string())
                    }
                };
            }
            QueueRefused::Queue(q) => match q {
                QueueError::NoTicket(_) => StatusCode::NOT_FOUND,
                QueueError::WrongToken(_) => StatusCode::FORBIDDEN,
                QueueError::ClientFull(_) => StatusCode::TOO_MANY_REQUESTS,
                QueueError::Full(_) => StatusCode::SERVICE_UNAVAILABLE,
            },
        };
        ApiError::new(status, e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_servers_limits_are_503_and_a_clients_share_429() {
        let server = ApiError::from(NoRoom::Draining);
        assert_eq!(server.status, StatusCode::SERVICE_UNAVAILABLE);
        assert!(
            server.message.contains("shutting down"),
            "{}",
            server.message
        );
        let client = ApiError::from(NoRoom::Client {
            client: crate::access::ClientKey::of([10, 0, 0, 1].into()),
            max: 3,
        });
        assert_eq!(client.status, StatusCode::TOO_MANY_REQUESTS);
        assert!(
            client.message.starts_with("10.0.0.1 holds 3 matches"),
            "{}",
            client.message
        );
    }
}
