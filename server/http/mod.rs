//! The HTTP interface: [`app`] builds the axum router that the binary serves and the tests
//! call directly. Handlers parse and validate at the edge ([`body::JsonBody`]), then talk to
//! the [`Registry`] and to match tasks; they never hold a world.

mod body;
mod error;
mod handlers;
mod openapi;
pub mod ws;

use std::path::PathBuf;
use std::sync::Arc;

use axum::Router;
use axum::extract::{DefaultBodyLimit, OriginalUri};
use axum::handler::HandlerWithoutStateExt;
use axum::http::StatusCode;
use axum::routing::{get, post};
use tower_http::compression::CompressionLayer;
use tower_http::services::ServeDir;
use tower_http::trace::TraceLayer;

use crate::game::Registry;
pub use error::ApiError;

/// Largest request body accepted (413 past it).
pub const MAX_BODY_BYTES: usize = 1 << 20;

/// What every handler shares.
#[derive(Debug, Clone)]
pub struct AppState {
    pub registry: Arc<Registry>,
}

/// The whole HTTP surface: the API under `/api`, WebSockets under `/ws`, the static client
/// everywhere else.
pub fn app(registry: Arc<Registry>, web_dir: PathBuf) -> Router {
    let state = AppState { registry };
    let api = Router::new()
        .route("/health", get(handlers::health))
        .route("/openapi.json", get(openapi::document))
        .route("/maps", get(handlers::list_maps).post(handlers::add_map))
        .route("/maps/{name}", get(handlers::get_map))
        .route(
            "/matches",
            get(handlers::list_matches).post(handlers::create_match),
        )
        .route(
            "/matches/{id}",
            get(handlers::get_match).delete(handlers::delete_match),
        )
        .route("/matches/{id}/step", post(handlers::step))
        .route("/matches/{id}/belief", get(handlers::belief))
        .route("/matches/{id}/events", get(handlers::events))
        .route(
            "/matches/{id}/opponents/{oid}/command",
            post(handlers::command),
        )
        .route("/matches/{id}/players", post(handlers::join))
        .route("/matches/{id}/stats", get(handlers::stats))
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed);
    let static_files = ServeDir::new(web_dir).not_found_service(not_found.into_service());
    Router::new()
        .nest("/api", api)
        .route("/ws/matches/{id}", get(ws::upgrade))
        .fallback_service(static_files)
        // Bodies are read (and limited) by `JsonBody`; this layer is the outer guard so a huge
        // upload is cut off even on routes that do not read bodies.
        .layer(DefaultBodyLimit::max(MAX_BODY_BYTES))
        .layer(CompressionLayer::new())
        .layer(TraceLayer::new_for_http())
        .with_state(state)
}

async fn not_found(OriginalUri(uri): OriginalUri) -> ApiError {
    ApiError::not_found(format!("no such route: {}", uri.path()))
}

async fn method_not_allowed(method: axum::http::Method, OriginalUri(uri): OriginalUri) -> ApiError {
    ApiError::new(
        StatusCode::METHOD_NOT_ALLOWED,
        format!("{method} is not allowed on {}", uri.path()),
    )
}
