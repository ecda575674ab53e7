//! The path search robots' orders take on a match's thread, priced from the order before it
//! runs. Each waypoint is a search over the map's navigation grid (`nav::path_within`), so an
//! order's work is at most its waypoints × twice the grid's cells and its set-up (twice: the
//! search, then string pulling the path it found). A request's work is bounded
//! (`Config::max_command_work`: the match gives up past it and refuses the order), and what
//! requests may take together is two token buckets of work units: the server's, refilled at
//! `command_work_per_s`, and each client's, refilled at its share (`client_budget_share`) of
//! that. A request is charged its price before it runs.

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::Instant;

use crate::access::{Bucket, ClientKey};
use crate::config::Config;
use crate::game::error::MatchError;
use lasertag_core::nav::search_setup_work;
use lasertag_core::world::{RobotOrder, WorldInput};

/// Clients tracked before full buckets are forgotten (memory stays flat).
const SWEEP_AT: usize = 1024;

/// The most path-search work `inputs` can take on a grid of `cells` cells.
pub fn route_work(inputs: &[WorldInput], cells: usize) -> u64 {
    let per_point = 2 * (cells as u64 + search_setup_work(cells));
    inputs
        .iter()
        .map(|input| match input {
            WorldInput::Robot {
                order: RobotOrder::Waypoints(points),
                ..
            } => points.len() as u64 * per_point,
            _ => 0,
        })
        .sum()
}

/// The most path search one request may take (`Config::max_command_work`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RequestBound(pub u64);

impl RequestBound {
    /// What a request with `inputs` on a grid of `cells` may take: its price, within the
    /// bound. The handler charges it; the match lets the request's orders search that much.
    pub fn work(self, inputs: &[WorldInput], cells: usize) -> u64 {
        route_work(inputs, cells).min(self.0)
    }
}

#[derive(Debug, Default)]
struct Buckets {
    server: Option<Bucket>,
    clients: HashMap<ClientKey, Bucket>,
}

/// The server's and each client's buckets of path-search work.
#[derive(Debug, Default)]
pub struct WorkBudget {
    buckets: Mutex<Buckets>,
}

impl WorkBudget {
    /// Takes `units` from the server's bucket and `client`'s (none for the operator), or
    /// neither: a client past its share is told so (429), a server out of work 503.
    pub fn take(
        &self,
        config: &Config,
        client: Option<ClientKey>,
        units: u64,
    ) -> Result<(), MatchError> {
        if units == 0 {
            return Ok(());
        }
        let units = units as f64;
        // A bucket holds at least one request's most, or that request could never run.
        let most = config.max_command_work as f64;
        let server_rate = config.command_work_per_s;
        let client_rate = server_rate * config.client_budget_share;
        let now = Instant::now();
        let mut guard = self.buckets.lock().unwrap_or_else(|e| e.into_inner());
        let b = &mut *guard;
        if b.clients.len() >= SWEEP_AT {
            b.clients.retain(|_, c| {
                c.refill(now);
                !c.is_full()
            });
        }
        let server = b
            .server
            .get_or_insert_with(|| Bucket::new(server_rate.max(most), server_rate));
        server.refill(now);
        let server_wait = server.wait_s(units);
        let client = match client {
            Some(key) => {
                let c = b
                    .clients
                    .entry(key)
                    .or_insert_with(|| Bucket::new(client_rate.max(most), client_rate));
                c.refill(now);
                let wait = c.wait_s(units);
                if wait > 0.0 {
                    return Err(MatchError::WorkShare {
                        client: key,
                        rate: client_rate as u64,
                        wait_s: wait,
                    });
                }
                Some(key)
            }
            None => None,
        };
        if server_wait > 0.0 {
            return Err(MatchError::WorkBusy {
                rate: server_rate as u64,
                wait_s: server_wait,
            });
        }
        if let Some(s) = b.server.as_mut() {
            s.spend(units);
        }
        if let Some(c) = client.and_then(|key| b.clients.get_mut(&key)) {
            c.spend(units);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point2;
    use std::net::IpAddr;

    fn waypoints(n: usize) -> WorldInput {
        WorldInput::Robot {
            robot: 0,
            order: RobotOrder::Waypoints(vec![Point2::new(1.0, 1.0); n]),
        }
    }

    #[test]
    fn an_order_is_priced_by_its_waypoints_and_the_grid() {
        let stop = WorldInput::Robot {
            robot: 0,
            order: RobotOrder::Stop,
        };
        assert_eq!(route_work(&[stop], 400_000), 0);
        let one = route_work(&[waypoints(1)], 400_000);
        assert_eq!(route_work(&[waypoints(16)], 400_000), 16 * one);
        assert!(one > 800_000, "{one}");
    }

    #[test]
    fn a_client_past_its_share_waits_and_the_others_go_on() {
        let config = Config {
            max_command_work: 1_000,
            command_work_per_s: 4_000.0,
            client_budget_share: 0.25,
            ..Config::default()
        };
        let budget = WorkBudget::default();
        let key = |s: &str| Some(ClientKey::of(s.parse::<IpAddr>().unwrap()));
        assert_eq!(budget.take(&config, key("192.0.2.1"), 1_000), Ok(()));
        assert!(matches!(
            budget.take(&config, key("192.0.2.1"), 1_000),
            Err(MatchError::WorkShare { .. })
        ));
        // Three more clients take the rest of the server's bucket; the next one waits.
        for ip in ["192.0.2.2", "192.0.2.3", "192.0.2.4"] {
            assert_eq!(budget.take(&config, key(ip), 1_000), Ok(()));
        }
        assert!(matches!(
            budget.take(&config, key("192.0.2.5"), 1_000),
            Err(MatchError::WorkBusy { .. })
        ));
    }
}
