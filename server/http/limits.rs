//! Per-client limits: a token bucket of HTTP requests, a count of open WebSocket
//! connections and of running replay exports for each client, an IPv4 address or an IPv6 /64 (`ClientKey`: one
//! subscriber usually holds a whole /64, which would otherwise be 2^64 fresh budgets).
//!
//! Hand-written rather than `tower_governor`: we need the refusal in the API's own JSON error
//! shape with a `Retry-After`, a count of concurrent WebSockets (which a rate limiter does not
//! do) and a metric per refusal; the whole thing is one small map under a mutex.
//!
//! The address is the TCP peer's (`ConnectInfo<SocketAddr>`, so the server must be served
//! with `into_make_service_with_connect_info`). Behind a reverse proxy every client shares
//! the proxy's address: raise the limits there or let the proxy limit.

use std::collections::HashMap;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::extract::{ConnectInfo, Request};

pub use crate::access::Bucket;
use crate::access::ClientKey;

/// Buckets idle this long are full again and are forgotten (memory stays flat).
const FORGET_AFTER: Duration = Duration::from_secs(60);
/// How many addresses are tracked before idle ones are swept.
const SWEEP_AT: usize = 1024;

#[derive(Debug, Default)]
struct PerAddress {
    requests: Option<Bucket>,
    connections: usize,
    exports: usize,
    /// Bytes of the replay sockets' cursors this client holds.
    cursor_bytes: u64,
    /// Bytes of beliefs it may read (`http::belief`).
    belief_bytes: Option<Bucket>,
}

/// The per-address state of one server.
#[derive(Debug, Default)]
pub struct AddressLimits {
    map: Mutex<HashMap<ClientKey, PerAddress>>,
    sweep_at: Mutex<usize>,
    /// The exports running, all clients together, as their writers report them (changed
    /// under `map`'s lock): how many there are, and which one could give way.
    running: Mutex<Vec<Arc<ExportWatch>>>,
    /// Bytes of every replay socket's cursor (changed under `map`'s lock).
    cursor_bytes: std::sync::atomic::AtomicU64,
    /// Bytes of beliefs every client together may read (taken under `map`'s lock).
    belief_bytes: Mutex<Option<Bucket>>,
}

/// Why a belief was not read: the client's share of belief bytes (429) or everyone's (503)
/// is spent for now; read again after the wait.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BeliefBytesSpent {
    Client(Duration),
    Server(Duration),
}

/// Why a belief was not read: the client's share of belief bytes a second (429) or
/// everyone's (503) is spent for now, or the belief moved on to a newer tick while it was
/// read (503: read again).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BeliefRefused {
    #[error(
        "belief: {client} reads at most {mb_per_s} MB of beliefs a second; thin them with ?particles=N, or retry in {retry_s} s"
    )]
    Client {
        client: crate::access::ClientKey,
        mb_per_s: f64,
        retry_s: u32,
    },
    #[error(
        "belief: this server serves at most {mb_per_s} MB of beliefs a second to everyone; thin them with ?particles=N, or retry in {retry_s} s"
    )]
    Server { mb_per_s: f64, retry_s: u32 },
    #[error("the belief moved on while it was read; read again")]
    MovedOn,
}

/// Bytes the cursors of open replay sockets may take, all clients together: each holds a
/// copy of its match's world while it plays.
pub const CURSOR_BYTES: u64 = 256 << 20;

/// Why a replay socket was not let in: its cursor would take the client past its share of
/// [`CURSOR_BYTES`] (429), or the server past all of it (503).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CursorsFull {
    Client,
    Server,
}

/// How long an export's client may read nothing before its slot goes to a newcomer who
/// finds every slot taken.
pub const GIVE_WAY_AFTER: Duration = Duration::from_secs(1);

/// Why an export was not let in: the client's share (429) or the server's (503) is taken;
/// or every slot is taken but one's client has stopped reading, and it was asked to give
/// way (try again shortly).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExportsFull {
    Client,
    Server,
    GivingWay,
}

/// A running export as its writer reports it: since when its client has read nothing, and
/// whether a newcomer asked for its slot.
#[derive(Debug, Default)]
pub struct ExportWatch {
    stalled_since: Mutex<Option<Instant>>,
    give_way: std::sync::atomic::AtomicBool,
}

impl ExportWatch {
    /// The client took nothing this time: stalled from now, unless already.
    pub fn stalled(&self) {
        self.stalled_since
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get_or_insert_with(Instant::now);
    }

    /// The client read again.
    pub fn reading(&self) {
        *self.stalled_since.lock().unwrap_or_else(|e| e.into_inner()) = None;
    }

    /// A newcomer asked for this export's slot.
    pub fn asked_to_give_way(&self) -> bool {
        self.give_way.load(Ordering::Acquire)
    }

    fn stalled_for(&self, now: Instant) -> Duration {
        self.stalled_since
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .map_or(Duration::ZERO, |t| now - t)
    }
}

impl AddressLimits {
    pub(super) fn check_request(
        &self,
        ip: IpAddr,
        capacity: f64,
        rate: f64,
    ) -> Result<(), Duration> {
        let mut map = self.map.lock().unwrap_or_else(|e| e.into_inner());
        self.sweep(&mut map);
        map.entry(ClientKey::of(ip))
            .or_default()
            .requests
            .get_or_insert_with(|| Bucket::new(capacity, rate))
            .take()
    }

    /// Charges `bytes` of belief to `ip` and to everyone, at `per_client` and `all` bytes a
    /// second (bursts of two seconds' worth), or says how long to wait. One read bigger
    /// than a burst goes through when its bucket is full, which then owes the rest.
    pub fn take_belief_bytes(
        &self,
        ip: IpAddr,
        bytes: u64,
        per_client: f64,
        all: f64,
    ) -> Result<(), BeliefBytesSpent> {
        let now = Instant::now();
        let mut map = self.map.lock().unwrap_or_else(|e| e.into_inner());
        self.sweep(&mut map);
        let mut everyone = self.belief_bytes.lock().unwrap_or_else(|e| e.into_inner());
        let everyone = everyone.get_or_insert_with(|| Bucket::new(2.0 * all, all));
        let client = map
            .entry(ClientKey::of(ip))
            .or_default()
            .belief_bytes
            .get_or_insert_with(|| Bucket::new(2.0 * per_client, per_client));
        client.refill(now);
        everyone.refill(now);
        let bytes = bytes as f64;
        let wait = client.wait_s(bytes.min(2.0 * per_client));
        if wait > 0.0 {
            return Err(BeliefBytesSpent::Client(Duration::from_secs_f64(wait)));
        }
        let wait = everyone.wait_s(bytes.min(2.0 * all));
        if wait > 0.0 {
            return Err(BeliefBytesSpent::Server(Duration::from_secs_f64(wait)));
        }
        client.spend(bytes);
        everyone.spend(bytes);
        Ok(())
    }

    /// Counts a WebSocket connection from `ip` unless it has `max` open already.
    pub fn open_connection(self: &Arc<Self>, ip: IpAddr, max: usize) -> Option<AddressConnection> {
        let mut map = self.map.lock().unwrap_or_else(|e| e.into_inner());
        let client = ClientKey::of(ip);
        let entry = map.entry(client).or_default();
        if entry.connections >= max {
            return None;
        }
        entry.connections += 1;
        Some(AddressConnection {
            limits: self.clone(),
            client,
        })
    }

    /// Counts a running export of `ip` unless the server runs `max` already or the client
    /// `per_client`.
    pub fn open_export(
        self: &Arc<Self>,
        ip: IpAddr,
        max: usize,
        per_client: usize,
    ) -> Result<AddressExport, ExportsFull> {
        let mut map = self.map.lock().unwrap_or_else(|e| e.into_inner());
        let client = ClientKey::of(ip);
        let entry = map.entry(client).or_default();
        if entry.exports >= per_client {
            return Err(ExportsFull::Client);
        }
        let mut running = self.running.lock().unwrap_or_else(|e| e.into_inner());
        if running.len() >= max {
            // A slot held by a client that stopped reading goes to the newcomer: the one
            // stalled longest ends (its last line says where to resume) and frees it.
            let now = Instant::now();
            let idle = running
                .iter()
                .filter(|w| w.stalled_for(now) >= GIVE_WAY_AFTER)
                .max_by_key(|w| w.stalled_for(now));
            return match idle {
                Some(w) => {
                    w.give_way.store(true, Ordering::Release);
                    Err(ExportsFull::GivingWay)
                }
                None => Err(ExportsFull::Server),
            };
        }
        entry.exports += 1;
        let watch = Arc::new(ExportWatch::default());
        running.push(watch.clone());
        Ok(AddressExport {
            limits: self.clone(),
            client,
            watch,
        })
    }

    /// Counts a replay socket's cursor of `bytes` for `ip` unless the client would hold more
    /// than `per_client` bytes of cursors or the server more than `max`.
    pub fn open_cursor(
        self: &Arc<Self>,
        ip: IpAddr,
        bytes: u64,
        max: u64,
        per_client: u64,
    ) -> Result<CursorHold, CursorsFull> {
        let mut map = self.map.lock().unwrap_or_else(|e| e.into_inner());
        let client = ClientKey::of(ip);
        let entry = map.entry(client).or_default();
        if entry.cursor_bytes + bytes > per_client {
            return Err(CursorsFull::Client);
        }
        if self.cursor_bytes.load(Ordering::Acquire) + bytes > max {
            return Err(CursorsFull::Server);
        }
        entry.cursor_bytes += bytes;
        self.cursor_bytes.fetch_add(bytes, Ordering::AcqRel);
        Ok(CursorHold {
            limits: self.clone(),
            client,
            bytes,
        })
    }

    /// Forgets addresses with no connection whose bucket has been idle long enough to be
    /// full; runs when the map has doubled since the last sweep.
    fn sweep(&self, map: &mut HashMap<ClientKey, PerAddress>) {
        let mut at = self.sweep_at.lock().unwrap_or_else(|e| e.into_inner());
        if map.len() < (*at).max(SWEEP_AT) {
            return;
        }
        let now = Instant::now();
        map.retain(|_, a| {
            a.connections > 0
                || a.exports > 0
                || a.cursor_bytes > 0
                || a.belief_bytes
                    .as_ref()
                    .is_some_and(|b| b.idle(now) < FORGET_AFTER * 10)
                || a.requests
                    .as_ref()
                    .is_some_and(|b| b.idle(now) < FORGET_AFTER)
        });
        *at = map.len() * 2;
    }

    /// Addresses tracked now (for tests of the sweep).
    pub fn tracked(&self) -> usize {
        self.map.lock().unwrap_or_else(|e| e.into_inner()).len()
    }
}

/// One open WebSocket connection of an address; uncounted when dropped.
#[derive(Debug)]
pub struct AddressConnection {
    limits: Arc<AddressLimits>,
    client: ClientKey,
}

impl Drop for AddressConnection {
    fn drop(&mut self) {
        let mut map = self.limits.map.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(a) = map.get_mut(&self.client) {
            a.connections = a.connections.saturating_sub(1);
        }
    }
}

/// One running export of an address; uncounted when dropped.
#[derive(Debug)]
pub struct AddressExport {
    limits: Arc<AddressLimits>,
    client: ClientKey,
    watch: Arc<ExportWatch>,
}

impl AddressExport {
    /// What the export's writer reports of its client.
    pub fn watch(&self) -> &ExportWatch {
        &self.watch
    }
}

impl Drop for AddressExport {
    fn drop(&mut self) {
        let mut map = self.limits.map.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(a) = map.get_mut(&self.client) {
            a.exports = a.exports.saturating_sub(1);
        }
        self.limits
            .running
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .retain(|w| !Arc::ptr_eq(w, &self.watch));
    }
}

/// One replay socket's cursor, counted for its client; uncounted when dropped.
#[derive(Debug)]
pub struct CursorHold {
    limits: Arc<AddressLimits>,
    client: ClientKey,
    bytes: u64,
}

impl Drop for CursorHold {
    fn drop(&mut self) {
        let mut map = self.limits.map.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(a) = map.get_mut(&self.client) {
            a.cursor_bytes = a.cursor_bytes.saturating_sub(self.bytes);
        }
        self.limits
            .cursor_bytes
            .fetch_sub(self.bytes, Ordering::AcqRel);
    }
}

/// The client's IP address; without `ConnectInfo` (a server not served with it) every
/// client shares one address, so the limits still hold for the server as a whole.
pub fn client_ip(req: &Request) -> IpAddr {
    req.extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map_or(IpAddr::V4(Ipv4Addr::UNSPECIFIED), |c| c.0.ip())
}

/// Extractor of the client's IP address (see [`client_ip`]).
#[derive(Debug, Clone, Copy)]
pub struct ClientIp(pub IpAddr);

impl<S: Send + Sync> axum::extract::FromRequestParts<S> for ClientIp {
    type Rejection = std::convert::Infallible;

    async fn from_request_parts(
        parts: &mut axum::http::request::Parts,
        _state: &S,
    ) -> Result<Self, Self::Rejection> {
        Ok(ClientIp(
            parts
                .extensions
                .get::<ConnectInfo<SocketAddr>>()
                .map_or(IpAddr::V4(Ipv4Addr::UNSPECIFIED), |c| c.0.ip()),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_addresses_of_one_ipv6_64_share_a_budget() {
        let limits = AddressLimits::default();
        let ip = |s: &str| s.parse::<IpAddr>().unwrap();
        // A bucket of two that refills once in a thousand seconds.
        assert!(limits.check_request(ip("2001:db8::1"), 2.0, 0.001).is_ok());
        assert!(
            limits
                .check_request(ip("2001:db8::ffff:2"), 2.0, 0.001)
                .is_ok()
        );
        assert!(limits.check_request(ip("2001:db8::3"), 2.0, 0.001).is_err());
        // The next /64 has its own.
        assert!(
            limits
                .check_request(ip("2001:db8:0:1::1"), 2.0, 0.001)
                .is_ok()
        );
        // IPv4 addresses are one client each.
        assert!(limits.check_request(ip("192.0.2.1"), 2.0, 0.001).is_ok());
        assert!(limits.check_request(ip("192.0.2.2"), 2.0, 0.001).is_ok());
    }

    #[test]
    fn a_client_runs_its_share_of_exports_and_the_server_its_own() {
        let limits = Arc::new(AddressLimits::default());
        let ip = |s: &str| s.parse::<IpAddr>().unwrap();
        let a = limits.open_export(ip("192.0.2.1"), 2, 1).unwrap();
        assert_eq!(
            limits.open_export(ip("192.0.2.1"), 2, 1).err(),
            Some(ExportsFull::Client)
        );
        let _b = limits.open_export(ip("192.0.2.2"), 2, 1).unwrap();
        assert_eq!(
            limits.open_export(ip("192.0.2.3"), 2, 1).err(),
            Some(ExportsFull::Server)
        );
        drop(a);
        assert!(limits.open_export(ip("192.0.2.3"), 2, 1).is_ok());
    }

    #[test]
    fn replay_cursors_fit_in_the_clients_share_and_the_servers_bytes() {
        let limits = Arc::new(AddressLimits::default());
        let ip = |s: &str| s.parse::<IpAddr>().unwrap();
        let a = limits.open_cursor(ip("192.0.2.1"), 60, 100, 80).unwrap();
        assert_eq!(
            limits.open_cursor(ip("192.0.2.1"), 30, 100, 80).err(),
            Some(CursorsFull::Client)
        );
        let _b = limits.open_cursor(ip("192.0.2.2"), 30, 100, 80).unwrap();
        assert_eq!(
            limits.open_cursor(ip("192.0.2.3"), 30, 100, 80).err(),
            Some(CursorsFull::Server)
        );
        drop(a);
        assert!(limits.open_cursor(ip("192.0.2.3"), 30, 100, 80).is_ok());
    }

    #[test]
    fn a_stalled_export_gives_its_slot_to_a_newcomer() {
        let limits = Arc::new(AddressLimits::default());
        let ip = |s: &str| s.parse::<IpAddr>().unwrap();
        let a = limits.open_export(ip("192.0.2.1"), 1, 1).unwrap();
        // Reading: the newcomer waits its turn.
        assert_eq!(
            limits.open_export(ip("192.0.2.2"), 1, 1).err(),
            Some(ExportsFull::Server)
        );
        assert!(!a.watch().asked_to_give_way());
        // Stalled long enough: it is asked to give way, and its slot is free once it ends.
        *a.watch().stalled_since.lock().unwrap() = Some(Instant::now() - GIVE_WAY_AFTER);
        assert_eq!(
            limits.open_export(ip("192.0.2.2"), 1, 1).err(),
            Some(ExportsFull::GivingWay)
        );
        assert!(a.watch().asked_to_give_way());
        drop(a);
        assert!(limits.open_export(ip("192.0.2.2"), 1, 1).is_ok());
    }
}
