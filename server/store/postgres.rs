//! The PostgreSQL database behind the store, for a fleet: every server writes its own matches
//! into one database and lists, loads and counts everyone's.
//!
//! The tables are SQLite's ([`sqlite`](super::sqlite)) with PostgreSQL's types, plus
//! `writers` (`schema.rs`: the migrations and every statement). `lasertag_schema` holds the
//! schema's version; [`migrate`] runs under an advisory lock, so servers starting together
//! migrate once, and refuses a newer schema. A batch is one transaction (`write.rs`);
//! retention is plain `DELETE` (autovacuum gives the space back).
//!
//! Several servers share the database, so "matches a previous process left running" cannot
//! mean every unfinished match. Each process's writer has an id of its own: it stamps its
//! matches with it, only it appends to or finishes them, and it beats every
//! [`HEARTBEAT`](super::HEARTBEAT) (`writers.seen_at`, on the database's clock, so the
//! servers' clocks do not matter). A match still running whose writer has been silent for
//! [`STALE_AFTER`] is closed as incomplete by whichever server looks first, at its start or
//! at a heartbeat. So another server's live match is never closed, a crashed server's
//! matches are closed within about a minute even if it never comes back, and a server cut
//! off for longer than that finds its matches closed but reopens them with its next write.
//!
//! The `postgres` client blocks on a small tokio runtime inside each connection, which
//! panics on an async worker: connections are made on a plain thread ([`off_runtime`]),
//! used on the writer thread and the blocking pool, and dropped off any runtime. No TLS
//! (`NoTls`): the database is meant to sit on the fleet's own network or socket.

use std::time::Duration;

use ::postgres::{Client, Config, NoTls};

use crate::store::backend::{
    self, Backend, LeaderOrder, Listed, Played, PlayerStats, Retention, StoreError, Stored,
    StoredCheckpoint, Unfinished,
};

mod convert;
mod names;
mod parties;
mod policies;
mod schema;
mod url;
mod write;

use convert::{big, db, describe, listed, stats};
use schema::Statements;
pub use schema::{SCHEMA_VERSION, migrate};
pub use url::parse;
use write::{Change, apply, evict};

/// How long a writer may be silent before its running matches are closed: six heartbeats,
/// so a slow commit or a short network cut never closes a live match.
pub const STALE_AFTER: Duration = Duration::from_secs(60);

/// A writer's hold on its running matches lasts this long after its last heartbeat, then
/// another server may take them (`adopt`); the holder stops them [`LEASE_MARGIN`] sooner
/// (`store::Lease`), so at most one server runs a match at any moment. It beats every
/// [`BEAT_EVERY`], a few times within its lease.
pub const LEASE: Duration = Duration::from_secs(10);
pub const LEASE_MARGIN: Duration = Duration::from_secs(3);
pub const BEAT_EVERY: Duration = Duration::from_secs(2);

/// The longest pause between the writer's tries to reach a database that went away.
const RETRY_AT_MOST: Duration = Duration::from_secs(5);

/// Whether `e` may have cost the connection: a closed socket, an I/O error, or the server's
/// FATAL (a terminated backend). The client may not know yet that its connection is gone
/// (it reads the socket only during a request), so the caller connects again.
fn lost(e: &::postgres::Error) -> bool {
    e.is_closed()
        || e.as_db_error()
            .is_none_or(|d| matches!(d.severity(), "FATAL" | "PANIC"))
}

/// Runs `f` where the client may block: on this thread when it is off any tokio runtime,
/// else on a plain thread of its own.
pub fn off_runtime<T: Send>(f: impl FnOnce() -> T + Send) -> Result<T, StoreError> {
    if tokio::runtime::Handle::try_current().is_err() {
        return Ok(f());
    }
    std::thread::scope(|s| {
        let handle = std::thread::Builder::new()
            .name("store-connect".into())
            .spawn_scoped(s, f)
            .map_err(|e| StoreError::Database(format!("no thread to connect on: {e}")))?;
        Ok(handle
            .join()
            .unwrap_or_else(|p| std::panic::resume_unwind(p)))
    })
}

/// A connection and its statements.
struct Conn {
    client: Client,
    st: Statements,
}

/// The PostgreSQL [`Backend`]: a connection, made again when the database drops it.
pub struct Postgres {
    config: Config,
    target: String,
    conn: Option<Conn>,
    retention: Retention,
    /// This process's writer id; none on a connection for reads.
    writer: Option<String>,
    /// The fence this writer holds each match it took from another at (`adopt`); one it
    /// began is held at 0. A write with a fence the match no longer has is refused.
    fences: std::collections::HashMap<String, i64>,
}

/// Why a batch was not committed.
enum Failure {
    /// Nothing of it was: it may be tried again.
    Undone(StoreError),
    /// The commit itself failed: it may or may not have landed.
    Unknown(StoreError),
}

impl Postgres {
    /// The writer's connection: checks `url`, connects, migrates the schema and registers a
    /// new writer id. Blocking; off any async worker ([`off_runtime`]).
    pub fn open(url: &str, retention: Retention) -> Result<Postgres, StoreError> {
        Postgres::connect(url, retention, Some(crate::access::random_id(8)))
    }

    /// A connection for reads.
    pub fn reader(url: &str, retention: Retention) -> Result<Postgres, StoreError> {
        Postgres::connect(url, retention, None)
    }

    fn connect(
        url: &str,
        retention: Retention,
        writer: Option<String>,
    ) -> Result<Postgres, StoreError> {
        let (config, target) = parse(url)?;
        let mut db = Postgres {
            config,
            target,
            conn: None,
            retention,
            writer,
            fences: Default::default(),
        };
        db.conn()?;
        Ok(db)
    }

    /// This writer's id (what its matches carry in `matches.writer`).
    pub fn writer_id(&self) -> Option<&str> {
        self.writer.as_deref()
    }

    /// Where the database is (no password).
    pub fn target(&self) -> &str {
        &self.target
    }

    /// The open connection, or a new one (migrated, with its statements, and the writer's
    /// heartbeat) when there is none or the database dropped it.
    fn conn(&mut self) -> Result<&mut Conn, StoreError> {
        let conn = match self.conn.take() {
            Some(c) if !c.client.is_closed() => c,
            _ => {
                let connect = |e: ::postgres::Error| StoreError::Connect {
                    target: self.target.clone(),
                    message: describe(&e),
                };
                let mut client = self.config.connect(NoTls).map_err(connect)?;
                migrate(&mut client)?;
                let st = Statements::prepare(&mut client).map_err(db)?;
                if let Some(writer) = &self.writer {
                    client.execute(&st.beat, &[writer]).map_err(db)?;
                }
                Conn { client, st }
            }
        };
        Ok(self.conn.insert(conn))
    }

    /// Waits until the database answers, trying again with a growing pause (at most
    /// [`RETRY_AT_MOST`]). Only the writer waits: its queue fills,
    /// [`Store::send`](super::Store::send) refuses, and the matches keep their inputs for a
    /// later append instead of losing them in a batch that could not be stored. Errors
    /// other than not reaching the database (a newer schema) are answered at once.
    fn connected(&mut self) -> Result<(), StoreError> {
        let mut pause = Duration::from_millis(100);
        let mut waited = false;
        loop {
            match self.conn() {
                Ok(_) => {
                    if waited {
                        tracing::info!("history: {} answers again", self.target);
                    }
                    return Ok(());
                }
                Err(e @ StoreError::Connect { .. }) => {
                    if !waited {
                        tracing::warn!("history: {e}; the writes wait until it answers");
                        waited = true;
                    }
                    std::thread::sleep(pause);
                    pause = (pause * 2).min(RETRY_AT_MOST);
                }
                Err(e) => return Err(e),
            }
        }
    }

    /// Runs a read, once more on a new connection when the database had dropped the old
    /// one (a restarted database answers the next request, not the one after).
    fn read<T>(
        &mut self,
        f: impl Fn(&mut Client, &Statements) -> Result<T, ::postgres::Error>,
    ) -> Result<T, StoreError> {
        let conn = self.conn()?;
        match f(&mut conn.client, &conn.st) {
            Ok(v) => Ok(v),
            Err(e) if lost(&e) => {
                tracing::warn!("history: {}; connecting again", describe(&e));
                self.conn = None;
                let conn = self.conn()?;
                f(&mut conn.client, &conn.st).map_err(db)
            }
            Err(e) => Err(db(e)),
        }
    }

    /// Matches still running whose writer has been silent for [`STALE_AFTER`] become
    /// incomplete, ending at their last stored tick; writers gone that long are forgotten.
    /// Answers how many matches.
    pub fn close_interrupted(&mut self) -> Result<usize, StoreError> {
        let me = self.writer.clone().unwrap_or_default();
        let stale = STALE_AFTER.as_secs_f64();
        self.read(|c, st| {
            let closed = c.execute(&st.close_silent, &[&me, &stale])?;
            c.execute(&st.forget_writers, &[&stale])?;
            Ok(closed as usize)
        })
    }

    /// Commits `changes` in one transaction.
    fn commit(&mut self, changes: &[Change<'_>], now: i64) -> Result<(), Failure> {
        let Some(writer) = self.writer.clone() else {
            return Err(Failure::Undone(StoreError::Database(
                "a connection for reads does not write".into(),
            )));
        };
        let retention = self.retention;
        self.conn().map_err(Failure::Undone)?;
        let Some(Conn { client, st }) = self.conn.as_mut() else {
            return Err(Failure::Undone(StoreError::Closed));
        };
        let mut tx = client.transaction().map_err(|e| Failure::Undone(db(e)))?;
        // Writing is a sign of life too: another server's sweep that forgot this writer (it
        // was silent, with nothing running) must not close the match it is starting now.
        tx.execute(&st.beat, &[&writer])
            .map_err(|e| Failure::Undone(db(e)))?;
        let mut finished = false;
        for change in changes {
            // A refused change costs only itself; a failed statement ends the transaction.
            match apply(&mut tx, st, &writer, &self.fences, change, now) {
                Ok(Ok(())) => {}
                Ok(Err(refused)) => tracing::warn!("history: {refused}"),
                Err(e) => return Err(Failure::Undone(db(e))),
            }
            finished |= matches!(change, Change::Finish { .. });
        }
        if finished && let Err(e) = evict(&mut tx, st, retention) {
            tracing::warn!("history: eviction put off: {}", describe(&e));
        }
        tx.commit().map_err(|e| Failure::Unknown(db(e)))?;
        for change in changes {
            match change {
                Change::Finish { id, .. } | Change::Lost { id } => {
                    self.fences.remove(*id);
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// Takes the running matches whose holder's lease ran out ([`LEASE`]) or that were
    /// handed to this writer and are not among `running`, at most `room` of them, and
    /// answers their ids: this writer holds them now, at their new fences.
    pub fn adopt(&mut self, room: usize, running: &[String]) -> Result<Vec<String>, StoreError> {
        let Some(me) = self.writer.clone() else {
            return Ok(Vec::new());
        };
        if room == 0 {
            return Ok(Vec::new());
        }
        let lease = LEASE.as_secs_f64();
        let room = big(room as u64);
        let taken = self.read(|c, st| {
            c.query(&st.adopt, &[&me, &lease, &room, &running])?
                .iter()
                .map(|r| Ok((r.try_get::<_, String>(0)?, r.try_get::<_, i64>(1)?)))
                .collect::<Result<Vec<_>, ::postgres::Error>>()
        })?;
        let mut ids = Vec::with_capacity(taken.len());
        for (id, fence) in taken {
            self.fences.insert(id.clone(), fence);
            ids.push(id);
        }
        Ok(ids)
    }

    /// Hands every match this writer holds to writer `to`: answers their ids.
    pub fn hand_over(&mut self, to: &str) -> Result<Vec<String>, StoreError> {
        let Some(me) = self.writer.clone() else {
            return Ok(Vec::new());
        };
        let ids = self.read(|c, st| {
            c.query(&st.hand_over, &[&me, &to])?
                .iter()
                .map(|r| r.try_get::<_, String>(0))
                .collect::<Result<Vec<_>, ::postgres::Error>>()
        })?;
        for id in &ids {
            self.fences.remove(id);
        }
        Ok(ids)
    }
}

impl Drop for Postgres {
    fn drop(&mut self) {
        // Closing a client blocks on its runtime, which panics on an async worker.
        if let Some(conn) = self.conn.take()
            && tokio::runtime::Handle::try_current().is_ok()
        {
            let _ = std::thread::Builder::new()
                .name("store-close".into())
                .spawn(move || drop(conn));
        }
    }
}

impl Backend for Postgres {
    fn beat_every(&self) -> Duration {
        BEAT_EVERY
    }

    fn lease(&self) -> Option<Duration> {
        self.writer.as_ref().map(|_| LEASE - LEASE_MARGIN)
    }

    fn adopt(&mut self, room: usize, running: &[String]) -> Result<Vec<String>, StoreError> {
        Postgres::adopt(self, room, running)
    }

    fn hand_over(&mut self, to: &str) -> Result<Vec<String>, StoreError> {
        Postgres::hand_over(self, to)
    }

    fn writer_id(&self) -> Option<String> {
        self.writer.clone()
    }

    fn write(&mut self, batch: &[backend::Write]) -> Result<(), StoreError> {
        let now = backend::unix_ms(std::time::SystemTime::now());
        let mut changes = Vec::with_capacity(batch.len());
        for change in batch.iter().filter_map(Change::of) {
            match change {
                Ok(c) => changes.push(c),
                Err(e) => tracing::warn!("history: {e}"),
            }
        }
        if changes.is_empty() {
            return Ok(());
        }
        self.connected()?;
        match self.commit(&changes, now) {
            Ok(()) => Ok(()),
            Err(Failure::Unknown(e)) => Err(e),
            Err(Failure::Undone(e)) => {
                // Nothing landed: each change alone, so one that fails costs only itself (as a
                // failed statement does in SQLite), on a new connection (the failure may have
                // cost the old one without the client knowing yet).
                tracing::warn!("history: {e}; storing the batch's writes one by one");
                self.conn = None;
                self.connected()?;
                for change in &changes {
                    if let Err(Failure::Undone(e) | Failure::Unknown(e)) =
                        self.commit(std::slice::from_ref(change), now)
                    {
                        tracing::warn!("history: {e}");
                    }
                }
                Ok(())
            }
        }
    }

    fn heartbeat(&mut self) -> Result<(), StoreError> {
        if let Some(writer) = self.writer.clone() {
            self.read(|c, st| c.execute(&st.beat, &[&writer]))?;
        }
        let closed = self.close_interrupted()?;
        if closed > 0 {
            tracing::warn!(
                closed,
                "matches of servers silent for {STALE_AFTER:?} are kept as incomplete"
            );
        }
        Ok(())
    }

    fn database_bytes(&mut self) -> Result<Option<u64>, StoreError> {
        self.read(|c, _| {
            let row = c.query_one("SELECT pg_database_size(current_database())", &[])?;
            Ok(Some(row.try_get::<_, i64>(0)?.max(0) as u64))
        })
    }

    fn list(
        &mut self,
        limit: usize,
        before: Option<&str>,
        without_prefix: Option<&str>,
    ) -> Result<Vec<Listed>, StoreError> {
        let limit = big(limit as u64);
        self.read(|c, st| {
            c.query(&st.list, &[&before, &limit, &without_prefix])?
                .iter()
                .map(listed)
                .collect()
        })
    }

    fn load_unfinished(&mut self, id: &str) -> Result<Option<Unfinished>, StoreError> {
        self.read(|c, st| {
            let Some(r) = c.query_opt(&st.load_running, &[&id])? else {
                return Ok(None);
            };
            let mut checkpoints = Vec::new();
            for row in c.query(&st.load_checkpoints, &[&id])? {
                checkpoints.push(StoredCheckpoint {
                    tick: row.try_get::<_, i64>(0)?.max(0) as u64,
                    applied: row.try_get::<_, i64>(1)?.max(0) as u64,
                    state: row.try_get(2)?,
                });
            }
            Ok(Some(Unfinished {
                stored: Stored {
                    listed: listed(&r)?,
                    settings: r.try_get(9)?,
                    map_document: r.try_get(10)?,
                    chunks: r.try_get(11)?,
                },
                live: r.try_get(12)?,
                checkpoints,
            }))
        })
    }

    fn input_chunks(
        &mut self,
        id: &str,
        from: usize,
        count: usize,
    ) -> Result<Vec<Vec<u8>>, StoreError> {
        let (from, count) = (from as i64, count as i64);
        self.read(|c, st| {
            c.query(&st.input_chunks, &[&id, &count, &from])?
                .iter()
                .map(|r| r.try_get(0))
                .collect()
        })
    }

    fn load(&mut self, id: &str) -> Result<Option<Stored>, StoreError> {
        self.read(|c, st| {
            let Some(r) = c.query_opt(&st.load, &[&id])? else {
                return Ok(None);
            };
            Ok(Some(Stored {
                listed: listed(&r)?,
                settings: r.try_get(9)?,
                map_document: r.try_get(10)?,
                chunks: r.try_get(11)?,
            }))
        })
    }

    fn claim(
        &mut self,
        claim: &backend::NameClaim,
        limits: backend::ClaimLimits,
    ) -> Result<backend::ClaimOutcome, StoreError> {
        self.read(|c, _| names::claim(c, claim, limits))
    }

    fn release(&mut self, key: &str, token: &str) -> Result<backend::ReleaseOutcome, StoreError> {
        self.read(|c, _| names::release(c, key, token))
    }

    fn claimed(&mut self, key: &str) -> Result<Option<backend::NameClaim>, StoreError> {
        self.read(|c, _| names::claimed(c, key))
    }

    fn keep_policy(&mut self, policy: &backend::KeptPolicy) -> Result<bool, StoreError> {
        self.read(|c, _| policies::keep(c, policy))
    }

    fn drop_policy(&mut self, name: &str) -> Result<(), StoreError> {
        self.read(|c, _| policies::drop(c, name))
    }

    fn kept_policies(&mut self) -> Result<Vec<backend::KeptPolicy>, StoreError> {
        self.read(|c, _| policies::kept(c, None))
    }

    fn kept_policy(&mut self, name: &str) -> Result<Option<backend::KeptPolicy>, StoreError> {
        self.read(|c, _| Ok(policies::kept(c, Some(name))?.pop()))
    }

    fn keep_party(&mut self, party: &backend::KeptParty) -> Result<(), StoreError> {
        self.read(|c, _| parties::keep(c, party))
    }

    fn drop_party(&mut self, code: &str) -> Result<(), StoreError> {
        self.read(|c, _| parties::drop(c, code))
    }

    fn kept_parties(&mut self) -> Result<Vec<backend::KeptParty>, StoreError> {
        self.read(|c, _| parties::kept(c))
    }

    fn player(&mut self, name: &str) -> Result<Option<PlayerStats>, StoreError> {
        self.read(|c, st| {
            c.query_opt(&st.player, &[&name])?
                .as_ref()
                .map(stats)
                .transpose()
        })
    }

    fn played(&mut self, name: &str, limit: usize) -> Result<Vec<Played>, StoreError> {
        let limit = big(limit as u64);
        self.read(|c, st| {
            c.query(&st.played, &[&name, &limit])?
                .iter()
                .map(|r| {
                    Ok(Played {
                        listed: listed(r)?,
                        rating_before: r.try_get(9)?,
                        rating_after: r.try_get(10)?,
                    })
                })
                .collect()
        })
    }

    fn leaders(
        &mut self,
        order: LeaderOrder,
        limit: usize,
    ) -> Result<Vec<PlayerStats>, StoreError> {
        let limit = big(limit as u64);
        let i = match order {
            LeaderOrder::Wins => 0,
            LeaderOrder::Tags => 1,
            LeaderOrder::Survival => 2,
            LeaderOrder::Matches => 3,
            LeaderOrder::Rating => 4,
        };
        self.read(|c, st| {
            c.query(&st.leaders[i], &[&limit])?
                .iter()
                .map(stats)
                .collect()
        })
    }

    fn totals(&mut self) -> Result<(u64, u64), StoreError> {
        self.read(|c, st| {
            let r = c.query_one(&st.totals, &[])?;
            Ok((
                r.try_get::<_, i64>(0)?.max(0) as u64,
                r.try_get::<_, i64>(1)?.max(0) as u64,
            ))
        })
    }
}
