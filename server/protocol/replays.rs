//! The shapes of history and replays: a finished match in the list, and one replay's
//! summary with its settings and events.

use std::time::{SystemTime, UNIX_EPOCH};

use serde::Serialize;
use utoipa::ToSchema;

use super::{EventDto, MatchSummary, Winner};

/// A finished match as `GET /api/replays` lists it.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ReplayListed {
    pub id: String,
    pub map: String,
    /// Unix time (seconds) the match was set up and ended.
    pub started_at: f64,
    pub ended_at: f64,
    /// Its last tick.
    pub ticks: u64,
    pub winner: Option<Winner>,
    /// Why it ended: `all_tagged`, `time_limit`, `stopped`, `server_shutdown`, `abandoned`
    /// or `overloaded`.
    pub reason: Option<&'static str>,
    /// Whether the recording reaches the end (false for a match cut short by a crash).
    pub complete: bool,
    /// Names of the people who played.
    pub players: Vec<String>,
}

/// `GET /api/replays/{id}`: the listing, the settings as the match's summary showed them at
/// its end, and every event.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ReplayDetail {
    #[serde(flatten)]
    pub listed: ReplayListed,
    pub settings: MatchSummary,
    pub events: Vec<EventDto>,
}

/// Unix time in seconds, to the millisecond.
pub fn unix(t: SystemTime) -> f64 {
    t.duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| (d.as_secs_f64() * 1000.0).round() / 1000.0)
}
