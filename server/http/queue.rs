//! The queue over HTTP: `POST /api/queue` (enter), `DELETE /api/queue/{ticket}` (leave) and
//! the ticket's socket `/ws/queue/{ticket}` (see [`crate::service::queue`]).

use std::time::Duration;

use axum::Json;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};

use crate::access::ClientKey;
use crate::game::queue::TicketView;
use crate::game::view::Team;
use crate::http::auth::Bearer;
use crate::http::body::JsonBody;
use crate::http::error::ApiError;
use crate::http::limits::ClientIp;
use crate::http::socket::{self, Asked, End, Manner};
use crate::http::state::AppState;
use crate::protocol::ErrorBody;
use crate::protocol::fleet::Elsewhere;
use crate::protocol::parties::{self as wire, NameRequest, QueueTicket};
use crate::protocol::socket as common;
use crate::service::queue::{self, QueueRefused};

#[utoipa::path(post, operation_id = "queue_enter", path = "/api/queue", request_body = NameRequest,
    responses((status = 202, body = QueueTicket, description = "waiting: open /ws/queue/{ticket}?token=… to be told the seat"),
              (status = 307, body = Elsewhere, description = "in a fleet: the queue is another node's; the same request to `Location` joins it there"),
              (status = 400, body = ErrorBody), (status = 403, body = ErrorBody, description = "somebody keeps that name"),
              (status = 429, body = ErrorBody, description = "this client holds as many tickets as it may"),
              (status = 503, body = ErrorBody, description = "the queue holds as many people as it may")))]
pub async fn enter(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    JsonBody(body): JsonBody<NameRequest>,
) -> Result<Response, ApiError> {
    // One queue for the fleet, so that people on different nodes meet: a newcomer here
    // joins it on its node (the ticket, its socket and the match are all there).
    if let Some(fleet) = &state.fleet
        && let Some(home) = fleet.queue_home()
    {
        let message = format!("the queue is on node {}", home.id);
        if let Some(moved) = crate::http::fleet::redirect(home, "/api/queue", message) {
            return Ok(moved);
        }
    }
    let (ticket, token) = queue::enter(
        state.service(),
        ClientKey::of(ip),
        &body.name,
        body.name_token.as_deref(),
    )
    .await?;
    Ok((StatusCode::ACCEPTED, Json(QueueTicket { ticket, token })).into_response())
}

#[utoipa::path(delete, operation_id = "queue_leave", path = "/api/queue/{ticket}", params(("ticket" = String, Path)),
    responses((status = 204, description = "out of the queue"),
              (status = 401, body = ErrorBody), (status = 403, body = ErrorBody, description = "not the ticket's token"),
              (status = 404, body = ErrorBody, description = "no such ticket waiting")),
    security(("owner_token" = [])))]
pub async fn leave(
    State(state): State<AppState>,
    bearer: Bearer,
    Path(ticket): Path<String>,
) -> Result<StatusCode, ApiError> {
    let token = bearer.token().ok_or_else(|| {
        ApiError::new(
            StatusCode::UNAUTHORIZED,
            "authorization: leaving the queue needs `Bearer <token>`",
        )
    })?;
    state
        .registry
        .queue
        .leave(&ticket, token)
        .map_err(QueueRefused::from)?;
    Ok(StatusCode::NO_CONTENT)
}

/// `GET /ws/queue/{ticket}?token=…`: `waiting` about once a second, then `matched` with the
/// seat (the socket then closes), or an `error` when the ticket could not be seated.
pub async fn upgrade(
    State(state): State<AppState>,
    Asked {
        id: ticket,
        query,
        ip,
        ws,
    }: Asked,
) -> Result<Response, ApiError> {
    let registry = state.registry.clone();
    socket::refuse_while_stopping(&registry)?;
    socket::only_params(&query, &["token"])?;
    let token = socket::token_param(&query, "the queue's socket")?;
    let mut view = registry
        .queue
        .watch(&ticket, token)
        .map_err(QueueRefused::from)?;
    let admitted = socket::admit(&state, ip, ws)?;
    let span = tracing::info_span!("queue", %ticket, %ip);
    let manner = Manner {
        role: "queue",
        close_drain: Duration::from_millis(500),
        error: common::error,
    };
    Ok(admitted.open(&state, manner, span, move |mut sock| async move {
        let end: Result<(), End> = async {
            let shutdown = sock.shutdown().clone();
            view.mark_changed();
            loop {
                tokio::select! {
                    changed = view.changed() => {
                        if changed.is_err() {
                            return Err(End::normal("the ticket is gone"));
                        }
                        let now = view.borrow_and_update().clone();
                        match now {
                            TicketView::Waiting { seconds, people } => {
                                sock.text(wire::waiting_message(seconds, people).into()).await?;
                            }
                            TicketView::Matched { match_id, token } => {
                                let msg = wire::seat_message("matched", &match_id, &token, Team::Opponents);
                                sock.text(msg.into()).await?;
                                return Err(End::normal("matched"));
                            }
                            TicketView::Gone(why) => {
                                sock.text(wire::gone_message(&why).into()).await?;
                                return Err(End::normal("out of the queue"));
                            }
                        }
                    }
                    msg = sock.recv() => {
                        sock.read(msg, |_| Ok::<(), crate::protocol::Invalid>(())).await?;
                    }
                    _ = shutdown.cancelled() => return Err(End::going_away()),
                }
            }
        }
        .await;
        sock.close(end).await;
    }))
}
