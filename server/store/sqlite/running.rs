//! What a match left running keeps for its resume: the list of such matches, each one's
//! record with its checkpoints, the checkpoints' turnover, and the end of a match that could
//! not be resumed.

use rusqlite::{Connection, OptionalExtension, params};

use super::rows::{db, load_where};
use crate::store::backend::{StoreError, StoredCheckpoint, Unfinished};

/// A running match that could not be resumed: over at its last stored tick, reason `lost`.
pub fn lose(conn: &Connection, id: &str) -> Result<(), StoreError> {
    conn.execute(
        "UPDATE matches SET ended_at = updated_at, complete = 0, reason = 'lost'
         WHERE id = ?1 AND ended_at IS NULL",
        [id],
    )
    .map_err(db)?;
    forget_checkpoints(conn, id)
}

/// Stores a running match's checkpoint and lets go of those before `keep_from`.
pub fn checkpoint(
    conn: &Connection,
    id: &str,
    tick: u64,
    applied: u64,
    keep_from: u64,
    state: &[u8],
) -> Result<(), StoreError> {
    let seq: Option<i64> = conn
        .query_row(
            "SELECT seq FROM matches WHERE id = ?1 AND ended_at IS NULL",
            [id],
            |r| r.get(0),
        )
        .optional()
        .map_err(db)?;
    let Some(seq) = seq else {
        return Err(StoreError::Unknown(id.to_string()));
    };
    conn.execute(
        "INSERT OR REPLACE INTO checkpoints (seq, tick, applied, state) VALUES (?1, ?2, ?3, ?4)",
        params![seq, tick as i64, applied as i64, state],
    )
    .map_err(db)?;
    conn.execute(
        "DELETE FROM checkpoints WHERE seq = ?1 AND tick < ?2",
        params![seq, keep_from.min(tick) as i64],
    )
    .map_err(db)?;
    Ok(())
}

/// An ended match needs no checkpoints: its replay starts at tick 0.
pub(super) fn forget_checkpoints(conn: &Connection, id: &str) -> Result<(), StoreError> {
    conn.execute(
        "DELETE FROM checkpoints WHERE seq = (SELECT seq FROM matches WHERE id = ?1)",
        [id],
    )
    .map_err(db)?;
    Ok(())
}

/// The matches left running: those people were playing first (they are waiting), then the
/// rest, oldest first.
pub fn unfinished(conn: &Connection) -> Result<Vec<String>, StoreError> {
    let mut stmt = conn
        .prepare_cached(
            "SELECT id FROM matches WHERE ended_at IS NULL
             ORDER BY COALESCE(live LIKE '%\"seats\"%', 0) DESC, seq",
        )
        .map_err(db)?;
    let rows = stmt.query_map([], |r| r.get::<_, String>(0)).map_err(db)?;
    rows.collect::<Result<_, _>>().map_err(db)
}

/// One match left running, whole, with what resumes it.
pub fn load_unfinished(conn: &Connection, id: &str) -> Result<Option<Unfinished>, StoreError> {
    let Some((stored, live)) = load_where(conn, id, false)? else {
        return Ok(None);
    };
    let mut stmt = conn
        .prepare_cached(
            "SELECT tick, applied, state FROM checkpoints
             WHERE seq = (SELECT seq FROM matches WHERE id = ?1) ORDER BY tick DESC",
        )
        .map_err(db)?;
    let checkpoints = stmt
        .query_map([id], |r| {
            Ok(StoredCheckpoint {
                tick: r.get::<_, i64>(0)?.max(0) as u64,
                applied: r.get::<_, i64>(1)?.max(0) as u64,
                state: r.get(2)?,
            })
        })
        .map_err(db)?
        .collect::<Result<Vec<_>, _>>()
        .map_err(db)?;
    Ok(Some(Unfinished {
        stored,
        live,
        checkpoints,
    }))
}
