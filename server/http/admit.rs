//! The bounded blocking pool (see [`crate::service::Pool`]) for the handlers that run
//! blocking work of their own, such as the replay socket's seeks.

use crate::http::error::ApiError;
use crate::http::state::AppState;

/// Runs `work` on the server's blocking pool, at most as many at once as there are cores.
pub async fn off_workers<T: Send + 'static>(
    state: &AppState,
    what: &'static str,
    work: impl FnOnce() -> T + Send + 'static,
) -> Result<T, ApiError> {
    Ok(state.pool.run(what, work).await?)
}
