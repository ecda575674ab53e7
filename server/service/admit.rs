//! The per-request limits: what one request that creates state may cost (`Config`'s
//! `max_request_memory_mb`, `max_build_s`, `max_tick_ms`), checked on its price (see
//! [`crate::admission`]) before anything is built. The server's budgets are the
//! registry's (`has_room`, `has_budget`, `try_start`).

use crate::game::Registry;
use crate::game::admission::{self, Price};
use crate::metrics::Refusal;

/// A request priced past a per-request limit: names the figure, the limit and what drives
/// it. `what` is what was priced ("the map", "the match").
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OverLimit {
    #[error(
        "{what} would keep about {}, over this server's limit of {limit_mb} MB per request (the map's size and walls, tracker.particles_per_role × opponents, a fine tracker.grid_cell, and one tracker per robot behind an imperfect radio weigh most)",
        mb(.memory)
    )]
    Memory {
        what: &'static str,
        memory: u64,
        limit_mb: u64,
    },
    #[error(
        "{what} would take about {build_s:.1} s of CPU to build, over this server's limit of {limit_s} s (long walls across a big map weigh most: each costs by the area of its bounding box)"
    )]
    Build {
        what: &'static str,
        build_s: f64,
        limit_s: f64,
    },
    #[error(
        "{what}: each tick would take about {tick_ms:.1} ms of CPU, over this server's limit of {limit_ms} ms per match (the map's area, robots, particles × tracker copies, landmarks and the search planner's depth and branching weigh most)"
    )]
    Tick {
        what: &'static str,
        tick_ms: f64,
        limit_ms: f64,
    },
}

fn mb(bytes: &u64) -> String {
    admission::mb(*bytes)
}

/// Refuses what one request may not cost, counting the refusal.
pub fn within_request_limits(
    registry: &Registry,
    what: &'static str,
    price: Price,
) -> Result<(), OverLimit> {
    let cfg = &registry.config;
    let over = if price.memory > cfg.max_request_memory_mb * 1_000_000 {
        OverLimit::Memory {
            what,
            memory: price.memory,
            limit_mb: cfg.max_request_memory_mb,
        }
    } else if price.build_s > cfg.max_build_s {
        OverLimit::Build {
            what,
            build_s: price.build_s,
            limit_s: cfg.max_build_s,
        }
    } else if price.tick_ms > cfg.max_tick_ms {
        OverLimit::Tick {
            what,
            tick_ms: price.tick_ms,
            limit_ms: cfg.max_tick_ms,
        }
    } else {
        return Ok(());
    };
    registry.metrics.refuse(Refusal::Budget);
    Err(over)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::maps::MapStore;

    #[test]
    fn a_request_over_a_limit_is_refused_naming_it() {
        let registry = Registry::new(MapStore::default());
        let cheap = Price::default();
        assert_eq!(within_request_limits(&registry, "the map", cheap), Ok(()));
        let heavy = Price {
            memory: (registry.config.max_request_memory_mb + 1) * 1_000_000,
            ..Price::default()
        };
        let over = within_request_limits(&registry, "the map", heavy).unwrap_err();
        assert!(matches!(
            over,
            OverLimit::Memory {
                what: "the map",
                ..
            }
        ));
        assert!(
            over.to_string().starts_with("the map would keep about"),
            "{over}"
        );
    }
}
