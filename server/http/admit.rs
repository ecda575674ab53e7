//! Admission at the edge: a request that creates state is priced (see
//! [`crate::game::admission`]) and checked against the per-request limits and the server's
//! budgets before anything is built, and what is built runs on a bounded blocking pool.

use axum::http::StatusCode;

use crate::game::admission::NoRoom;
use crate::game::admission::{self, Price};
use crate::http::{ApiError, AppState};
use crate::metrics::Refusal;

/// Runs `work` on the blocking pool, at most as many at once as there are cores:
/// validating and building maps and worlds takes up to seconds (priced and bounded before
/// it starts) and must neither hold up the async workers nor pile up threads.
pub async fn off_workers<T: Send + 'static>(
    state: &AppState,
    what: &'static str,
    work: impl FnOnce() -> T + Send + 'static,
) -> Result<T, ApiError> {
    let failed = |e: &dyn std::fmt::Display| {
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            format!("{what} failed: {e}"),
        )
    };
    let _permit = state.builders.acquire().await.map_err(|e| failed(&e))?;
    tokio::task::spawn_blocking(work)
        .await
        .map_err(|e| failed(&e))
}

/// Refuses what one request may not cost (`Config`'s per-request limits), naming the
/// figure, the limit and what drives it.
pub fn within_request_limits(state: &AppState, what: &str, price: Price) -> Result<(), ApiError> {
    let cfg = &state.registry.config;
    let refuse = |message: String| {
        state.registry.metrics.refuse(Refusal::Budget);
        Err(ApiError::bad_request(message))
    };
    if price.memory > cfg.max_request_memory_mb * 1_000_000 {
        return refuse(format!(
            "{what} would keep about {}, over this server's limit of {} MB per request (the map's size and walls, tracker.particles_per_role × opponents, a fine tracker.grid_cell, and one tracker per robot behind an imperfect radio weigh most)",
            admission::mb(price.memory),
            cfg.max_request_memory_mb
        ));
    }
    if price.build_s > cfg.max_build_s {
        return refuse(format!(
            "{what} would take about {:.1} s of CPU to build, over this server's limit of {} s (long walls across a big map weigh most: each costs by the area of its bounding box)",
            price.build_s, cfg.max_build_s
        ));
    }
    if price.tick_ms > cfg.max_tick_ms {
        return refuse(format!(
            "{what}: each tick would take about {:.1} ms of CPU, over this server's limit of {} ms per match (robots × the map's area, particles × tracker copies, and landmarks weigh most)",
            price.tick_ms, cfg.max_tick_ms
        ));
    }
    Ok(())
}

pub fn no_room(why: NoRoom) -> ApiError {
    match why {
        NoRoom::Server(max) => ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "the server holds {max} matches, its most; try again when one has finished (finished matches are removed after a grace period)"
            ),
        ),
        NoRoom::Client { client, max } => ApiError::new(
            StatusCode::TOO_MANY_REQUESTS,
            format!(
                "{client} holds {max} matches, the most one client may; delete one (DELETE /api/matches/{{id}} with its owner_token) or wait for one to end"
            ),
        ),
        NoRoom::Memory {
            held,
            asked,
            budget,
        } => ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "the server's memory budget of {} is taken ({} admitted; this needs {}); try again when matches have ended",
                admission::mb(budget),
                admission::mb(held),
                admission::mb(asked)
            ),
        ),
        NoRoom::ClientBudget {
            client,
            held,
            asked,
            memory,
            tick_ms,
        } => ApiError::new(
            StatusCode::TOO_MANY_REQUESTS,
            format!(
                "{client} holds matches and maps priced at {} and {:.1} ms per tick; this needs {} and {:.1} ms, past the share one client may hold ({} and {tick_ms:.1} ms); delete a match or map (with its owner_token) or wait for one to end",
                admission::mb(held.memory),
                held.tick_ms,
                admission::mb(asked.memory),
                asked.tick_ms,
                admission::mb(memory)
            ),
        ),
        NoRoom::Cpu {
            held_ms,
            asked_ms,
            budget_ms,
        } => ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "the server's tick budget of {budget_ms:.0} ms is taken ({held_ms:.1} ms admitted; this match needs {asked_ms:.1} ms); try again when matches have ended"
            ),
        ),
        NoRoom::Draining => ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "the server is shutting down and takes no new matches; its running matches go on until they end",
        ),
    }
}
