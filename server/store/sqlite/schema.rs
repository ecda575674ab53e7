//! The SQLite schema, one migration a step, and bringing a file up to date.

use rusqlite::Connection;

use super::rows::db;
use crate::store::backend::StoreError;

/// The schema, one migration a step: step i takes `user_version` i to i + 1.
const MIGRATIONS: &[&str] = &[
    // 1: matches, their inputs in chunks, their maps (deduplicated), who played them.
    "CREATE TABLE maps (
        hash TEXT PRIMARY KEY,
        name TEXT NOT NULL,
        document TEXT NOT NULL
    );
    CREATE TABLE matches (
        seq INTEGER PRIMARY KEY AUTOINCREMENT,
        id TEXT NOT NULL UNIQUE,
        map TEXT NOT NULL,
        map_hash TEXT NOT NULL REFERENCES maps(hash),
        settings TEXT NOT NULL,
        started_at INTEGER NOT NULL,
        updated_at INTEGER NOT NULL,
        ended_at INTEGER,
        ticks INTEGER NOT NULL DEFAULT 0,
        winner TEXT,
        reason TEXT,
        complete INTEGER NOT NULL DEFAULT 0,
        names TEXT NOT NULL DEFAULT '[]',
        bytes INTEGER NOT NULL DEFAULT 0
    );
    CREATE INDEX matches_ended ON matches(ended_at);
    CREATE TABLE inputs (
        seq INTEGER NOT NULL REFERENCES matches(seq) ON DELETE CASCADE,
        chunk BLOB NOT NULL
    );
    CREATE INDEX inputs_by_match ON inputs(seq);
    CREATE TABLE players (
        seq INTEGER NOT NULL REFERENCES matches(seq) ON DELETE CASCADE,
        name TEXT NOT NULL,
        tags INTEGER NOT NULL,
        survived_ticks INTEGER NOT NULL,
        won INTEGER NOT NULL
    );
    CREATE INDEX players_by_name ON players(name);",
    // 2: ratings (docs/ratings.md): each name's, and what each rated match did to it.
    "CREATE TABLE ratings (
        name TEXT PRIMARY KEY,
        rating REAL NOT NULL,
        deviation REAL NOT NULL,
        volatility REAL NOT NULL,
        matches INTEGER NOT NULL,
        updated_at INTEGER NOT NULL
    );
    CREATE INDEX ratings_by_age ON ratings(updated_at);
    ALTER TABLE players ADD COLUMN rating_before REAL;
    ALTER TABLE players ADD COLUMN rating_after REAL;",
    // 3: what resumes a running match (`codec::StoredLive`: owner, seats, token hashes).
    "ALTER TABLE matches ADD COLUMN live TEXT;",
    // 4: running matches' checkpoints (`backend::Write::Checkpoint`), the newest few each.
    "CREATE TABLE checkpoints (
        seq INTEGER NOT NULL REFERENCES matches(seq) ON DELETE CASCADE,
        tick INTEGER NOT NULL,
        applied INTEGER NOT NULL,
        state BLOB NOT NULL,
        PRIMARY KEY (seq, tick)
    );",
    // 5: names people keep (`backend::NameClaim`), by their look-alikes' key.
    "CREATE TABLE names (
        key TEXT PRIMARY KEY,
        name TEXT NOT NULL,
        token TEXT NOT NULL,
        client TEXT NOT NULL,
        claimed_at INTEGER NOT NULL
    );
    CREATE INDEX names_by_client ON names(client);",
    // 6: uploaded policies (`backend::KeptPolicy`), so that they outlive their server.
    "CREATE TABLE policies (
        name TEXT PRIMARY KEY,
        model BLOB NOT NULL,
        token TEXT NOT NULL,
        client TEXT NOT NULL,
        decide_every INTEGER NOT NULL,
        added_at INTEGER NOT NULL
    );",
    // 7: parties' rooms (`backend::KeptParty`), so that a room and its tokens outlive the
    // server.
    "CREATE TABLE parties (
        code TEXT PRIMARY KEY,
        doc TEXT NOT NULL
    );",
];

/// The schema version this build writes.
pub const SCHEMA_VERSION: usize = MIGRATIONS.len();

pub fn migrate(conn: &mut Connection) -> Result<(), StoreError> {
    let version: usize = conn
        .query_row("PRAGMA user_version", [], |r| r.get(0))
        .map_err(db)?;
    if version > SCHEMA_VERSION {
        return Err(StoreError::NewerSchema {
            found: version,
            known: SCHEMA_VERSION,
        });
    }
    for (step, sql) in MIGRATIONS.iter().enumerate().skip(version) {
        let tx = conn.transaction().map_err(db)?;
        tx.execute_batch(sql).map_err(db)?;
        tx.pragma_update(None, "user_version", step + 1)
            .map_err(db)?;
        tx.commit().map_err(db)?;
    }
    Ok(())
}
