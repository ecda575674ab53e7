//! The use cases: what a request asks of the server, in domain terms. Each takes parsed
//! values and a [`Service`] (the registry, the blocking pool, the fleet), does the work —
//! checks, admission, building on the pool, starting — and answers with a value or a
//! typed error that says what went wrong; `http` parses requests, calls one use case and
//! maps its answer (errors to statuses in `http/error.rs`).

pub mod admit;
pub mod maps;
pub mod matches;
pub mod names;
pub mod parties;
pub mod players;
pub mod policies;
pub mod queue;
pub mod replays;

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use tokio::sync::Semaphore;

use crate::access::ClientKey;
use crate::fleet::Fleet;
use crate::game::Registry;

/// What every use case works with.
#[derive(Debug, Clone, Copy)]
pub struct Service<'a> {
    pub registry: &'a Registry,
    pub pool: &'a Pool,
    /// The replays' own pool.
    pub replays: &'a ReplayPool,
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
        let permit = self.0.acquire().await;
        let _permit = permit.map_err(|e| PoolError::of(what, &e))?;
        Self::spawn(what, work).await
    }

    /// Like [`Pool::run`] when a permit is free within `wait`; `None` (and `work` dropped
    /// unrun) when none was.
    pub async fn run_within<T: Send + 'static>(
        &self,
        wait: Duration,
        what: &'static str,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Result<Option<T>, PoolError> {
        let Ok(permit) = tokio::time::timeout(wait, self.0.acquire()).await else {
            return Ok(None);
        };
        let _permit = permit.map_err(|e| PoolError::of(what, &e))?;
        Self::spawn(what, work).await.map(Some)
    }

    async fn spawn<T: Send + 'static>(
        what: &'static str,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, PoolError> {
        // A thread of its own at the background priority, not tokio's blocking pool: the
        // pool's threads also serve files and the history, which should not run low.
        let (tx, rx) = tokio::sync::oneshot::channel();
        crate::game::background::spawn(what, move || {
            let _ = tx.send(work());
        })
        .map_err(|e| PoolError::of(what, &e))?;
        rx.await
            .map_err(|_| PoolError::of(what, &"the job panicked"))
    }
}

impl PoolError {
    fn of(what: &'static str, e: &dyn std::fmt::Display) -> PoolError {
        PoolError {
            what,
            reason: e.to_string(),
        }
    }
}

/// How long a replay's job waits for a slot before it is refused.
const REPLAY_WAIT: Duration = Duration::from_secs(2);

/// The replays' own bounded pool (`Config::replay_jobs` slots): re-simulating a finished
/// match never waits for, nor holds, the permits that build matches. A job waits for a slot
/// a short while, then is refused (the server's slots busy); a client may have at most
/// twice its share of the slots in flight, running or waiting.
#[derive(Debug, Clone)]
pub struct ReplayPool {
    slots: Pool,
    jobs: usize,
    per_client: usize,
    in_flight: Arc<Mutex<HashMap<ClientKey, usize>>>,
}

/// A replay's job that was not run.
#[derive(Debug, Clone, thiserror::Error)]
pub enum ReplayBusy {
    #[error(
        "this server's {jobs} replay slots are busy re-simulating matches; try again in a few seconds"
    )]
    Server { jobs: usize },
    #[error(
        "{client} has {held} replay requests in flight, the most one client may; wait for one to answer"
    )]
    Client { client: ClientKey, held: usize },
    #[error(transparent)]
    Failed(#[from] PoolError),
}

/// One job of a client in flight; uncounted when dropped.
struct InFlight {
    map: Arc<Mutex<HashMap<ClientKey, usize>>>,
    client: ClientKey,
}

impl Drop for InFlight {
    fn drop(&mut self) {
        let mut map = self.map.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(n) = map.get_mut(&self.client) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                map.remove(&self.client);
            }
        }
    }
}

impl ReplayPool {
    /// `jobs` slots, a client holding at most `share` of them (at least one) running.
    pub fn new(jobs: usize, share: f64) -> ReplayPool {
        let jobs = jobs.max(1);
        ReplayPool {
            slots: Pool::new(jobs),
            jobs,
            per_client: 2 * ((jobs as f64 * share).floor() as usize).max(1),
            in_flight: Arc::default(),
        }
    }

    /// Runs `work` (`what`, for the error) on a blocking thread once a slot is free, for
    /// `client` (none: not counted against a client, e.g. a socket's own seeks).
    pub async fn run<T: Send + 'static>(
        &self,
        client: Option<ClientKey>,
        what: &'static str,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, ReplayBusy> {
        let _counted = match client {
            Some(client) => {
                let mut map = self.in_flight.lock().unwrap_or_else(|e| e.into_inner());
                let held = map.entry(client).or_insert(0);
                if *held >= self.per_client {
                    return Err(ReplayBusy::Client {
                        client,
                        held: *held,
                    });
                }
                *held += 1;
                Some(InFlight {
                    map: self.in_flight.clone(),
                    client,
                })
            }
            None => None,
        };
        self.slots
            .run_within(REPLAY_WAIT, what, work)
            .await?
            .ok_or(ReplayBusy::Server { jobs: self.jobs })
    }

    /// Like [`ReplayPool::run`] without a time limit on the wait: a replay socket's seeks
    /// queue for a slot (a slow pool plays slower).
    pub async fn queue<T: Send + 'static>(
        &self,
        what: &'static str,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, PoolError> {
        self.slots.run(what, work).await
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::IpAddr;

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_full_replay_pool_refuses_and_a_client_holds_at_most_its_share() {
        let pool = ReplayPool::new(1, 0.5);
        let client = Some(ClientKey::of("192.0.2.1".parse::<IpAddr>().unwrap()));
        let (release, held) = std::sync::mpsc::channel::<()>();
        let busy = pool.clone();
        let running = tokio::spawn(async move {
            busy.run(client, "holding the slot", move || held.recv().is_ok())
                .await
        });
        tokio::time::sleep(Duration::from_millis(100)).await;
        let other = Some(ClientKey::of("192.0.2.2".parse::<IpAddr>().unwrap()));
        let waited = pool.run(other, "waiting", || ()).await;
        assert!(
            matches!(waited, Err(ReplayBusy::Server { jobs: 1 })),
            "{waited:?}"
        );
        // The first client has one running; a second waits; a third is one too many.
        let second = {
            let pool = pool.clone();
            tokio::spawn(async move { pool.run(client, "second", || ()).await })
        };
        tokio::time::sleep(Duration::from_millis(100)).await;
        let third = pool.run(client, "third", || ()).await;
        assert!(
            matches!(third, Err(ReplayBusy::Client { held: 2, .. })),
            "{third:?}"
        );
        release.send(()).unwrap();
        assert!(matches!(running.await, Ok(Ok(true))));
        assert!(matches!(second.await, Ok(Ok(()))));
        // Nothing in flight is left counted.
        assert!(pool.in_flight.lock().unwrap().is_empty());
    }
}
