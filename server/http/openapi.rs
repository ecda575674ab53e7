//! The OpenAPI document of the API, generated from the handlers' annotations and the
//! protocol types, served at `GET /api/openapi.json`.

use axum::Json;
use utoipa::OpenApi;

use crate::http::handlers;
use crate::maps::MapFile;
use crate::protocol::*;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "lasertag",
        description = "Robots play laser tag against people: the HTTP API. Play and spectate over the WebSocket `GET /ws/matches/{id}` (`?token=` to play); its messages are described in the project's README. Every endpoint may answer 429 (too many requests from one address, with Retry-After); the server's limits are its command-line settings (README, Configuration)."
    ),
    paths(
        handlers::health,
        handlers::list_maps,
        handlers::get_map,
        handlers::add_map,
        handlers::list_matches,
        handlers::create_match,
        handlers::get_match,
        handlers::delete_match,
        handlers::step,
        handlers::belief,
        handlers::events,
        handlers::command,
        handlers::join,
        handlers::stats,
        crate::http::metrics,
    ),
    components(schemas(
        ErrorBody,
        Health,
        MapInfo,
        MapFile,
        CreateMatch,
        TrackerSettings,
        TrackerConfig,
        RadioSettings,
        RadioConfig,
        MatchSummary,
        MatchState,
        RobotState,
        OpponentState,
        PoseDto,
        DetectionDto,
        Belief,
        Role,
        Events,
        EventDto,
        StepRequest,
        OpponentCommand,
        JoinRequest,
        Joined,
        MatchStats
    ))
)]
pub struct ApiDoc;

pub async fn document() -> Json<utoipa::openapi::OpenApi> {
    Json(ApiDoc::openapi())
}
