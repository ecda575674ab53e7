//! Per-client limits: a token bucket of HTTP requests and a count of open WebSocket
//! connections for each client, an IPv4 address or an IPv6 /64 (`ClientKey`: one
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
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::extract::{ConnectInfo, Request};

use crate::access::ClientKey;

/// Buckets idle this long are full again and are forgotten (memory stays flat).
const FORGET_AFTER: Duration = Duration::from_secs(60);
/// How many addresses are tracked before idle ones are swept.
const SWEEP_AT: usize = 1024;

/// A token bucket: `capacity` at once, refilled at `rate` per second.
#[derive(Debug, Clone)]
pub struct Bucket {
    tokens: f64,
    capacity: f64,
    rate: f64,
    last: Instant,
}

impl Bucket {
    pub fn new(capacity: f64, rate: f64) -> Bucket {
        Bucket {
            tokens: capacity,
            capacity,
            rate,
            last: Instant::now(),
        }
    }

    /// Takes a token if there is one; otherwise says how long until there will be.
    pub fn take(&mut self) -> Result<(), Duration> {
        let now = Instant::now();
        self.tokens =
            (self.tokens + (now - self.last).as_secs_f64() * self.rate).min(self.capacity);
        self.last = now;
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            Ok(())
        } else {
            Err(Duration::from_secs_f64((1.0 - self.tokens) / self.rate))
        }
    }
}

#[derive(Debug, Default)]
struct PerAddress {
    requests: Option<Bucket>,
    connections: usize,
}

/// The per-address state of one server.
#[derive(Debug, Default)]
pub struct AddressLimits {
    map: Mutex<HashMap<ClientKey, PerAddress>>,
    sweep_at: Mutex<usize>,
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
                || a.requests
                    .as_ref()
                    .is_some_and(|b| now - b.last < FORGET_AFTER)
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
}
