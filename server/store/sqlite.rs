//! The SQLite database behind the store: its schema and migrations, and every statement.
//!
//! One file, `lasertag.db`, in WAL mode: the writer thread commits while readers read, and a
//! killed process loses nothing it committed. `PRAGMA user_version` is the schema's version;
//! `schema::migrate` brings an older file up to date in one transaction per step. The statements
//! are plain SQL of the common kind, so that a server database can stand in behind the same
//! [`Backend`](super::Backend) for a fleet.

use std::path::Path;

use rusqlite::{Connection, OptionalExtension, params};

use crate::store::backend::{
    self, Ended, LeaderOrder, Listed, Played, PlayerStats, Retention, StoreError, Stored,
    Unfinished,
};

/// Opens (creating) the database in `dir` and brings its schema up to date.
pub fn open(dir: &Path) -> Result<Connection, StoreError> {
    std::fs::create_dir_all(dir).map_err(|e| StoreError::Io {
        path: dir.display().to_string(),
        message: e.to_string(),
    })?;
    let path = dir.join("lasertag.db");
    let mut conn = Connection::open(&path).map_err(db)?;
    // auto_vacuum only takes on a new file (before the first table): evicted matches then
    // give their pages back to the file system (`incremental_vacuum`), so retention bounds
    // the file, not only its contents.
    conn.execute_batch(
        "PRAGMA auto_vacuum = INCREMENTAL;
         PRAGMA journal_mode = WAL;
         PRAGMA synchronous = NORMAL;
         PRAGMA foreign_keys = ON;
         PRAGMA busy_timeout = 5000;",
    )
    .map_err(db)?;
    migrate(&mut conn)?;
    Ok(conn)
}

/// Opens a second connection to an opened database, for reading beside the writer.
pub fn open_reader(dir: &Path) -> Result<Connection, StoreError> {
    let conn = Connection::open(dir.join("lasertag.db")).map_err(db)?;
    conn.execute_batch("PRAGMA foreign_keys = ON; PRAGMA busy_timeout = 5000;")
        .map_err(db)?;
    Ok(conn)
}

/// A match's start as the database stores it.
pub struct Begun<'a> {
    pub id: &'a str,
    pub map: &'a str,
    pub map_hash: &'a str,
    pub map_document: &'a str,
    /// JSON of `codec::StoredSettings`.
    pub settings: &'a str,
    /// JSON of `codec::StoredLive`.
    pub live: &'a str,
    /// Unix milliseconds.
    pub started_at: i64,
}

pub fn begin(conn: &Connection, b: &Begun<'_>) -> Result<(), StoreError> {
    conn.execute(
        "INSERT OR IGNORE INTO maps (hash, name, document) VALUES (?1, ?2, ?3)",
        params![b.map_hash, b.map, b.map_document],
    )
    .map_err(db)?;
    conn.execute(
        "INSERT INTO matches (id, map, map_hash, settings, started_at, updated_at, bytes, live)
         VALUES (?1, ?2, ?3, ?4, ?5, ?5, ?6, ?7)",
        params![
            b.id,
            b.map,
            b.map_hash,
            b.settings,
            b.started_at,
            b.settings.len() as i64,
            b.live
        ],
    )
    .map_err(db)?;
    Ok(())
}

/// Adds a chunk of inputs (if any) and moves the match's last tick on.
pub fn append(
    conn: &Connection,
    id: &str,
    chunk: Option<&[u8]>,
    names: Option<&str>,
    live: Option<&str>,
    tick: u64,
    now: i64,
) -> Result<(), StoreError> {
    let seq: Option<i64> = conn
        .query_row("SELECT seq FROM matches WHERE id = ?1", [id], |r| r.get(0))
        .optional()
        .map_err(db)?;
    let Some(seq) = seq else {
        return Err(StoreError::Unknown(id.to_string()));
    };
    let bytes = chunk.map_or(0, |c| c.len() as i64);
    if let Some(chunk) = chunk {
        conn.execute(
            "INSERT INTO inputs (seq, chunk) VALUES (?1, ?2)",
            params![seq, chunk],
        )
        .map_err(db)?;
    }
    conn.execute(
        "UPDATE matches SET ticks = ?2, updated_at = ?3, bytes = bytes + ?4,
                names = COALESCE(?5, names), live = COALESCE(?6, live) WHERE seq = ?1",
        params![seq, tick as i64, now, bytes, names, live],
    )
    .map_err(db)?;
    Ok(())
}

pub fn finish(conn: &Connection, id: &str, ended: &Ended) -> Result<(), StoreError> {
    let seq: i64 = conn
        .query_row("SELECT seq FROM matches WHERE id = ?1", [id], |r| r.get(0))
        .map_err(db)?;
    forget_checkpoints(conn, id)?;
    conn.execute(
        "UPDATE matches SET ended_at = ?2, ticks = ?3, winner = ?4, reason = ?5, complete = 1
         WHERE seq = ?1",
        params![
            seq,
            ended.ended_at,
            ended.ticks as i64,
            ended.winner,
            ended.reason
        ],
    )
    .map_err(db)?;
    for p in &ended.players {
        let rating = match ended.rated.filter(|_| p.rated) {
            Some(preset) => Some(rate(conn, &p.name, preset, p.won, ended.ended_at)?),
            None => None,
        };
        conn.execute(
            "INSERT INTO players (seq, name, tags, survived_ticks, won, rating_before, rating_after)
             VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7)",
            params![
                seq,
                p.name,
                p.tags,
                p.survived_ticks as i64,
                p.won,
                rating.map(|r| r.0.rating),
                rating.map(|r| r.1.rating)
            ],
        )
        .map_err(db)?;
    }
    Ok(())
}

/// Ended matches (see [`Backend::list`]): in the order they ended, the newest first.
pub fn list(
    conn: &Connection,
    limit: usize,
    before: Option<&str>,
    without_prefix: Option<&str>,
) -> Result<Vec<Listed>, StoreError> {
    let mut stmt = conn
        .prepare_cached(&format!(
            "{LISTED} WHERE ended_at IS NOT NULL
               AND (?3 IS NULL OR substr(id, 1, length(?3)) <> ?3)
               AND (NOT EXISTS (SELECT 1 FROM matches WHERE id = ?1 AND ended_at IS NOT NULL)
                    OR (ended_at, seq) < (SELECT ended_at, seq FROM matches WHERE id = ?1))
             ORDER BY ended_at DESC, seq DESC LIMIT ?2"
        ))
        .map_err(db)?;
    let rows = stmt
        .query_map(params![before, limit as i64, without_prefix], listed)
        .map_err(db)?;
    rows.collect::<Result<_, _>>().map_err(db)
}

/// One ended match, whole.
pub fn load(conn: &Connection, id: &str) -> Result<Option<Stored>, StoreError> {
    Ok(load_where(conn, id, true)?.map(|(stored, _)| stored))
}

/// What the store holds: ended matches and their bytes (settings and inputs).
pub fn totals(conn: &Connection) -> Result<(u64, u64), StoreError> {
    conn.query_row(
        "SELECT COUNT(*), COALESCE(SUM(bytes), 0) FROM matches WHERE ended_at IS NOT NULL",
        [],
        |r| Ok((r.get::<_, i64>(0)? as u64, r.get::<_, i64>(1)? as u64)),
    )
    .map_err(db)
}

/// Bytes of the database file in use: its pages less the free ones (what the file shrinks
/// to once `vacuum` gives those back), indexes, maps and every match included.
fn used_bytes(conn: &Connection) -> Result<u64, StoreError> {
    let pragma = |name: &str| -> Result<u64, StoreError> {
        conn.query_row(&format!("PRAGMA {name}"), [], |r| r.get::<_, i64>(0))
            .map(|v| v.max(0) as u64)
            .map_err(db)
    };
    let pages = pragma("page_count")?.saturating_sub(pragma("freelist_count")?);
    Ok(pages * pragma("page_size")?)
}

/// Deletes the oldest ended matches, and each one's map when no other match uses it, until
/// at most `max_matches` are left and the database uses at most `max_bytes` of the file
/// system (its real size: stored maps, running matches and SQLite's own pages count too).
/// Answers how many matches went.
pub fn evict(conn: &Connection, max_matches: u64, max_bytes: u64) -> Result<u64, StoreError> {
    let (mut count, _) = totals(conn)?;
    let mut evicted = 0;
    while count > max_matches || used_bytes(conn)? > max_bytes {
        let oldest: Option<(i64, String)> = conn
            .query_row(
                "SELECT seq, map_hash FROM matches WHERE ended_at IS NOT NULL ORDER BY seq LIMIT 1",
                [],
                |r| Ok((r.get(0)?, r.get(1)?)),
            )
            .optional()
            .map_err(db)?;
        let Some((seq, map_hash)) = oldest else { break };
        conn.execute("DELETE FROM matches WHERE seq = ?1", [seq])
            .map_err(db)?;
        conn.execute(
            "DELETE FROM maps WHERE hash = ?1
             AND NOT EXISTS (SELECT 1 FROM matches WHERE map_hash = ?1)",
            [&map_hash],
        )
        .map_err(db)?;
        count -= 1;
        evicted += 1;
    }
    Ok(evicted)
}

/// Bytes of the shared-memory index SQLite keeps beside a database in WAL mode.
const SHM_BYTES: u64 = 32 * 1024;

/// Keeps the write-ahead log, beside the database in the data directory, to a twentieth of
/// the history's bytes (at least 16 pages): checkpoints that often, and the log cut back to
/// that size after each. Answers the bytes the log and the shared memory may take, which
/// the database leaves them of the history's bytes.
fn bound_wal(conn: &Connection, max_bytes: u64) -> Result<u64, StoreError> {
    let page: i64 = conn
        .query_row("PRAGMA page_size", [], |r| r.get(0))
        .map_err(db)?;
    let wal = (max_bytes / 20).min(i64::MAX as u64) as i64;
    let pages = (wal / page.max(1)).max(16);
    conn.execute_batch(&format!(
        "PRAGMA wal_autocheckpoint = {pages}; PRAGMA journal_size_limit = {};",
        pages * page
    ))
    .map_err(db)?;
    Ok((pages * page) as u64 + SHM_BYTES)
}

/// Gives the pages of deleted rows back to the file system (outside a transaction).
pub fn vacuum(conn: &Connection) -> Result<(), StoreError> {
    // The pragma yields a row for every page it gives back and frees the next one only when
    // stepped again: read it to the end (`execute_batch` steps once, freeing one page).
    let mut stmt = conn.prepare("PRAGMA incremental_vacuum").map_err(db)?;
    let mut rows = stmt.query([]).map_err(db)?;
    while rows.next().map_err(db)?.is_some() {}
    Ok(())
}

/// The SQLite [`Backend`](super::Backend).
pub struct Sqlite {
    conn: Connection,
    retention: Retention,
    /// Of `retention.max_bytes`, what the write-ahead log and shared memory may take.
    beside: u64,
}

impl Sqlite {
    /// The writer's connection: creates and migrates the database.
    pub fn open(dir: &Path, retention: Retention) -> Result<Sqlite, StoreError> {
        let conn = open(dir)?;
        let beside = bound_wal(&conn, retention.max_bytes)?;
        Ok(Sqlite {
            conn,
            retention,
            beside,
        })
    }

    /// A reader's connection to a database [`Sqlite::open`] made.
    pub fn reader(dir: &Path, retention: Retention) -> Result<Sqlite, StoreError> {
        Ok(Sqlite {
            conn: open_reader(dir)?,
            retention,
            beside: 0,
        })
    }

    pub fn connection(&self) -> &Connection {
        &self.conn
    }
}

impl backend::Backend for Sqlite {
    fn write(&mut self, batch: &[backend::Write]) -> Result<(), StoreError> {
        use backend::Write;
        let now = backend::unix_ms(std::time::SystemTime::now());
        let tx = self.conn.transaction().map_err(db)?;
        let mut finished = false;
        let mut begun = false;
        for w in batch {
            // One write that fails (a match whose start was never stored) costs only itself:
            // SQLite undoes the failed statement, not the transaction.
            let done = match w {
                Write::Begin {
                    id,
                    arena,
                    settings,
                    live,
                    started_at,
                } => {
                    begun = true;
                    let document = crate::maps::import::to_json(&crate::maps::to_file(&arena.def));
                    serde_json::to_string(settings)
                        .map_err(|e| StoreError::Database(e.to_string()))
                        .and_then(|settings| {
                            begin(
                                &tx,
                                &Begun {
                                    id,
                                    map: &arena.def.name,
                                    map_hash: &backend::map_key(&document),
                                    map_document: &document,
                                    settings: &settings,
                                    live: &live.to_json(),
                                    started_at: backend::unix_ms(*started_at),
                                },
                            )
                        })
                }
                Write::Append {
                    id,
                    inputs,
                    names,
                    live,
                    tick,
                } => {
                    let chunk =
                        (!inputs.is_empty()).then(|| crate::store::codec::encode_inputs(inputs));
                    let names = names
                        .as_ref()
                        .map(|n| serde_json::to_string(n).unwrap_or_else(|_| "[]".into()));
                    let live = live.as_ref().map(|l| l.to_json());
                    append(
                        &tx,
                        id,
                        chunk.as_deref(),
                        names.as_deref(),
                        live.as_deref(),
                        *tick,
                        now,
                    )
                }
                Write::Checkpoint {
                    id,
                    tick,
                    applied,
                    keep_from,
                    world,
                    max_bytes,
                } => crate::store::backend::checkpoint_state(id, world, *max_bytes)
                    .and_then(|state| checkpoint(&tx, id, *tick, *applied, *keep_from, &state)),
                Write::Lost { id } => {
                    finished = true;
                    lose(&tx, id)
                }
                Write::Finish { id, ended } => {
                    finished = true;
                    finish(&tx, id, ended)
                }
                Write::Flush(_)
                | Write::Adopt { .. }
                | Write::HandOver { .. }
                | Write::Claim { .. }
                | Write::Release { .. }
                | Write::KeepPolicy { .. }
                | Write::DropPolicy { .. }
                | Write::KeepParty(_)
                | Write::DropParty { .. } => Ok(()),
            };
            match done {
                // The disk, not this write: the whole batch is undone, to be tried again.
                Err(e @ StoreError::Unwritable(_)) => return Err(e),
                Err(e) => tracing::warn!("history: {e}"),
                Ok(()) => {}
            }
        }
        // A match's start stores its map, its end may leave the history past its bounds.
        let evicted = if finished || begun {
            let bytes = self.retention.max_bytes.saturating_sub(self.beside);
            evict(&tx, self.retention.max_matches, bytes)?
        } else {
            0
        };
        tx.commit().map_err(db)?;
        if evicted > 0 {
            vacuum(&self.conn)?;
        }
        if finished || evicted > 0 {
            // The log holds what this batch wrote (a map can be larger than its bound):
            // written back and cut to nothing, unless a reader is in the way (then at the
            // next checkpoint).
            self.conn
                .query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()))
                .map_err(db)?;
        }
        Ok(())
    }

    fn list(
        &mut self,
        limit: usize,
        before: Option<&str>,
        without_prefix: Option<&str>,
    ) -> Result<Vec<Listed>, StoreError> {
        list(&self.conn, limit, before, without_prefix)
    }

    fn load(&mut self, id: &str) -> Result<Option<Stored>, StoreError> {
        load(&self.conn, id)
    }

    fn input_chunks(
        &mut self,
        id: &str,
        from: usize,
        count: usize,
    ) -> Result<Vec<Vec<u8>>, StoreError> {
        let mut stmt = self
            .conn
            .prepare_cached(
                "SELECT chunk FROM inputs
                 WHERE seq = (SELECT seq FROM matches WHERE id = ?1 AND ended_at IS NOT NULL)
                 ORDER BY rowid LIMIT ?2 OFFSET ?3",
            )
            .map_err(db)?;
        stmt.query_map(rusqlite::params![id, count as i64, from as i64], |r| {
            r.get::<_, Vec<u8>>(0)
        })
        .map_err(db)?
        .collect::<Result<Vec<_>, _>>()
        .map_err(db)
    }

    fn unfinished(&mut self) -> Result<Vec<String>, StoreError> {
        unfinished(&self.conn)
    }

    fn load_unfinished(&mut self, id: &str) -> Result<Option<Unfinished>, StoreError> {
        load_unfinished(&self.conn, id)
    }

    fn claim(
        &mut self,
        claim: &backend::NameClaim,
        limits: backend::ClaimLimits,
    ) -> Result<backend::ClaimOutcome, StoreError> {
        names::claim(&mut self.conn, claim, limits)
    }

    fn release(&mut self, key: &str, token: &str) -> Result<backend::ReleaseOutcome, StoreError> {
        names::release(&mut self.conn, key, token)
    }

    fn claimed(&mut self, key: &str) -> Result<Option<backend::NameClaim>, StoreError> {
        names::claimed(&self.conn, key)
    }

    fn keep_policy(&mut self, policy: &backend::KeptPolicy) -> Result<bool, StoreError> {
        policies::keep(&self.conn, policy)
    }

    fn drop_policy(&mut self, name: &str) -> Result<(), StoreError> {
        policies::drop(&self.conn, name)
    }

    fn kept_policies(&mut self) -> Result<Vec<backend::KeptPolicy>, StoreError> {
        policies::kept(&self.conn, None)
    }

    fn kept_policy(&mut self, name: &str) -> Result<Option<backend::KeptPolicy>, StoreError> {
        Ok(policies::kept(&self.conn, Some(name))?.pop())
    }

    fn keep_party(&mut self, party: &backend::KeptParty) -> Result<(), StoreError> {
        parties::keep(&self.conn, party)
    }

    fn drop_party(&mut self, code: &str) -> Result<(), StoreError> {
        parties::drop(&self.conn, code)
    }

    fn kept_parties(&mut self) -> Result<Vec<backend::KeptParty>, StoreError> {
        parties::kept(&self.conn)
    }

    fn player(&mut self, name: &str) -> Result<Option<PlayerStats>, StoreError> {
        player(&self.conn, name)
    }

    fn played(&mut self, name: &str, limit: usize) -> Result<Vec<Played>, StoreError> {
        played(&self.conn, name, limit)
    }

    fn leaders(
        &mut self,
        order: LeaderOrder,
        limit: usize,
    ) -> Result<Vec<PlayerStats>, StoreError> {
        leaders(&self.conn, order, limit)
    }

    fn totals(&mut self) -> Result<(u64, u64), StoreError> {
        totals(&self.conn)
    }
}

mod names;
mod parties;
mod players;
mod policies;
mod rows;
mod running;
mod schema;
use players::rate;
pub use players::{leaders, played, player};
use rows::{LISTED, db, listed, load_where};
use running::forget_checkpoints;
pub use running::{checkpoint, load_unfinished, lose, unfinished};
pub use schema::SCHEMA_VERSION;
use schema::migrate;

#[cfg(test)]
mod tests;
