//! Uploaded policies in SQLite: one row each, the model as uploaded.

use rusqlite::{Connection, params};

use super::rows::db;
use crate::store::backend::{KeptPolicy, StoreError};

/// Keeps `policy`; false, keeping nothing, when its name is kept already.
pub fn keep(conn: &Connection, policy: &KeptPolicy) -> Result<bool, StoreError> {
    let added = conn
        .execute(
            "INSERT OR IGNORE INTO policies (name, model, token, client, decide_every, added_at)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6)",
            params![
                policy.name,
                policy.model,
                policy.token,
                policy.client,
                policy.every.min(i64::MAX as u64) as i64,
                policy.added_at
            ],
        )
        .map_err(db)?;
    Ok(added == 1)
}

pub fn drop(conn: &Connection, name: &str) -> Result<(), StoreError> {
    conn.execute("DELETE FROM policies WHERE name = ?1", [name])
        .map_err(db)?;
    Ok(())
}

/// The kept policies, oldest first: every one, or the one called `name`.
pub fn kept(conn: &Connection, name: Option<&str>) -> Result<Vec<KeptPolicy>, StoreError> {
    let mut st = conn
        .prepare(
            "SELECT name, model, token, client, decide_every, added_at FROM policies
             WHERE ?1 IS NULL OR name = ?1 ORDER BY added_at, name",
        )
        .map_err(db)?;
    let rows = st
        .query_map([name], |r| {
            Ok(KeptPolicy {
                name: r.get(0)?,
                model: r.get(1)?,
                token: r.get(2)?,
                client: r.get(3)?,
                every: r.get::<_, i64>(4)?.max(0) as u64,
                added_at: r.get(5)?,
            })
        })
        .map_err(db)?;
    rows.collect::<Result<_, _>>().map_err(db)
}
