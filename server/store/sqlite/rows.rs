//! What every SQLite statement module shares: the store's error for a database error, a
//! listed match's columns and how a row of them reads, and a match read whole.

use rusqlite::{Connection, OptionalExtension, params};

use crate::store::backend::{Listed, StoreError, Stored};

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

/// The match `id`, ended or running as `ended` says, and its live record.
pub(super) fn load_where(
    conn: &Connection,
    id: &str,
    ended: bool,
) -> Result<Option<(Stored, Option<String>)>, StoreError> {
    let row = conn
        .query_row(
            "SELECT id, map, started_at, ended_at, ticks, winner, reason, complete, names,
                    settings, (SELECT document FROM maps WHERE hash = map_hash), seq, live
             FROM matches WHERE id = ?1 AND (ended_at IS NOT NULL) = ?2",
            params![id, ended],
            |r| {
                Ok((
                    listed(r)?,
                    r.get::<_, String>(9)?,
                    r.get::<_, String>(10)?,
                    r.get::<_, i64>(11)?,
                    r.get::<_, Option<String>>(12)?,
                ))
            },
        )
        .optional()
        .map_err(db)?;
    let Some((listed, settings, map_document, seq, live)) = row else {
        return Ok(None);
    };
    let mut stmt = conn
        .prepare_cached("SELECT chunk FROM inputs WHERE seq = ?1 ORDER BY rowid")
        .map_err(db)?;
    let chunks = stmt
        .query_map([seq], |r| r.get::<_, Vec<u8>>(0))
        .map_err(db)?
        .collect::<Result<Vec<_>, _>>()
        .map_err(db)?;
    Ok(Some((
        Stored {
            listed,
            settings,
            map_document,
            chunks,
        },
        live,
    )))
}
