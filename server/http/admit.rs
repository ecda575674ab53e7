//! The replays' bounded pool (see [`crate::service::ReplayPool`]) for the handlers that run
//! blocking work of their own, such as the replay socket's seeks.

use crate::http::error::ApiError;
use crate::http::state::AppState;

/// Runs `work` on the replays' pool once a slot is free (a socket's seeks queue: a slow
/// pool plays slower); never on the permits that build matches.
pub async fn off_workers<T: Send + 'static>(
    state: &AppState,
    what: &'static str,
    work: impl FnOnce() -> T + Send + 'static,
) -> Result<T, ApiError> {
    Ok(state.replays.queue(what, work).await?)
}
