//! Who may change what: the owner token handed out when a match or map was made, or the
//! operator's admin token, presented as `Authorization: Bearer <token>`. Reading is open;
//! with one of those tokens it also sees a match people play live (see `game::delay`),
//! except a rated match's owner token, which reads it as late as everybody.

use axum::http::StatusCode;
use axum::http::header::AUTHORIZATION;
use axum::http::request::Parts;

use crate::access::{Owner, same_secret};
use crate::game::Sight;
use crate::http::error::ApiError;
use crate::http::state::AppState;
use crate::metrics::Refusal;

/// The bearer token of a request, if it sent one.
#[derive(Debug, Clone, Default)]
pub struct Bearer(Option<String>);

impl<S: Send + Sync> axum::extract::FromRequestParts<S> for Bearer {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, _state: &S) -> Result<Bearer, ApiError> {
        let Some(value) = parts.headers.get(AUTHORIZATION) else {
            return Ok(Bearer(None));
        };
        // A header that is there but not a bearer token is a client bug worth naming,
        // rather than a silent "no token".
        let token = value
            .to_str()
            .ok()
            .and_then(|v| {
                let (scheme, token) = v.split_once(' ')?;
                scheme.eq_ignore_ascii_case("bearer").then(|| token.trim())
            })
            .filter(|t| !t.is_empty())
            .ok_or_else(|| {
                ApiError::new(
                    StatusCode::UNAUTHORIZED,
                    "authorization: expected `Bearer <token>`",
                )
            })?;
        Ok(Bearer(Some(token.to_owned())))
    }
}

impl Bearer {
    /// The token sent, if any.
    pub fn token(&self) -> Option<&str> {
        self.0.as_deref()
    }

    /// Whether this is the operator's (admin) token: such requests are not held to the
    /// per-address rate and quotas (a local research client, the operator's own tools).
    pub fn is_admin(&self, state: &AppState) -> bool {
        let admin = state.registry.config.admin_token.as_ref();
        matches!((&self.0, admin), (Some(t), Some(a)) if same_secret(&a.0, t))
    }

    /// Lets the request change `what` (e.g. "match 3f2a…"), owned by `owner`, when it carries
    /// the owner's token or the admin token: 401 without a token, 403 with another one. The
    /// caller has found the thing first: that it exists is public (a `GET` says so), so an
    /// unknown one is a 404 for everybody, whatever the token.
    pub fn may_change(&self, state: &AppState, owner: &Owner, what: &str) -> Result<(), ApiError> {
        let metrics = &state.registry.metrics;
        let Some(token) = &self.0 else {
            metrics.refuse(Refusal::Unauthorized);
            return Err(ApiError::new(
                StatusCode::UNAUTHORIZED,
                format!(
                    "authorization: changing {what} takes its owner_token as `Authorization: Bearer <owner_token>`"
                ),
            ));
        };
        if opens(state, Some(owner), token) {
            return Ok(());
        }
        metrics.refuse(Refusal::Forbidden);
        let message = if owner.token.is_none() {
            format!("authorization: only the operator may change {what}")
        } else {
            format!("authorization: that is not the owner_token of {what}")
        };
        Err(ApiError::new(StatusCode::FORBIDDEN, message))
    }

    /// Whether this request carries `owner`'s token or the admin token (what shows a match's
    /// secret seed in the listing; a token that opens nothing there is no error).
    pub fn opens(&self, state: &AppState, owner: &Owner) -> bool {
        self.0
            .as_deref()
            .is_some_and(|token| reads_live(state, owner, token))
    }

    /// How a read of `what` (owned by `owner`) sees it: live with the owner's or the admin
    /// token, as everybody does without a token; a token that is neither is refused (403)
    /// rather than quietly shown the delayed view.
    pub fn sight(&self, state: &AppState, owner: &Owner, what: &str) -> Result<Sight, ApiError> {
        let Some(token) = &self.0 else {
            return Ok(Sight::Public);
        };
        if reads_live(state, owner, token) {
            return Ok(Sight::Live);
        }
        if owner.is(token) {
            // A rated match's owner reads what everybody reads.
            return Ok(Sight::Public);
        }
        state.registry.metrics.refuse(Refusal::Forbidden);
        Err(ApiError::new(
            StatusCode::FORBIDDEN,
            format!(
                "authorization: that token does not open the live view of {what} (its owner_token or the admin token does; without a token a match people play is shown late)"
            ),
        ))
    }
}

/// Whether `token` sees `owner`'s match live: the admin token, or the owner's token when
/// the owner reads live (not in a rated match).
fn reads_live(state: &AppState, owner: &Owner, token: &str) -> bool {
    let admin = state.registry.config.admin_token.as_ref();
    admin.is_some_and(|a| same_secret(&a.0, token)) || (owner.reads_live && owner.is(token))
}

/// Whether `token` is the admin token or `owner`'s.
fn opens(state: &AppState, owner: Option<&Owner>, token: &str) -> bool {
    let admin = state.registry.config.admin_token.as_ref();
    admin.is_some_and(|a| same_secret(&a.0, token)) || owner.is_some_and(|o| o.is(token))
}
