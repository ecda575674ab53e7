//! What every SQLite statement module shares: the store's error for a database error, and a
//! listed match's columns and how a row of them reads.

use crate::store::backend::{Listed, StoreError};

pub(super) fn db(e: rusqlite::Error) -> StoreError {
    use rusqlite::ffi::ErrorCode;
    match e.sqlite_error_code() {
        // The disk, not the data: the same writes may succeed once there is room again.
        Some(ErrorCode::DiskFull | ErrorCode::SystemIoFailure | ErrorCode::CannotOpen) => {
            StoreError::Unwritable(e.to_string())
        }
        _ => StoreError::Database(e.to_string()),
    }
}

pub(super) const LISTED: &str =
    "SELECT id, map, started_at, ended_at, ticks, winner, reason, complete, names
                      FROM matches";

pub(super) fn listed(r: &rusqlite::Row) -> rusqlite::Result<Listed> {
    let names: String = r.get(8)?;
    Ok(Listed {
        id: r.get(0)?,
        map: r.get(1)?,
        started_at_ms: r.get(2)?,
        ended_at_ms: r.get(3)?,
        ticks: r.get::<_, i64>(4)? as u64,
        winner: r.get(5)?,
        reason: r.get(6)?,
        complete: r.get(7)?,
        players: serde_json::from_str(&names).unwrap_or_default(),
    })
}
