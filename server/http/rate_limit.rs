//! The per-address request rate, as a middleware over every route.

use axum::extract::{Request, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use crate::access::ClientKey;
use crate::http::error::ApiError;
use crate::http::limits::client_ip;
use crate::http::state::AppState;
use crate::metrics::Refusal;

/// Middleware: refuses a request over its address's rate with 429 and `Retry-After`. The
/// operator's token is not rate limited (a local research client steps thousands of times a
/// second).
pub async fn rate_limit(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let ip = client_ip(&req);
    let cfg = &state.registry.config;
    if let Some(admin) = &cfg.admin_token {
        let presented = req
            .headers()
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.split_once(' '))
            .filter(|(scheme, _)| scheme.eq_ignore_ascii_case("bearer"))
            .map(|(_, t)| t.trim());
        if presented.is_some_and(|t| crate::access::same_secret(&admin.0, t)) {
            return next.run(req).await;
        }
    }
    match state
        .limits
        .check_request(ip, cfg.request_burst, cfg.requests_per_s)
    {
        Ok(()) => next.run(req).await,
        Err(wait) => {
            state.registry.metrics.refuse(Refusal::RateLimited);
            let secs = wait.as_secs_f64().ceil().max(1.0) as u64;
            let mut resp = ApiError::new(
                StatusCode::TOO_MANY_REQUESTS,
                format!(
                    "too many requests from {}: at most {} per second (bursts of {}); retry in {secs} s",
                    ClientKey::of(ip),
                    cfg.requests_per_s, cfg.request_burst
                ),
            )
            .into_response();
            if let Ok(v) = HeaderValue::from_str(&secs.to_string()) {
                resp.headers_mut().insert(header::RETRY_AFTER, v);
            }
            resp
        }
    }
}
