//! Parties' rooms in SQLite: one row each, the room as one document.

use rusqlite::{Connection, params};

use super::rows::db;
use crate::store::backend::{KeptParty, StoreError};

pub fn keep(conn: &Connection, party: &KeptParty) -> Result<(), StoreError> {
    conn.execute(
        "INSERT INTO parties (code, doc) VALUES (?1, ?2)
         ON CONFLICT (code) DO UPDATE SET doc = excluded.doc",
        params![party.code, party.doc],
    )
    .map_err(db)?;
    Ok(())
}

pub fn drop(conn: &Connection, code: &str) -> Result<(), StoreError> {
    conn.execute("DELETE FROM parties WHERE code = ?1", [code])
        .map_err(db)?;
    Ok(())
}

pub fn kept(conn: &Connection) -> Result<Vec<KeptParty>, StoreError> {
    let mut st = conn
        .prepare("SELECT code, doc FROM parties ORDER BY code")
        .map_err(db)?;
    let rows = st
        .query_map([], |r| {
            Ok(KeptParty {
                code: r.get(0)?,
                doc: r.get(1)?,
            })
        })
        .map_err(db)?;
    rows.collect::<Result<_, _>>().map_err(db)
}
