//! The use cases: what a request asks of the server, in domain terms. Each takes parsed
//! values and a [`Service`] (the registry, the blocking pool, the fleet), does the work —
//! checks, admission, building on the pool, starting — and answers with a value or a
//! typed error that says what went wrong; `http` parses requests, calls one use case and
//! maps its answer (errors to statuses in `http/error.rs`).

pub mod admit;
pub mod maps;
pub mod matches;
pub mod players;
pub mod replays;

use std::sync::Arc;

use tokio::sync::Semaphore;

use crate::fleet::Fleet;
use crate::game::Registry;

/// What every use case works with.
#[derive(Debug, Clone, Copy)]
pub struct Service<'a> {
    pub registry: &'a Registry,
    pub pool: &'a Pool,
    /// This node's part in a fleet (`--fleet`), if it is in one.
    pub fleet: Option<&'a Fleet>,
}

/// The bounded blocking pool: validating and building maps and worlds, replaying and
/// reading the history take up to seconds (priced and bounded before they start) and must
/// neither hold up the async workers nor pile up threads, so at most one job per permit
/// runs at once.
#[derive(Debug, Clone)]
pub struct Pool(Arc<Semaphore>);

/// A job of the pool that did not finish (it panicked, or the pool is closed): the
/// server's fault, not the request's.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{what} failed: {reason}")]
pub struct PoolError {
    pub what: &'static str,
    pub reason: String,
}

impl Pool {
    /// A pool running at most `permits` jobs at once (one per core, as a rule).
    pub fn new(permits: usize) -> Pool {
        Pool(Arc::new(Semaphore::new(permits)))
    }

    /// Runs `work` (`what`, for the error) on the blocking pool once a permit is free.
    pub async fn run<T: Send + 'static>(
        &self,
        what: &'static str,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, PoolError> {
        let failed = |e: &dyn std::fmt::Display| PoolError {
            what,
            reason: e.to_string(),
        };
        let _permit = self.0.acquire().await.map_err(|e| failed(&e))?;
        tokio::task::spawn_blocking(work)
            .await
            .map_err(|e| failed(&e))
    }
}
