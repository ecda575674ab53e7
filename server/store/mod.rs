//! The history of matches on disk: every match's map, settings and inputs (enough to replay
//! it, `game::replay`), how it ended, and who played it; lists, loads and player statistics
//! read back.
//!
//! Writes never wait: a match task hands [`Write`]s to a bounded channel
//! ([`Store::send`], which refuses rather than blocks when the channel is full) and one
//! writer thread commits them in batches, a transaction a batch. Reads run on the caller's
//! thread (callers are off the async workers) through a connection of their own.
//!
//! The database sits behind [`Backend`], a narrow trait: SQLite ([`sqlite`]) is the default,
//! embedded and bundled; PostgreSQL ([`postgres`], `--database`) is the fleet's, one database
//! that every server writes its own matches to and reads everyone's from.

pub mod backend;
pub mod codec;
pub mod postgres;
pub mod ratings;
pub mod results;
pub mod sqlite;

pub use backend::{
    Backend, ClaimLimits, ClaimOutcome, Ended, HEARTBEAT, KeptParty, KeptPolicy, LeaderOrder,
    Listed, NameClaim, Played, PlayerStats, Rated, ReleaseOutcome, Retention, StoreError, Stored,
    StoredCheckpoint, Unfinished, Write, unix_ms,
};
pub use results::PlayerResult;

use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Writes the channel holds before [`Store::send`] refuses (a second of a thousand busy
/// matches).
const WRITE_QUEUE: usize = 4096;
/// Most writes committed in one transaction.
const BATCH: usize = 512;
/// The `serve` command's history flags.
#[derive(Debug, Clone, clap::Args)]
pub struct StoreArgs {
    /// Directory of the history database (`lasertag.db`), created if missing.
    #[arg(long, env = "LASERTAG_DATA", default_value = "data")]
    pub data_dir: PathBuf,
    /// A PostgreSQL database for the history instead of SQLite in `--data-dir`
    /// (`postgres://user[:password]@host[:port]/database`): every server pointed at it lists
    /// and replays every match. No TLS.
    #[arg(
        long,
        env = "LASERTAG_DATABASE",
        value_name = "URL",
        hide_env_values = true
    )]
    pub database: Option<String>,
    /// Ended matches the history keeps; the oldest go first.
    #[arg(long, env = "LASERTAG_KEEP_MATCHES", default_value_t = 10_000,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub keep_matches: u64,
    /// Megabytes of recorded matches the history keeps; the oldest go first.
    #[arg(long, env = "LASERTAG_KEEP_MB", default_value_t = 1024,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub keep_mb: u64,
}

impl StoreArgs {
    pub fn retention(&self) -> Retention {
        Retention {
            max_matches: self.keep_matches,
            max_bytes: self.keep_mb.saturating_mul(1 << 20),
        }
    }
}

/// The history on disk: a writer thread and a connection for reads.
pub struct Store {
    writes: SyncSender<Write>,
    reader: Mutex<Box<dyn Backend>>,
    /// SQLite's directory (for [`Store::file_bytes`]); none for a server database.
    dir: Option<PathBuf>,
    /// See [`Store::resumes`]: SQLite's one server resumes its own; a fleet's shared
    /// database is another matter (`fleet`).
    resumes: bool,
    /// How long this server may run its matches (a shared database's lease).
    lease: Arc<Lease>,
    /// Whether other servers' matches may be taken from this store ([`Store::adopt`]).
    adopts: bool,
    /// This server's writer id in a shared database.
    writer_id: Option<String>,
}

impl std::fmt::Debug for Store {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Store")
            .field("dir", &self.dir)
            .finish_non_exhaustive()
    }
}

impl Store {
    /// The history the `serve` flags ask for: PostgreSQL with `--database`, else SQLite in
    /// `--data-dir`.
    pub fn from_args(args: &StoreArgs) -> Result<Store, StoreError> {
        match &args.database {
            Some(url) => Store::open_postgres(url, args.retention()),
            None => Store::open(&args.data_dir, args.retention()),
        }
    }

    /// Where [`Store::from_args`] keeps the history, for the log (no password).
    pub fn describe(args: &StoreArgs) -> String {
        match &args.database {
            Some(url) => match postgres::parse(url) {
                Ok((_, target)) => format!("PostgreSQL at {target}"),
                Err(e) => e.to_string(),
            },
            None => format!("SQLite in {}", args.data_dir.display()),
        }
    }

    /// Opens the history in the PostgreSQL database at `url`, migrating its schema. Matches
    /// left running by a writer the database has not heard from in
    /// [`postgres::STALE_AFTER`] are closed as incomplete; other servers' live ones are left
    /// alone.
    pub fn open_postgres(url: &str, retention: Retention) -> Result<Store, StoreError> {
        // The client blocks on a runtime of its own: never on an async worker.
        let (writer, reader, interrupted) = postgres::off_runtime(|| {
            let mut writer = postgres::Postgres::open(url, retention)?;
            let interrupted = writer.close_interrupted()?;
            let reader = postgres::Postgres::reader(url, retention)?;
            Ok::<_, StoreError>((writer, reader, interrupted))
        })??;
        tracing::info!(
            writer = writer.writer_id().unwrap_or_default(),
            database = writer.target(),
            "history in PostgreSQL"
        );
        if interrupted > 0 {
            tracing::warn!(
                interrupted,
                "matches left unfinished by servers gone silent are kept as incomplete"
            );
        }
        Ok(Store::with(Box::new(writer), Box::new(reader), None))
    }

    /// Opens the SQLite history in `dir` (created if missing). Matches a previous process
    /// left running stay as they are: the server resumes them (`game::resume`).
    pub fn open(dir: &Path, retention: Retention) -> Result<Store, StoreError> {
        let writer = sqlite::Sqlite::open(dir, retention)?;
        let reader = sqlite::Sqlite::reader(dir, retention)?;
        Ok(Store::with(
            Box::new(writer),
            Box::new(reader),
            Some(dir.to_path_buf()),
        ))
    }

    /// A store over any backend: `writer` for the writer thread, `reader` for reads; `dir`
    /// is where the database's files are, if it has files of its own.
    pub fn with(writer: Box<dyn Backend>, reader: Box<dyn Backend>, dir: Option<PathBuf>) -> Store {
        let (tx, rx) = std::sync::mpsc::sync_channel(WRITE_QUEUE);
        let lease = Arc::new(Lease::default());
        let adopts = writer.lease().is_some();
        let writer_id = writer.writer_id();
        let held = lease.clone();
        let spawned = std::thread::Builder::new()
            .name("store".into())
            .spawn(move || write_loop(writer, rx, held));
        if let Err(e) = spawned {
            // The channel's receiver is gone with the closure: every send says Closed.
            tracing::error!("no store writer thread: {e}");
        }
        Store {
            writes: tx,
            reader: Mutex::new(reader),
            resumes: dir.is_some(),
            dir,
            lease,
            adopts,
            writer_id,
        }
    }

    /// Whether matches left running in this store are resumed by the next server that opens
    /// it (`game::resume`).
    pub fn resumes(&self) -> bool {
        self.resumes
    }

    /// How long this server may run its matches (see [`Lease`]).
    pub fn lease(&self) -> &Arc<Lease> {
        &self.lease
    }

    /// Whether servers share this store, taking each other's matches when one stops
    /// ([`Store::adopt`], [`Store::hand_over`]).
    pub fn adopts(&self) -> bool {
        self.adopts
    }

    /// This server's writer id in a shared store.
    pub fn writer_id(&self) -> Option<&str> {
        self.writer_id.as_deref()
    }

    /// Takes at most `room` matches other servers can no longer run (their lease ran out)
    /// or that were handed to this one, and are not among `running`: answers their ids,
    /// which this server holds now (blocking, at most `timeout`).
    pub fn adopt(
        &self,
        room: usize,
        running: Vec<String>,
        timeout: Duration,
    ) -> Result<Vec<String>, StoreError> {
        let (reply, rx) = std::sync::mpsc::channel();
        self.writes
            .send(Write::Adopt {
                room,
                running,
                reply,
            })
            .map_err(|_| StoreError::Closed)?;
        rx.recv_timeout(timeout).map_err(|_| StoreError::Closed)
    }

    /// Hands every match this server holds to the server whose writer is `to`, after every
    /// write before (blocking, at most `timeout`): answers their ids.
    pub fn hand_over(&self, to: &str, timeout: Duration) -> Result<Vec<String>, StoreError> {
        let (reply, rx) = std::sync::mpsc::channel();
        self.writes
            .send(Write::HandOver {
                to: to.to_string(),
                reply,
            })
            .map_err(|_| StoreError::Closed)?;
        rx.recv_timeout(timeout).map_err(|_| StoreError::Closed)
    }

    /// Claims a name through the writer (blocking, at most `timeout`).
    pub fn claim(
        &self,
        claim: NameClaim,
        limits: ClaimLimits,
        timeout: Duration,
    ) -> Result<ClaimOutcome, StoreError> {
        let (reply, rx) = std::sync::mpsc::channel();
        self.writes
            .try_send(Write::Claim {
                claim,
                limits,
                reply,
            })
            .map_err(|_| StoreError::Closed)?;
        rx.recv_timeout(timeout).map_err(|_| StoreError::Closed)?
    }

    /// Gives up the claim on `key` if `token` (the hash of its token) is its (blocking, at
    /// most `timeout`).
    pub fn release(
        &self,
        key: String,
        token: String,
        timeout: Duration,
    ) -> Result<ReleaseOutcome, StoreError> {
        let (reply, rx) = std::sync::mpsc::channel();
        self.writes
            .try_send(Write::Release { key, token, reply })
            .map_err(|_| StoreError::Closed)?;
        rx.recv_timeout(timeout).map_err(|_| StoreError::Closed)?
    }

    /// Keeps `policy` (blocking, at most `timeout`): false when a policy by its name is kept
    /// already.
    pub fn keep_policy(&self, policy: KeptPolicy, timeout: Duration) -> Result<bool, StoreError> {
        let (reply, rx) = std::sync::mpsc::channel();
        self.writes
            .try_send(Write::KeepPolicy {
                policy: Box::new(policy),
                reply,
            })
            .map_err(|_| StoreError::Closed)?;
        rx.recv_timeout(timeout).map_err(|_| StoreError::Closed)?
    }

    /// Queues `w` for the writer; refuses (giving it back) when the queue is full.
    pub fn send(&self, w: Write) -> Result<(), Box<Write>> {
        self.writes.try_send(w).map_err(|e| match e {
            TrySendError::Full(w) | TrySendError::Disconnected(w) => Box::new(w),
        })
    }

    /// Waits (blocking, at most `timeout`) until everything sent so far is committed.
    pub fn flush(&self, timeout: Duration) -> Result<(), StoreError> {
        let (tx, rx) = std::sync::mpsc::channel();
        self.writes
            .send(Write::Flush(tx))
            .map_err(|_| StoreError::Closed)?;
        rx.recv_timeout(timeout).map_err(|_| StoreError::Closed)
    }

    /// The ids of the matches left running in the store, to resume (blocking).
    pub fn unfinished(&self) -> Result<Vec<String>, StoreError> {
        self.read(|b| b.unfinished())
    }

    /// The record of the unfinished match `id` (blocking).
    pub fn load_unfinished(&self, id: &str) -> Result<Option<Unfinished>, StoreError> {
        self.read(|b| b.load_unfinished(id))
    }

    /// Runs `f` on the read connection (blocking).
    pub fn read<T>(
        &self,
        f: impl FnOnce(&mut dyn Backend) -> Result<T, StoreError>,
    ) -> Result<T, StoreError> {
        let mut reader = self.reader.lock().unwrap_or_else(|e| e.into_inner());
        f(reader.as_mut())
    }

    /// The size of the database now (bytes): SQLite's files, or what a server database
    /// reports (0 when it cannot be asked).
    pub fn file_bytes(&self) -> u64 {
        match &self.dir {
            Some(dir) => ["lasertag.db", "lasertag.db-wal"]
                .iter()
                .filter_map(|f| std::fs::metadata(dir.join(f)).ok())
                .map(|m| m.len())
                .sum(),
            None => self
                .read(|b| b.database_bytes())
                .ok()
                .flatten()
                .unwrap_or(0),
        }
    }
}

fn write_loop(mut backend: Box<dyn Backend>, rx: Receiver<Write>, lease: Arc<Lease>) {
    let every = backend.beat_every();
    let hold = backend.lease();
    // The start of the last heartbeat due; a write the database took counts as one too (it
    // beats in the same transaction, `postgres`).
    let mut beat = Instant::now() - every;
    loop {
        if beat.elapsed() >= every {
            let started = Instant::now();
            beat = started;
            match backend.heartbeat() {
                Ok(()) => lease.renew(started, hold),
                Err(e) => tracing::warn!("history heartbeat: {e}"),
            }
        }
        // A busy writer beats too: the heartbeat is due by the clock, not by idleness.
        match rx.recv_timeout(every.saturating_sub(beat.elapsed())) {
            Ok(first) => {
                let mut batch = vec![first];
                while batch.len() < BATCH {
                    match rx.try_recv() {
                        Ok(w) => batch.push(w),
                        Err(_) => break,
                    }
                }
                // Changes in order; a request for the writer waits for the changes before it.
                let mut changes = Vec::new();
                for w in batch {
                    if !w.is_control() {
                        changes.push(w);
                        continue;
                    }
                    commit(backend.as_mut(), &mut changes, &lease, hold);
                    answer(backend.as_mut(), w);
                }
                commit(backend.as_mut(), &mut changes, &lease, hold);
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
}

/// How long the writer waits before it tries again a batch the database could not take
/// for want of room.
const UNWRITABLE_RETRY: Duration = Duration::from_secs(1);

/// Commits `changes` (and empties it); the database took them as a sign of life. A batch
/// the disk could not take (full, failing) is tried again until it goes in: meanwhile the
/// queue fills, [`Store::send`] refuses, and every match keeps the inputs it could not hand
/// over, so that the record never has a gap (a resumed match would not be the same match).
/// Live play goes on all the while; the log says so once a minute.
fn commit(
    backend: &mut dyn Backend,
    changes: &mut Vec<Write>,
    lease: &Lease,
    hold: Option<Duration>,
) {
    if changes.is_empty() {
        return;
    }
    let mut told: Option<Instant> = None;
    loop {
        let started = Instant::now();
        match backend.write(changes) {
            Ok(()) => {
                lease.renew(started, hold);
                if told.is_some() {
                    tracing::info!("the history is stored again");
                }
                break;
            }
            Err(e @ StoreError::Unwritable(_)) => {
                if told.is_none_or(|t| t.elapsed() >= Duration::from_secs(60)) {
                    tracing::error!(
                        "the history could not store {} writes: {e}; matches play on and keep their inputs until it can",
                        changes.len()
                    );
                    told = Some(Instant::now());
                }
                std::thread::sleep(UNWRITABLE_RETRY);
            }
            Err(e) => {
                tracing::error!("the history could not store {} writes: {e}", changes.len());
                break;
            }
        }
    }
    changes.clear();
}

/// Answers a request for the writer.
fn answer(backend: &mut dyn Backend, w: Write) {
    match w {
        Write::Flush(done) => {
            let _ = done.send(());
        }
        Write::Adopt {
            room,
            running,
            reply,
        } => {
            let ids = backend.adopt(room, &running).unwrap_or_else(|e| {
                tracing::warn!("history: adopting matches: {e}");
                Vec::new()
            });
            let _ = reply.send(ids);
        }
        Write::HandOver { to, reply } => {
            let ids = backend.hand_over(&to).unwrap_or_else(|e| {
                tracing::warn!("history: handing matches over: {e}");
                Vec::new()
            });
            let _ = reply.send(ids);
        }
        Write::Claim {
            claim,
            limits,
            reply,
        } => {
            let _ = reply.send(backend.claim(&claim, limits));
        }
        Write::Release { key, token, reply } => {
            let _ = reply.send(backend.release(&key, &token));
        }
        Write::KeepPolicy { policy, reply } => {
            let _ = reply.send(backend.keep_policy(&policy));
        }
        Write::DropPolicy { name } => {
            if let Err(e) = backend.drop_policy(&name) {
                tracing::error!(policy = name, "history: forgetting a policy: {e}");
            }
        }
        Write::KeepParty(party) => {
            if let Err(e) = backend.keep_party(&party) {
                tracing::error!(party = party.code, "history: keeping a party: {e}");
            }
        }
        Write::DropParty { code } => {
            if let Err(e) = backend.drop_party(&code) {
                tracing::error!(party = code, "history: forgetting a party: {e}");
            }
        }
        _ => {}
    }
}

/// How long this server may go on running its matches: until a while after the start of its
/// last heartbeat the database took, when other servers could take them
/// (`Backend::lease`); for ever with a database of its own. Match tasks ask before each
/// tick ([`Lease::holds`]): a server that was paused (`SIGSTOP`, a stalled VM) past its lease
/// stops its matches rather than run them beside the server that took them. A lease that
/// ran out stays out for the matches that held it: a heartbeat after it starts a new *term*,
/// which only matches started (or adopted) from then on hold.
#[derive(Debug)]
pub struct Lease {
    /// Whether the lease can run out at all.
    applies: std::sync::atomic::AtomicBool,
    /// Milliseconds after `epoch` until which it holds.
    until_ms: std::sync::atomic::AtomicU64,
    /// Bumped by a renewal after the lease ran out.
    term: std::sync::atomic::AtomicU64,
    epoch: Instant,
}

impl Default for Lease {
    fn default() -> Self {
        Lease {
            applies: std::sync::atomic::AtomicBool::new(false),
            until_ms: std::sync::atomic::AtomicU64::new(0),
            term: std::sync::atomic::AtomicU64::new(0),
            epoch: Instant::now(),
        }
    }
}

impl Lease {
    fn now_ms(&self) -> u64 {
        self.epoch.elapsed().as_millis() as u64
    }

    /// A heartbeat or write that started at `started` was taken: the lease holds `hold`
    /// after it (`None`: a lease that never runs out).
    fn renew(&self, started: Instant, hold: Option<Duration>) {
        use std::sync::atomic::Ordering;
        let Some(hold) = hold else { return };
        let until = (started + hold)
            .saturating_duration_since(self.epoch)
            .as_millis() as u64;
        if self.applies.load(Ordering::Acquire)
            && self.now_ms() >= self.until_ms.load(Ordering::Acquire)
        {
            // It ran out meanwhile: whatever held it then holds nothing now.
            self.term.fetch_add(1, Ordering::AcqRel);
        }
        self.until_ms.fetch_max(until, Ordering::Release);
        self.applies.store(true, Ordering::Release);
    }

    /// The term a match started now holds the lease in.
    pub fn term(&self) -> u64 {
        self.term.load(std::sync::atomic::Ordering::Acquire)
    }

    /// Whether a match that holds the lease in `term` may run now.
    pub fn holds(&self, term: u64) -> bool {
        use std::sync::atomic::Ordering;
        if !self.applies.load(Ordering::Acquire) {
            return true;
        }
        term == self.term() && self.now_ms() < self.until_ms.load(Ordering::Acquire)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lease_that_ran_out_stays_out_for_what_held_it() {
        let lease = Lease::default();
        assert!(lease.holds(0), "a store of one's own: always");
        let hold = Some(Duration::from_millis(50));
        lease.renew(Instant::now(), hold);
        let term = lease.term();
        assert!(lease.holds(term));
        std::thread::sleep(Duration::from_millis(80));
        assert!(!lease.holds(term), "past its hold");
        lease.renew(Instant::now(), hold);
        assert!(
            !lease.holds(term),
            "a renewal after it ran out starts a new term"
        );
        assert!(lease.holds(lease.term()));
        lease.renew(Instant::now(), None);
        assert!(lease.holds(lease.term()));
    }
}
