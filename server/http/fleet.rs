//! The HTTP side of the fleet (`--fleet`): a request for a match another node hosts is
//! answered 307 Temporary Redirect to that node (the same method and body, so a `POST`
//! stays a `POST`), with a JSON body naming the node; and the API may be called from any
//! origin, so that a page served by one node can play a match on another.
//!
//! Browsers cannot follow a redirect when they open a WebSocket: the page looks the
//! match's node up in the listing and opens the socket there (web/app.js).

use axum::Json;
use axum::extract::{Request, State};
use axum::http::{HeaderValue, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use tower_http::cors::{Any, CorsLayer};

use crate::http::state::AppState;
use crate::protocol::fleet::{Elsewhere, NodeRef};

/// The match id a path names: `/api/matches/{id}…` or `/ws/matches/{id}`.
fn match_id(path: &str) -> Option<&str> {
    let rest = path
        .strip_prefix("/api/matches/")
        .or_else(|| path.strip_prefix("/ws/matches/"))?;
    let id = rest.split('/').next()?;
    (!id.is_empty()).then_some(id)
}

/// Sends a request for a match this node does not hold, but another node of the fleet
/// does, to that node. Everything else goes on to the routes (a match nobody holds gets
/// their 404).
pub async fn elsewhere(State(state): State<AppState>, request: Request, next: Next) -> Response {
    if let Some(fleet) = &state.fleet
        && let Some(id) = match_id(request.uri().path())
        && state.registry.get(id).is_none()
        && let Some(node) = fleet.host_of(id)
    {
        let path = request
            .uri()
            .path_and_query()
            .map_or(request.uri().path(), |p| p.as_str());
        let message = format!("match {id} is hosted on node {}", node.id);
        if let Some(response) = redirect(node, path, message) {
            return response;
        }
    }
    next.run(request).await
}

/// 307 to `path` (with its query) on `node`; `None` when the node's URL does not make a
/// header (it comes from the directory: then the request is answered here, as outside a
/// fleet).
pub fn redirect(node: NodeRef, path: &str, message: String) -> Option<Response> {
    let location = format!("{}{path}", node.url);
    let header = HeaderValue::from_str(&location).ok()?;
    let body = Elsewhere {
        message,
        node,
        location,
    };
    let mut response = (StatusCode::TEMPORARY_REDIRECT, Json(body)).into_response();
    response.headers_mut().insert(header::LOCATION, header);
    Some(response)
}

/// The API may be called from any origin. It holds no cookie or other ambient credential
/// (owner tokens travel in `Authorization` headers the caller sets), so a cross-origin
/// page can do nothing through it that it could not do by calling it directly; and the
/// page of one node must reach the others (joining a match there, following a 307).
pub fn cors() -> CorsLayer {
    CorsLayer::new()
        .allow_origin(Any)
        .allow_methods([Method::GET, Method::POST, Method::DELETE])
        .allow_headers([header::CONTENT_TYPE, header::AUTHORIZATION])
        .expose_headers([header::LOCATION, header::RETRY_AFTER])
        .max_age(std::time::Duration::from_secs(600))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_match_a_path_names() {
        assert_eq!(match_id("/api/matches/ab12"), Some("ab12"));
        assert_eq!(match_id("/api/matches/ab12/players"), Some("ab12"));
        assert_eq!(match_id("/ws/matches/ab12"), Some("ab12"));
        assert_eq!(match_id("/api/matches"), None);
        assert_eq!(match_id("/api/matches/"), None);
        assert_eq!(match_id("/api/replays/ab12"), None);
    }
}
