//! A name's statistics and rating in SQLite: the totals over the stored matches, the
//! matches a name played with what each did to their rating, the leaderboards, and the
//! rating update a rated match's end makes (in the writer's transaction).

use rusqlite::{Connection, OptionalExtension, params};

use super::rows::{db, listed};
use crate::store::backend::{LeaderOrder, Played, PlayerStats, Rated, StoreError};
use crate::store::ratings::{self, Rating};

const STATS: &str = "SELECT p.name, COUNT(*), SUM(p.won), SUM(p.tags), MAX(p.survived_ticks),
                             r.rating, r.deviation, r.matches
                      FROM players p LEFT JOIN ratings r ON r.name = p.name";
const BY_NAME: &str = "GROUP BY p.name, r.rating, r.deviation, r.matches";

fn stats(r: &rusqlite::Row) -> rusqlite::Result<PlayerStats> {
    let rating = match r.get::<_, Option<f64>>(5)? {
        Some(rating) => Some(Rated {
            rating,
            deviation: r.get(6)?,
            matches: r.get::<_, i64>(7)?.max(0) as u64,
        }),
        None => None,
    };
    Ok(PlayerStats {
        name: r.get(0)?,
        matches: r.get::<_, i64>(1)? as u64,
        wins: r.get::<_, i64>(2)? as u64,
        tags: r.get::<_, i64>(3)? as u64,
        longest_survival_ticks: r.get::<_, i64>(4)? as u64,
        rating,
    })
}

/// The totals of everyone named `name`.
pub fn player(conn: &Connection, name: &str) -> Result<Option<PlayerStats>, StoreError> {
    conn.query_row(
        &format!("{STATS} WHERE p.name = ?1 {BY_NAME}"),
        [name],
        stats,
    )
    .optional()
    .map_err(db)
}

/// The ended matches `name` played, newest first, with what each did to their rating.
pub fn played(conn: &Connection, name: &str, limit: usize) -> Result<Vec<Played>, StoreError> {
    let mut stmt = conn
        .prepare_cached(
            "SELECT m.id, m.map, m.started_at, m.ended_at, m.ticks, m.winner, m.reason,
                    m.complete, m.names, p.rating_before, p.rating_after
             FROM players p JOIN matches m ON m.seq = p.seq
             WHERE p.name = ?1 ORDER BY m.seq DESC LIMIT ?2",
        )
        .map_err(db)?;
    let rows = stmt
        .query_map(params![name, limit as i64], |r| {
            Ok(Played {
                listed: listed(r)?,
                rating_before: r.get(9)?,
                rating_after: r.get(10)?,
            })
        })
        .map_err(db)?;
    rows.collect::<Result<_, _>>().map_err(db)
}

/// The best `limit` names by `order`.
pub fn leaders(
    conn: &Connection,
    order: LeaderOrder,
    limit: usize,
) -> Result<Vec<PlayerStats>, StoreError> {
    let (only, by) = leader_order(order);
    let mut stmt = conn
        .prepare_cached(&format!(
            "{STATS} {only} {BY_NAME} ORDER BY {by}, p.name LIMIT ?1"
        ))
        .map_err(db)?;
    let rows = stmt.query_map([limit as i64], stats).map_err(db)?;
    rows.collect::<Result<_, _>>().map_err(db)
}

/// A leaderboard's filter and order, in SQL both databases take.
fn leader_order(order: LeaderOrder) -> (&'static str, &'static str) {
    match order {
        LeaderOrder::Wins => ("", "SUM(p.won) DESC, COUNT(*) ASC"),
        LeaderOrder::Tags => ("", "SUM(p.tags) DESC, COUNT(*) ASC"),
        LeaderOrder::Survival => ("", "MAX(p.survived_ticks) DESC"),
        LeaderOrder::Matches => ("", "COUNT(*) DESC"),
        LeaderOrder::Rating => (
            "WHERE r.rating IS NOT NULL",
            "r.rating - 2 * r.deviation DESC",
        ),
    }
}

/// Rates `name` for one match against `preset`: stores the new rating and answers (before,
/// after). A new name past [`ratings::MAX_RATED_NAMES`] pushes out the one rated longest ago.
pub(super) fn rate(
    conn: &Connection,
    name: &str,
    preset: lasertag_core::difficulty::Difficulty,
    won: bool,
    now: i64,
) -> Result<(Rating, Rating), StoreError> {
    let found = conn
        .query_row(
            "SELECT rating, deviation, volatility FROM ratings WHERE name = ?1",
            [name],
            |r| {
                Ok(Rating {
                    rating: r.get(0)?,
                    deviation: r.get(1)?,
                    volatility: r.get(2)?,
                })
            },
        )
        .optional()
        .map_err(db)?;
    let before = found.unwrap_or_else(Rating::newcomer);
    let after = ratings::after(before, preset, won);
    conn.execute(
        "INSERT INTO ratings (name, rating, deviation, volatility, matches, updated_at)
         VALUES (?1, ?2, ?3, ?4, 1, ?5)
         ON CONFLICT (name) DO UPDATE SET rating = ?2, deviation = ?3, volatility = ?4,
                                          matches = matches + 1, updated_at = ?5",
        params![name, after.rating, after.deviation, after.volatility, now],
    )
    .map_err(db)?;
    if found.is_none() {
        conn.execute(
            "DELETE FROM ratings WHERE name IN (
               SELECT name FROM ratings ORDER BY updated_at, name
               LIMIT MAX(0, (SELECT COUNT(*) FROM ratings) - ?1))",
            [ratings::MAX_RATED_NAMES as i64],
        )
        .map_err(db)?;
    }
    Ok((before, after))
}
