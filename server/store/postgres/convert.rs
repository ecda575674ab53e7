//! The client's errors as the store's, with the database's own words, counts as
//! PostgreSQL's `BIGINT`, and rows as the store's listings and statistics: what the
//! connection, the schema and the writes share.

use ::postgres::Row;

use crate::store::backend::{Listed, PlayerStats, Rated, StoreError};

/// An error of the client, with the database's own message when there is one ("db error"
/// alone says nothing).
pub(super) fn describe(e: &::postgres::Error) -> String {
    if let Some(d) = e.as_db_error() {
        let mut text = format!("{} {}: {}", d.severity(), d.code().code(), d.message());
        if let Some(detail) = d.detail() {
            text.push_str(&format!(" ({detail})"));
        }
        return text;
    }
    match std::error::Error::source(e) {
        Some(cause) => format!("{e}: {cause}"),
        None => e.to_string(),
    }
}

/// A client error as the store's.
pub(super) fn db(e: ::postgres::Error) -> StoreError {
    StoreError::Database(describe(&e))
}

/// A count or tick as PostgreSQL's `BIGINT`.
pub(super) fn big(n: u64) -> i64 {
    i64::try_from(n).unwrap_or(i64::MAX)
}

pub(super) fn listed(r: &Row) -> Result<Listed, ::postgres::Error> {
    let names: String = r.try_get(8)?;
    Ok(Listed {
        id: r.try_get(0)?,
        map: r.try_get(1)?,
        started_at_ms: r.try_get(2)?,
        ended_at_ms: r.try_get(3)?,
        ticks: r.try_get::<_, i64>(4)?.max(0) as u64,
        winner: r.try_get(5)?,
        reason: r.try_get(6)?,
        complete: r.try_get(7)?,
        players: serde_json::from_str(&names).unwrap_or_default(),
    })
}

pub(super) fn stats(r: &Row) -> Result<PlayerStats, ::postgres::Error> {
    let n = |i: usize| {
        r.try_get::<_, Option<i64>>(i)
            .map(|v| v.unwrap_or(0).max(0) as u64)
    };
    let rating = match r.try_get::<_, Option<f64>>(5)? {
        Some(rating) => Some(Rated {
            rating,
            deviation: r.try_get(6)?,
            matches: n(7)?,
        }),
        None => None,
    };
    Ok(PlayerStats {
        name: r.try_get(0)?,
        matches: n(1)?,
        wins: n(2)?,
        tags: n(3)?,
        longest_survival_ticks: n(4)?,
        rating,
    })
}
