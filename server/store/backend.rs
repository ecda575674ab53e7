//! What the store and its databases share: the changes a match hands the writer
//! ([`Write`]), what reads answer, what can go wrong, and [`Backend`], the operations a
//! database must offer.

use std::sync::Arc;
use std::time::{Duration, SystemTime};

use lasertag_core::difficulty::Difficulty;
use lasertag_core::sim::arena::Arena;
use lasertag_core::world::{World, WorldInput};

use crate::store::codec::{self, StoredLive, StoredSettings};
use crate::store::results::PlayerResult;

/// How often the writer thread calls [`Backend::heartbeat`], busy or idle.
pub const HEARTBEAT: Duration = Duration::from_secs(10);

/// What went wrong with the store.
#[derive(Debug, Clone, thiserror::Error)]
pub enum StoreError {
    #[error("data directory {path}: {message}")]
    Io { path: String, message: String },
    #[error("database: {0}")]
    Database(String),
    /// The database cannot be written now (a full disk, an I/O error): the same writes may
    /// go through later.
    #[error("the database cannot be written now: {0}")]
    Unwritable(String),
    #[error("--database: {0}")]
    DatabaseUrl(String),
    #[error("cannot connect to PostgreSQL at {target}: {message}")]
    Connect { target: String, message: String },
    #[error("a stored match is already called {0}")]
    Duplicate(String),
    #[error("the database's schema is version {found}, newer than this server's {known}")]
    NewerSchema { found: usize, known: usize },
    #[error("no stored match {0}")]
    Unknown(String),
    /// The match's checkpoint came out larger than its price: it resumes from an older one.
    #[error("match {0}'s checkpoint is larger than priced: not stored")]
    CheckpointTooLarge(String),
    #[error(transparent)]
    Codec(#[from] std::sync::Arc<codec::CodecError>),
    #[error("the store is closed")]
    Closed,
}

impl From<codec::CodecError> for StoreError {
    fn from(e: codec::CodecError) -> Self {
        StoreError::Codec(Arc::new(e))
    }
}

/// How much the store keeps: the oldest ended matches go first past either limit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Retention {
    pub max_matches: u64,
    pub max_bytes: u64,
}

/// One change to the history, from a match task.
#[derive(Debug)]
pub enum Write {
    /// A match started.
    Begin {
        id: String,
        arena: Arc<Arena>,
        settings: Box<StoredSettings>,
        /// Its owner and seats, to resume it.
        live: Box<StoredLive>,
        started_at: SystemTime,
    },
    /// Inputs applied since the last append, and the tick the match has reached.
    Append {
        id: String,
        inputs: Vec<(u64, WorldInput)>,
        /// Everyone who has played it so far, when that changed.
        names: Option<Vec<String>>,
        /// Its owner and seats now, when the seats changed.
        live: Option<Box<StoredLive>>,
        tick: u64,
    },
    /// A copy of a running match's state (`World::checkpoint`, encoded by the writer),
    /// taken between ticks after `applied` of its inputs, every one of which went before it
    /// in an append: a resume starts there instead of at tick 0. The store keeps it and
    /// those from `keep_from` on, and stores none past `max_bytes` (its price).
    Checkpoint {
        id: String,
        tick: u64,
        applied: u64,
        keep_from: u64,
        world: Box<World>,
        max_bytes: u64,
    },
    /// The match ended (after its last append).
    Finish { id: String, ended: Ended },
    /// A running match that could not be resumed ends where its record stops, with reason
    /// `lost` (an incomplete replay).
    Lost { id: String },
    /// Answers once everything before it is committed.
    Flush(std::sync::mpsc::Sender<()>),
    /// Takes at most `room` running matches whose holder's lease ran out, or that were
    /// handed to this writer and are not among `running` (`Backend::adopt`); answers their
    /// ids, after everything before it is committed.
    Adopt {
        room: usize,
        running: Vec<String>,
        reply: std::sync::mpsc::Sender<Vec<String>>,
    },
    /// Hands every match this writer holds to writer `to` (`Backend::hand_over`), after
    /// everything before it is committed; answers their ids.
    HandOver {
        to: String,
        reply: std::sync::mpsc::Sender<Vec<String>>,
    },
    /// Claims a name (`Backend::claim`): claims go through the one writer, so two claims of
    /// look-alikes cannot both win.
    Claim {
        claim: NameClaim,
        limits: ClaimLimits,
        reply: std::sync::mpsc::Sender<Result<ClaimOutcome, StoreError>>,
    },
    /// Gives a claim up (`Backend::release`).
    Release {
        key: String,
        token: String,
        reply: std::sync::mpsc::Sender<Result<ReleaseOutcome, StoreError>>,
    },
    /// Keeps an uploaded policy (`Backend::keep_policy`); answers false when the store
    /// keeps one by that name already (another server of a fleet took it).
    KeepPolicy {
        policy: Box<KeptPolicy>,
        reply: std::sync::mpsc::Sender<Result<bool, StoreError>>,
    },
    /// Keeps a party's room as it is now, replacing what was kept of it
    /// (`Backend::keep_party`).
    KeepParty(Box<KeptParty>),
    /// Forgets a party that lapsed (`Backend::drop_party`).
    DropParty { code: String },
    /// Forgets an uploaded policy (`Backend::drop_policy`).
    DropPolicy { name: String },
}

/// A party's room as the store keeps it, so that it outlives its server: its code, and the
/// room as one document (`store::codec::party`: members with their tokens as hashes, sides,
/// the host's settings).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeptParty {
    pub code: String,
    pub doc: String,
}

/// An uploaded policy as the store keeps it (`POST /api/policies`), so that it outlives the
/// server that took it: the model's bytes as uploaded, checked again when a server loads it.
#[derive(Clone, PartialEq)]
pub struct KeptPolicy {
    pub name: String,
    /// The ONNX file.
    pub model: Vec<u8>,
    /// The owner token's hash (hex): a copied database lets nobody remove it.
    pub token: String,
    /// The client that uploaded it, as an address: its quota follows it.
    pub client: String,
    /// Ticks between its decisions.
    pub every: u64,
    /// Unix milliseconds.
    pub added_at: i64,
}

impl std::fmt::Debug for KeptPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("KeptPolicy")
            .field("name", &self.name)
            .field("model_bytes", &self.model.len())
            .field("client", &self.client)
            .field("every", &self.every)
            .field("added_at", &self.added_at)
            .finish_non_exhaustive()
    }
}

/// A name somebody keeps (`POST /api/names`).
#[derive(Debug, Clone, PartialEq)]
pub struct NameClaim {
    pub name: String,
    /// `names::Name::key`: look-alikes share it, and it is the claim's key.
    pub key: String,
    /// The name token's hash (hex): a copied database lets nobody play under the name.
    pub token: String,
    /// The client that claimed it, as an address: its claims count against it.
    pub client: String,
    /// Unix milliseconds.
    pub claimed_at: i64,
}

/// How many names one client, and everyone, may keep.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClaimLimits {
    pub per_client: u64,
    pub total: u64,
}

/// What became of a claim.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ClaimOutcome {
    Claimed,
    /// This name, or a look-alike of it, is kept already (the name kept).
    Taken(String),
    /// The client keeps as many names as it may.
    ClientFull,
    /// The server keeps as many names as it may.
    ServerFull,
}

/// What became of giving a claim up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReleaseOutcome {
    Released,
    NotClaimed,
    WrongToken,
}

impl Write {
    /// Whether it asks the writer for something rather than storing a change.
    pub fn is_control(&self) -> bool {
        matches!(
            self,
            Write::Flush(_)
                | Write::Adopt { .. }
                | Write::HandOver { .. }
                | Write::Claim { .. }
                | Write::Release { .. }
                | Write::KeepPolicy { .. }
                | Write::DropPolicy { .. }
                | Write::KeepParty(_)
                | Write::DropParty { .. }
        )
    }
}

/// How a match ended.
#[derive(Debug, Clone)]
pub struct Ended {
    /// Unix milliseconds.
    pub ended_at: i64,
    pub ticks: u64,
    pub winner: Option<&'static str>,
    pub reason: Option<&'static str>,
    pub players: Vec<PlayerResult>,
    /// The preset its players are rated against, when it counts for ratings (a rated match
    /// that ended by the rules: all tagged or out of time).
    pub rated: Option<Difficulty>,
}

/// An ended match as lists show it.
#[derive(Debug, Clone, PartialEq)]
pub struct Listed {
    pub id: String,
    pub map: String,
    pub started_at_ms: i64,
    pub ended_at_ms: Option<i64>,
    pub ticks: u64,
    pub winner: Option<String>,
    pub reason: Option<String>,
    /// False for a match the server was killed in the middle of.
    pub complete: bool,
    pub players: Vec<String>,
}

/// An ended match, whole: enough to replay it.
#[derive(Debug, Clone)]
pub struct Stored {
    pub listed: Listed,
    /// JSON of [`StoredSettings`].
    pub settings: String,
    /// The map as a map file (docs/map-format.md).
    pub map_document: String,
    /// Deflated chunks of inputs ([`codec::decode_inputs`]), in order.
    pub chunks: Vec<Vec<u8>>,
}

/// A match a server left running: its record, whole, and what resumes it.
#[derive(Debug, Clone)]
pub struct Unfinished {
    /// Its listing says how far the record goes (`ticks`) and `complete: false`.
    pub stored: Stored,
    /// JSON of [`StoredLive`]; none for a record written before the store kept it.
    pub live: Option<String>,
    /// Its checkpoints, newest first.
    pub checkpoints: Vec<StoredCheckpoint>,
}

/// A running match's state at `tick`, after `applied` of its inputs ([`Write::Checkpoint`]).
#[derive(Debug, Clone, PartialEq)]
pub struct StoredCheckpoint {
    pub tick: u64,
    pub applied: u64,
    /// [`codec::encode_checkpoint`](codec::encode_checkpoint)'s bytes.
    pub state: Vec<u8>,
}

/// What both databases store of a [`Write::Checkpoint`]: its deflated bytes, or the refusal
/// when they came out larger than its price.
pub fn checkpoint_state(id: &str, world: &World, max_bytes: u64) -> Result<Vec<u8>, StoreError> {
    codec::encode_checkpoint(world, max_bytes)
        .ok_or_else(|| StoreError::CheckpointTooLarge(id.to_owned()))
}

/// A player name's totals over the stored matches.
#[derive(Debug, Clone, PartialEq)]
pub struct PlayerStats {
    pub name: String,
    pub matches: u64,
    pub wins: u64,
    /// Robots this name tagged.
    pub tags: u64,
    pub longest_survival_ticks: u64,
    /// Their rating, once they have played a rated match.
    pub rating: Option<Rated>,
}

/// A name's rating as reads show it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rated {
    pub rating: f64,
    pub deviation: f64,
    /// Rated matches it is made of.
    pub matches: u64,
}

/// An ended match a name played, with what it did to their rating (rated matches only).
#[derive(Debug, Clone, PartialEq)]
pub struct Played {
    pub listed: Listed,
    pub rating_before: Option<f64>,
    pub rating_after: Option<f64>,
}

/// What a leaderboard ranks by.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LeaderOrder {
    Wins,
    Tags,
    Survival,
    Matches,
    /// Rated names only, by [`Rating::conservative`](super::ratings::Rating::conservative).
    Rating,
}

/// The operations a database must offer the store.
pub trait Backend: Send {
    /// How often the writer thread calls [`Backend::heartbeat`].
    fn beat_every(&self) -> Duration {
        HEARTBEAT
    }
    /// How long this writer may go on running its matches after the start of a heartbeat
    /// (or a write) the database took: `None` when nobody else could take them (a database
    /// of one server's own).
    fn lease(&self) -> Option<Duration> {
        None
    }
    /// See [`Write::Adopt`]; a database of one server's own has nothing to adopt.
    fn adopt(&mut self, _room: usize, _running: &[String]) -> Result<Vec<String>, StoreError> {
        Ok(Vec::new())
    }
    /// See [`Write::HandOver`].
    fn hand_over(&mut self, _to: &str) -> Result<Vec<String>, StoreError> {
        Ok(Vec::new())
    }
    /// This writer's id, when the database knows writers apart.
    fn writer_id(&self) -> Option<String> {
        None
    }
    /// Called by the writer thread every [`HEARTBEAT`]: a shared database hears that this
    /// writer is alive, and closes the matches of writers it has not heard from.
    fn heartbeat(&mut self) -> Result<(), StoreError> {
        Ok(())
    }
    /// The database's size on disk, when the backend knows it (a server database).
    fn database_bytes(&mut self) -> Result<Option<u64>, StoreError> {
        Ok(None)
    }
    /// Commits `batch` in one transaction.
    fn write(&mut self, batch: &[Write]) -> Result<(), StoreError>;
    /// Ended matches, the last to end first (ties: the last to start first): at most
    /// `limit`, those that ended before `before` when given (all, for an id it does not
    /// hold), and none whose id begins with `without_prefix` when given.
    fn list(
        &mut self,
        limit: usize,
        before: Option<&str>,
        without_prefix: Option<&str>,
    ) -> Result<Vec<Listed>, StoreError>;
    fn load(&mut self, id: &str) -> Result<Option<Stored>, StoreError>;
    /// At most `count` of the ended match `id`'s chunks of inputs, from the `from`th (in
    /// order, as [`Stored::chunks`] has them): a replay reads a long record in windows.
    /// Fewer than asked at the end, none for a match no longer stored.
    fn input_chunks(
        &mut self,
        id: &str,
        from: usize,
        count: usize,
    ) -> Result<Vec<Vec<u8>>, StoreError>;
    /// The ids of the matches this server may resume: left running by a process that has
    /// stopped, oldest first.
    fn unfinished(&mut self) -> Result<Vec<String>, StoreError> {
        Ok(Vec::new())
    }
    /// The record of the unfinished match `id`.
    fn load_unfinished(&mut self, _id: &str) -> Result<Option<Unfinished>, StoreError> {
        Ok(None)
    }
    /// See [`Write::Claim`]: in one transaction, refused when the key is kept or a limit
    /// is reached.
    fn claim(&mut self, claim: &NameClaim, limits: ClaimLimits)
    -> Result<ClaimOutcome, StoreError>;
    /// Gives up the claim on `key` if its token's hash is `token`; the name's rating goes
    /// with it (whoever keeps the name next starts afresh).
    fn release(&mut self, key: &str, token: &str) -> Result<ReleaseOutcome, StoreError>;
    /// The claim on `key`, if any.
    fn claimed(&mut self, key: &str) -> Result<Option<NameClaim>, StoreError>;
    /// See [`Write::KeepPolicy`]: false, keeping nothing, when the name is kept already.
    fn keep_policy(&mut self, policy: &KeptPolicy) -> Result<bool, StoreError>;
    fn drop_policy(&mut self, name: &str) -> Result<(), StoreError>;
    /// Every kept policy, oldest first.
    fn kept_policies(&mut self) -> Result<Vec<KeptPolicy>, StoreError>;
    /// The kept policy `name`, if any.
    fn kept_policy(&mut self, name: &str) -> Result<Option<KeptPolicy>, StoreError>;
    /// Keeps `party`, replacing what was kept under its code.
    fn keep_party(&mut self, party: &KeptParty) -> Result<(), StoreError>;
    fn drop_party(&mut self, code: &str) -> Result<(), StoreError>;
    /// Every kept party.
    fn kept_parties(&mut self) -> Result<Vec<KeptParty>, StoreError>;
    fn player(&mut self, name: &str) -> Result<Option<PlayerStats>, StoreError>;
    fn played(&mut self, name: &str, limit: usize) -> Result<Vec<Played>, StoreError>;
    fn leaders(&mut self, order: LeaderOrder, limit: usize)
    -> Result<Vec<PlayerStats>, StoreError>;
    /// (ended matches, their bytes).
    fn totals(&mut self) -> Result<(u64, u64), StoreError>;
}

/// A map document's key: equal documents are stored once.
pub(crate) fn map_key(document: &str) -> String {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    document.hash(&mut h);
    format!("{:016x}-{}", h.finish(), document.len())
}

/// Unix milliseconds of `t`.
pub fn unix_ms(t: SystemTime) -> i64 {
    t.duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}
