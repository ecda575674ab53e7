//! The HTTP interface: [`app`] builds the axum router that the binary serves and the tests
//! call directly. Handlers parse and validate at the edge ([`body::JsonBody`]), call one use
//! case ([`crate::service`]) or match task, and map its answer; they never hold a world.

mod admit;
mod auth;
mod belief;
mod body;
mod error;
mod export;
mod fleet;
mod handlers;
pub mod limits;
mod names;
mod openapi;
pub(crate) mod parties;
mod players;
mod policies;
pub(crate) mod queue;
mod rate_limit;
mod replay_ws;
mod replays;
mod robots;
mod rules;
mod serve;
pub mod socket;
mod state;
pub mod tls;
pub mod transport;
pub mod ws;

use std::path::PathBuf;
use std::sync::Arc;

use axum::Router;
use axum::extract::{DefaultBodyLimit, OriginalUri};
use axum::handler::HandlerWithoutStateExt;
use axum::http::StatusCode;
use axum::routing::{delete, get, patch, post};
use tower_http::compression::CompressionLayer;
use tower_http::services::{ServeDir, ServeFile};
use tower_http::trace::TraceLayer;

use crate::fleet::Fleet;
use crate::game::Registry;
use crate::service::{Pool, ReplayPool};
pub use error::ApiError;
pub use serve::{
    Caps, ConnectionLimits, TooFewFiles, derive_caps, raise_open_files_limit, serve,
    trim_memory_periodically,
};
pub use state::AppState;

/// The whole HTTP surface: the API under `/api`, WebSockets under `/ws`, metrics at
/// `/metrics`, the static client everywhere else. The limits and settings are the registry's
/// `config`. Serve it with `into_make_service_with_connect_info::<SocketAddr>()`: the
/// per-address limits key on the peer's address.
pub fn app(registry: Arc<Registry>, web_dir: PathBuf) -> Router {
    router(registry, web_dir, None).0
}

/// [`app`] (or [`app_in_fleet`], with `fleet`) and the state its handlers share, for
/// [`transport::start`] to serve the same sockets over WebTransport.
pub fn app_and_state(
    registry: Arc<Registry>,
    web_dir: PathBuf,
    fleet: Option<Arc<Fleet>>,
) -> (Router, AppState) {
    router(registry, web_dir, fleet)
}

/// [`app`] for a node of a fleet: the listing shows every node's matches, a request for a
/// match another node hosts is redirected there, a new match may be placed elsewhere, and
/// the API answers cross-origin requests (see [`fleet`]).
pub fn app_in_fleet(registry: Arc<Registry>, web_dir: PathBuf, fleet: Arc<Fleet>) -> Router {
    router(registry, web_dir, Some(fleet)).0
}

fn router(
    registry: Arc<Registry>,
    web_dir: PathBuf,
    fleet: Option<Arc<Fleet>>,
) -> (Router, AppState) {
    let max_body = registry.config.max_body_bytes;
    let max_policy = registry.config.max_policy_bytes.max(max_body);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let in_fleet = fleet.is_some();
    let replays = ReplayPool::new(
        registry.config.replay_jobs,
        registry.config.client_budget_share,
    );
    // Rooms whose match ended wait again, and forgotten ones lapse, for as long as the
    // server runs (a router built outside a runtime, in a unit test, has no rooms to keep).
    let keeps = tokio::runtime::Handle::try_current().ok();
    if let Some(runtime) = &keeps {
        runtime.spawn(crate::service::parties::keep(registry.clone()));
    }
    let webtransport_seats =
        crate::http::transport::seats::Seats::new(registry.config.max_webtransport_sessions);
    let state = AppState {
        webtransport_seats,
        registry,
        limits: Arc::default(),
        pool: Pool::new(cores),
        replays,
        fleet,
        transport: Arc::default(),
    };
    // The queue's groups seated once a second, on the same pools as every match.
    if let Some(runtime) = &keeps {
        runtime.spawn(crate::service::queue::keep(
            state.registry.clone(),
            state.pool.clone(),
            state.replays.clone(),
        ));
    }
    let api = Router::new()
        .route("/health", get(handlers::health))
        .route("/openapi.json", get(openapi::document))
        .route("/rules", get(rules::rules))
        .route("/transport", get(transport::transport))
        .route("/difficulties", get(rules::difficulties))
        .route("/maps", get(handlers::list_maps).post(handlers::add_map))
        .route(
            "/policies",
            get(policies::list_policies)
                .post(policies::add_policy)
                .layer(DefaultBodyLimit::max(max_policy)),
        )
        .route("/policies/{name}", delete(policies::delete_policy))
        .route(
            "/maps/{name}",
            get(handlers::get_map).delete(handlers::delete_map),
        )
        .route(
            "/matches",
            get(handlers::list_matches).post(handlers::create_match),
        )
        .route(
            "/matches/{id}",
            get(handlers::get_match).delete(handlers::delete_match),
        )
        .route("/matches/{id}/step", post(handlers::step))
        .route("/matches/{id}/belief", get(belief::belief))
        .route("/matches/{id}/events", get(handlers::events))
        .route(
            "/matches/{id}/opponents/{oid}/command",
            post(handlers::command),
        )
        .route("/matches/{id}/robots/{rid}/command", post(robots::command))
        .route(
            "/matches/{id}/robots/{rid}/observation",
            get(robots::observation),
        )
        .route("/matches/{id}/players", post(handlers::join))
        .route("/showcase/players", post(handlers::join_showcase))
        .route("/replays", get(replays::list))
        .route("/replays/{id}", get(replays::detail))
        .route("/replays/{id}/state", get(replays::state_at))
        .route("/replays/{id}/belief", get(replays::belief_at))
        .route("/replays/{id}/export", get(export::export))
        .route("/players/{name}", get(players::player))
        .route("/names", post(names::claim))
        .route("/names/{name}", delete(names::release))
        .route("/leaderboard", get(players::leaderboard))
        .route("/parties", post(parties::create))
        .route("/parties/{code}", get(parties::get))
        .route("/parties/{code}/members", post(parties::join))
        .route(
            "/parties/{code}/members/{member_id}",
            patch(parties::change).delete(parties::remove),
        )
        .route("/parties/{code}/start", post(parties::start))
        .route("/parties/{code}/invite.svg", get(parties::invite))
        .route("/queue", post(queue::enter))
        .route("/queue/{ticket}", delete(queue::leave))
        .route("/matches/{id}/stats", get(handlers::stats))
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed);
    // Browsers ask for `/favicon.ico` by themselves (before, or without, the page's link):
    // the page's icon answers it.
    let favicon = ServeFile::new(web_dir.join("favicon.svg"));
    let static_files = ServeDir::new(web_dir).not_found_service(not_found.into_service());
    // The environment step, a research client's hot path: the same body and request
    // limits (and, in a fleet, the redirect to the node that hosts the match), but no
    // compression (a few kilobytes, on loopback as a rule) and no trace span.
    let mut act = Router::new()
        .route("/api/matches/{id}/act", post(robots::act))
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(max_body));
    if in_fleet {
        act = act.layer(axum::middleware::from_fn_with_state(
            state.clone(),
            fleet::elsewhere,
        ));
    }
    let act = act.layer(axum::middleware::from_fn_with_state(
        state.clone(),
        rate_limit::rate_limit,
    ));
    let mut router = Router::new()
        .nest("/api", api)
        .route("/ws/matches/{id}", get(ws::upgrade))
        .route("/ws/replays/{id}", get(replay_ws::upgrade))
        .route("/ws/parties/{code}", get(parties::upgrade))
        .route("/ws/queue/{ticket}", get(queue::upgrade))
        .route("/metrics", get(handlers::metrics))
        .route_service("/favicon.ico", favicon)
        .fallback_service(static_files)
        // Bodies are read (and limited) by `JsonBody`; this layer is the outer guard so a huge
        // upload is cut off even on routes that do not read bodies.
        .layer(DefaultBodyLimit::max(max_body));
    if in_fleet {
        // Before the routes, so that a match held elsewhere never reaches their 404.
        router = router.layer(axum::middleware::from_fn_with_state(
            state.clone(),
            fleet::elsewhere,
        ));
    }
    router = router
        .layer(CompressionLayer::new())
        // Outside compression and the routes: a refused request costs almost nothing.
        .layer(axum::middleware::from_fn_with_state(
            state.clone(),
            rate_limit::rate_limit,
        ));
    // Failed requests are logged by `ApiError` (its 503s, refusals the server means, only at
    // debug): the layer's own line for each would say it again, at ERROR for every 503.
    let trace = TraceLayer::new_for_http()
        .on_failure(tower_http::trace::DefaultOnFailure::new().level(tracing::Level::DEBUG));
    router = router.layer(trace).merge(act);
    if in_fleet {
        // Outside everything that answers, so that redirects and refusals carry it too (a
        // page reads neither without it).
        router = router.layer(fleet::cors());
    }
    (router.with_state(state.clone()), state)
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
