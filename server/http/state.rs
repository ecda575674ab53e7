//! [`AppState`]: what every handler shares.

use std::sync::Arc;

use crate::fleet::Fleet;
use crate::game::Registry;
use crate::http::limits;
use crate::service::{Pool, ReplayPool, Service};

/// What every handler shares.
#[derive(Debug, Clone)]
pub struct AppState {
    pub registry: Arc<Registry>,
    pub limits: Arc<limits::AddressLimits>,
    /// The blocking pool that validates and builds maps and worlds: one job per core.
    pub pool: Pool,
    /// The replays' own pool (`Config::replay_jobs`).
    pub replays: ReplayPool,
    /// This node's part in a fleet (`--fleet`), if it is in one.
    pub fleet: Option<Arc<Fleet>>,
    /// Where WebTransport is served, once [`crate::http::transport::start`] runs.
    pub transport: Arc<crate::http::transport::published::Published>,
    /// The WebTransport sessions the server carries, players first.
    pub webtransport_seats: Arc<crate::http::transport::seats::Seats>,
}

impl AppState {
    /// What the use cases work with.
    pub fn service(&self) -> Service<'_> {
        Service {
            registry: &self.registry,
            pool: &self.pool,
            replays: &self.replays,
            fleet: self.fleet.as_deref(),
        }
    }
}
