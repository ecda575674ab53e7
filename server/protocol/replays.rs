//! The shapes of history and replays: a finished match in the list, one replay's summary
//! with its settings and events, and the lines of its export.

use serde::Serialize;
use utoipa::ToSchema;

use super::{Belief, EventDto, MatchState, MatchSummary, Winner};

/// One line of a replay's export (`GET /api/replays/{id}/export`): the state at `tick`, and
/// the team's belief when asked for.
#[derive(Debug, Serialize)]
pub struct ExportLine<'a> {
    pub tick: u64,
    pub state: &'a MatchState,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub belief: Option<&'a Belief>,
}

/// The last line of every export: whether it is complete (`lines` lines were sent) and, when
/// the server cut it short, why and the tick to resume from (`?from_tick=`).
#[derive(Debug, Serialize)]
pub struct ExportEnd<'a> {
    pub complete: bool,
    pub lines: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub from_tick: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<&'a str>,
}

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
    pub reason: Option<String>,
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

/// A player name's totals, as the leaderboard and `GET /api/players/{name}` show them.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct PlayerTotals {
    pub name: String,
    /// Ended matches they played.
    pub matches: u64,
    /// Matches the opponents won with them still in it.
    pub wins: u64,
    /// Robots they tagged.
    pub tags: u64,
    /// Their longest stay in a match without being tagged, seconds.
    pub longest_survival_s: f64,
    /// Their rating, once they have played a rated match (docs/ratings.md); null before.
    pub rating: Option<RatingDto>,
}

/// A name's Glicko-2 rating: the robot presets' fixed ratings are on the same scale, where
/// the `evade` bot stands at 1500.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct RatingDto {
    pub rating: f64,
    /// Its uncertainty: the name's strength is within two deviations of `rating` with 95%
    /// confidence. The leaderboard ranks by `rating - 2 * deviation`.
    pub deviation: f64,
    /// Rated matches it rests on.
    pub matches: u64,
}

/// A match a name played, with what it did to their rating.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct PlayedMatch {
    #[serde(flatten)]
    pub listed: ReplayListed,
    /// Their rating before and after this match; null when it was not rated.
    pub rating_before: Option<f64>,
    pub rating_after: Option<f64>,
}

/// `GET /api/players/{name}`: the totals and the latest matches of that name.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct PlayerDetail {
    #[serde(flatten)]
    pub totals: PlayerTotals,
    /// Their latest ended matches, newest first (at most 20).
    pub recent: Vec<PlayedMatch>,
}

/// `GET /api/leaderboard`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Leaderboard {
    /// What it ranks by: `wins`, `tags`, `survival`, `matches` or `rating` (rated names
    /// only, by `rating - 2 * deviation`).
    pub by: &'static str,
    pub players: Vec<PlayerTotals>,
}
