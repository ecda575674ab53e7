//! Parties over HTTP: `/api/parties` (make, read, join, change, leave, start), the invite's
//! QR code, and the room's socket `/ws/parties/{code}` (see [`crate::service::parties`]).

use std::time::Duration;

use axum::Json;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};

use crate::access::ClientKey;
use crate::game::party::RoomView;
use crate::http::auth::Bearer;
use crate::http::body::JsonBody;
use crate::http::error::ApiError;
use crate::http::limits::ClientIp;
use crate::http::socket::{self, Asked, End, Manner};
use crate::http::state::AppState;
use crate::protocol::ErrorBody;
use crate::protocol::parties::{
    self as wire, MemberPatch, NameRequest, PartyCreated, PartyDto, PartyJoined, PartyStarted,
};
use crate::protocol::socket as common;
use crate::service::parties;

/// Close codes of the room's socket a page acts on: the room is gone (it lapsed), or the
/// member was removed from it (the private range of RFC 6455, 4000–4999).
const ROOM_GONE: u16 = 4404;
const REMOVED: u16 = 4403;

fn token_of<'a>(bearer: &'a Bearer, what: &str) -> Result<&'a str, ApiError> {
    bearer.token().ok_or_else(|| {
        ApiError::new(
            StatusCode::UNAUTHORIZED,
            format!("authorization: {what} needs `Bearer <member_token>`"),
        )
    })
}

/// The page's address that joins room `code`, on the host the caller used.
fn invite_url(headers: &HeaderMap, code: &str) -> String {
    let host = headers
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .filter(|h| {
            h.len() <= 255
                && h.bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b".-:[]".contains(&b))
        });
    match host {
        Some(host) => format!("http://{host}/#/party/{code}"),
        None => format!("/#/party/{code}"),
    }
}

#[utoipa::path(post, operation_id = "party_create", path = "/api/parties", request_body = NameRequest,
    responses((status = 201, body = PartyCreated, description = "a room, hosted by the caller: keep `member_token` (shown once)"),
              (status = 400, body = ErrorBody, description = "not a name"),
              (status = 403, body = ErrorBody, description = "somebody keeps that name: send its name_token"),
              (status = 429, body = ErrorBody, description = "this client hosts as many parties as it may"),
              (status = 503, body = ErrorBody, description = "the server holds as many parties as it may")))]
pub async fn create(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    headers: HeaderMap,
    JsonBody(body): JsonBody<NameRequest>,
) -> Result<(StatusCode, Json<PartyCreated>), ApiError> {
    let (code, member_id, member_token) = parties::create(
        state.service(),
        ClientKey::of(ip),
        &body.name,
        body.name_token.as_deref(),
    )
    .await?;
    Ok((
        StatusCode::CREATED,
        Json(PartyCreated {
            invite_url: invite_url(&headers, &code),
            code,
            member_id,
            member_token,
        }),
    ))
}

#[utoipa::path(get, operation_id = "party_get", path = "/api/parties/{code}", params(("code" = String, Path)),
    responses((status = 200, body = PartyDto),
              (status = 404, body = ErrorBody, description = "no such party"),
              (status = 429, body = ErrorBody, description = "this client named too many codes that name no party")))]
pub async fn get(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    Path(code): Path<String>,
) -> Result<Json<PartyDto>, ApiError> {
    let view = state
        .registry
        .parties
        .get(&code, Some(ClientKey::of(ip)))
        .map_err(parties::PartiesError::from)?;
    Ok(Json(wire::party(&view)))
}

#[utoipa::path(post, operation_id = "party_join", path = "/api/parties/{code}/members", params(("code" = String, Path)),
    request_body = NameRequest,
    responses((status = 201, body = PartyJoined, description = "in the room: keep `member_token` (shown once)"),
              (status = 400, body = ErrorBody), (status = 403, body = ErrorBody, description = "somebody keeps that name"),
              (status = 404, body = ErrorBody, description = "no such party"),
              (status = 409, body = ErrorBody, description = "the room is full (8 people)"),
              (status = 429, body = ErrorBody, description = "this client named too many codes that name no party")))]
pub async fn join(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    Path(code): Path<String>,
    JsonBody(body): JsonBody<NameRequest>,
) -> Result<(StatusCode, Json<PartyJoined>), ApiError> {
    let (member_id, member_token) = parties::join(
        state.service(),
        ClientKey::of(ip),
        &code,
        &body.name,
        body.name_token.as_deref(),
    )
    .await?;
    Ok((
        StatusCode::CREATED,
        Json(PartyJoined {
            member_id,
            member_token,
        }),
    ))
}

#[utoipa::path(patch, operation_id = "party_change", path = "/api/parties/{code}/members/{member_id}",
    params(("code" = String, Path), ("member_id" = String, Path)), request_body = MemberPatch,
    responses((status = 200, body = PartyDto, description = "the room as it is now"),
              (status = 400, body = ErrorBody), (status = 401, body = ErrorBody, description = "no member token"),
              (status = 403, body = ErrorBody, description = "not a member's token, or not the host's for another member's side or the settings"),
              (status = 404, body = ErrorBody, description = "no such party or member"),
              (status = 429, body = ErrorBody, description = "this client named too many codes that name no party")),
    security(("owner_token" = [])))]
pub async fn change(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    bearer: Bearer,
    Path((code, member)): Path<(String, String)>,
    JsonBody(body): JsonBody<MemberPatch>,
) -> Result<Json<PartyDto>, ApiError> {
    let token = token_of(&bearer, "changing a member")?;
    let view = parties::change(
        state.service(),
        ClientKey::of(ip),
        &code,
        &member,
        token,
        body.change(),
    )?;
    Ok(Json(wire::party(&view)))
}

#[utoipa::path(delete, operation_id = "party_remove", path = "/api/parties/{code}/members/{member_id}",
    params(("code" = String, Path), ("member_id" = String, Path)),
    responses((status = 200, body = PartyDto, description = "the room without them"),
              (status = 401, body = ErrorBody), (status = 403, body = ErrorBody, description = "neither the member's nor the host's token"),
              (status = 404, body = ErrorBody, description = "no such party or member"),
              (status = 409, body = ErrorBody, description = "the host cannot leave their own party"),
              (status = 429, body = ErrorBody, description = "this client named too many codes that name no party")),
    security(("owner_token" = [])))]
pub async fn remove(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    bearer: Bearer,
    Path((code, member)): Path<(String, String)>,
) -> Result<Json<PartyDto>, ApiError> {
    let token = token_of(&bearer, "removing a member")?;
    let view = state
        .registry
        .parties
        .remove(&code, &member, token, ClientKey::of(ip))
        .map_err(parties::PartiesError::from)?;
    Ok(Json(wire::party(&view)))
}

#[utoipa::path(post, operation_id = "party_start", path = "/api/parties/{code}/start", params(("code" = String, Path)),
    responses((status = 201, body = PartyStarted, description = "the match runs, every member seated: each member's socket gets its seat"),
              (status = 401, body = ErrorBody), (status = 403, body = ErrorBody, description = "not the host's token"),
              (status = 404, body = ErrorBody, description = "no such party"),
              (status = 409, body = ErrorBody, description = "not everyone is ready (the message names who), or the party plays already"),
              (status = 429, body = ErrorBody), (status = 503, body = ErrorBody, description = "the server has no room for the match")),
    security(("owner_token" = [])))]
pub async fn start(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    bearer: Bearer,
    Path(code): Path<String>,
) -> Result<(StatusCode, Json<PartyStarted>), ApiError> {
    let token = token_of(&bearer, "starting the match")?;
    let match_id = parties::start(state.service(), ClientKey::of(ip), &code, token).await?;
    Ok((StatusCode::CREATED, Json(PartyStarted { match_id })))
}

#[utoipa::path(get, operation_id = "party_invite", path = "/api/parties/{code}/invite.svg", params(("code" = String, Path)),
    responses((status = 200, content_type = "image/svg+xml", body = String, description = "the invite link as a QR code"),
              (status = 404, body = ErrorBody), (status = 429, body = ErrorBody)))]
pub async fn invite(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    headers: HeaderMap,
    Path(code): Path<String>,
) -> Result<Response, ApiError> {
    let view = state
        .registry
        .parties
        .get(&code, Some(ClientKey::of(ip)))
        .map_err(parties::PartiesError::from)?;
    let url = invite_url(&headers, &view.party.code);
    let qr = qrcode::QrCode::with_error_correction_level(url.as_bytes(), qrcode::EcLevel::M)
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, format!("QR code: {e}")))?;
    let svg = qr
        .render::<qrcode::render::svg::Color<'_>>()
        .min_dimensions(200, 200)
        .quiet_zone(true)
        .build();
    Ok((
        [
            (header::CONTENT_TYPE, "image/svg+xml"),
            (header::CACHE_CONTROL, "private, max-age=600"),
        ],
        svg,
    )
        .into_response())
}

/// `GET /ws/parties/{code}?token=<member_token>`: the room whenever it changes, and this
/// member's seat when the host starts.
pub async fn upgrade(
    State(state): State<AppState>,
    Asked {
        id: code,
        query,
        ip,
        ws,
    }: Asked,
) -> Result<Response, ApiError> {
    let registry = state.registry.clone();
    socket::refuse_while_stopping(&registry)?;
    socket::only_params(&query, &["token"])?;
    let token = socket::token_param(&query, "the room's socket")?;
    let (member, mut room) = registry
        .parties
        .subscribe(&code, token, ClientKey::of(ip))
        .map_err(parties::PartiesError::from)?;
    let admitted = socket::admit(&state, ip, ws)?;
    let code = room.borrow().party.code.clone();
    let span = tracing::info_span!("party", %code, %member, %ip);
    let manner = Manner {
        role: "party",
        close_drain: Duration::from_millis(500),
        error: common::error,
    };
    Ok(admitted.open(&state, manner, span, move |mut sock| async move {
        registry.parties.connected(&code, &member, true);
        // Starts already told on this socket: a member who (re)connects while the party
        // plays is told their seat again, and goes back to the match.
        let mut told = 0;
        let end: Result<(), End> = async {
            let shutdown = sock.shutdown().clone();
            room.mark_changed();
            loop {
                tokio::select! {
                    changed = room.changed() => {
                        if changed.is_err() {
                            return Err(End::Close(ROOM_GONE, "the party is gone".into()));
                        }
                        let view: RoomView = room.borrow_and_update().clone();
                        if view.gone {
                            return Err(End::Close(ROOM_GONE, "the party lapsed".into()));
                        }
                        if view.party.member(&member).is_none() {
                            return Err(End::Close(REMOVED, "the host removed you from the party".into()));
                        }
                        sock.text(wire::party_message(&view).into()).await?;
                        if let Some(started) = &view.started
                            && started.serial > told
                        {
                            told = started.serial;
                            if let Some((seat, team)) = started.seats.get(&member) {
                                let msg = wire::seat_message("start", &started.match_id, seat, *team);
                                sock.text(msg.into()).await?;
                            }
                        }
                    }
                    msg = sock.recv() => {
                        // The page says nothing but pings; anything else is refused by
                        // the socket's own rules.
                        sock.read(msg, |_| Ok::<(), crate::protocol::Invalid>(())).await?;
                    }
                    _ = shutdown.cancelled() => return Err(End::restarting()),
                }
            }
        }
        .await;
        registry.parties.connected(&code, &member, false);
        sock.close(end).await;
    }))
}
