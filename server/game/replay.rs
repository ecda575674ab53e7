//! Replays: a finished match rebuilt from its map, settings, seed and recorded inputs
//! (`game::record`), at any tick.
//!
//! The core is deterministic, so re-simulating the inputs gives back the match bit for bit:
//! the state and belief a replay shows at tick N are what the live endpoints showed. To reach
//! any tick quickly, the re-simulation keeps copies of the world (keyframes) at regular
//! ticks as it passes them; a later seek starts from the nearest one before it. At most
//! [`MAX_KEYFRAMES`] are kept, and no more than fit in [`KEYFRAME_BYTES`] (each priced as a
//! copy of the world, `admission::world_copy`), so a long match or a big world gets them
//! farther apart rather than more; a world too big for the budget keeps none (every seek
//! re-simulates from the start, on the replays' bounded pool).
//!
//! Re-simulating is real work (a whole match, the first time): callers run it off the async
//! workers.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::SystemTime;

use lasertag_core::sim::arena::Arena;
use lasertag_core::world::{MatchConfig, SetupError, Side, World, WorldInput};

use crate::game::admission::{self, world_copy};
use crate::game::view::MatchMeta;
use crate::store::codec::StoredSettings;
use crate::store::{Listed, Store, StoreError, Write};

mod inputs;

pub use inputs::InputsError;

use inputs::{Inputs, Position};

/// Keyframes kept per replay: about 300 KB each for an office match, so at most tens of MB.
pub const MAX_KEYFRAMES: u64 = 120;
/// The closest keyframes may be (ticks): a seek then re-simulates at most this many.
pub const MIN_KEYFRAME_SPACING: u64 = 50;
/// Bytes one replay's keyframes may take; [`OPEN_REPLAYS`] keep theirs at once.
pub const KEYFRAME_BYTES: u64 = 64_000_000;

/// Ticks between keyframes of a match of `last_tick` ticks whose world copies take `bytes`
/// each, or `None` when not even one fits in the budget.
fn keyframe_spacing(last_tick: u64, bytes: u64) -> Option<u64> {
    let fit = (KEYFRAME_BYTES / bytes.max(1)).min(MAX_KEYFRAMES);
    // The start is a keyframe too.
    let between = fit.checked_sub(1).filter(|n| *n > 0)?;
    Some(MIN_KEYFRAME_SPACING.max(last_tick.div_ceil(between)))
}

/// A finished match, replayable.
#[derive(Debug)]
pub struct Replay {
    pub meta: MatchMeta,
    /// The last tick of the match.
    pub last_tick: u64,
    pub winner: Option<lasertag_core::world::Side>,
    /// Names of the people who played, in the order they joined.
    pub players: Vec<String>,
    /// Wall-clock times the match was set up and ended.
    pub started_at: SystemTime,
    pub ended_at: SystemTime,
    /// Why it ended (from its `finished` event).
    pub reason: Option<lasertag_core::world::FinishReason>,
    /// False for a match the server was killed in the middle of: it replays up to the last
    /// tick the store had.
    pub complete: bool,
    arena: Arc<Arena>,
    config: MatchConfig,
    inputs: Inputs,
    /// Ticks between keyframes; `None`: the world is too big to keep copies of.
    spacing: Option<u64>,
    /// Worlds at multiples of `spacing`, in tick order (the start is always first).
    keyframes: Mutex<Vec<World>>,
}

/// A stored match that cannot be replayed (a damaged or foreign database).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("the stored match cannot be replayed: {0}")]
pub struct LoadError(String);

/// Why a tick of a replay could not be shown.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReplayError {
    #[error("tick: {asked} is past the match's last tick, {last}")]
    PastTheEnd { asked: u64, last: u64 },
    #[error("the match could not be set up again: {0}")]
    Setup(#[from] SetupError),
    #[error(transparent)]
    Inputs(#[from] InputsError),
}

impl Replay {
    /// The replay of a match that ended at `last`: `world` as it ended.
    pub fn of(
        world: &World,
        meta: MatchMeta,
        arena: Arc<Arena>,
        config: MatchConfig,
        inputs: Vec<(u64, WorldInput)>,
        started_at: SystemTime,
    ) -> Replay {
        let last_tick = world.tick;
        let reason = world.events().iter().rev().find_map(|e| match e.kind {
            lasertag_core::world::EventKind::Finished { reason, .. } => Some(reason),
            _ => None,
        });
        let players = world
            .events()
            .iter()
            .filter_map(|e| match &e.kind {
                lasertag_core::world::EventKind::PlayerJoined { name, .. } => Some(name.clone()),
                _ => None,
            })
            .fold(Vec::new(), |mut names, n| {
                if !names.contains(&n) {
                    names.push(n);
                }
                names
            });
        let spacing = keyframe_spacing(last_tick, world_copy(&arena.def, &config));
        Replay {
            meta,
            last_tick,
            winner: world.winner,
            players,
            started_at,
            ended_at: SystemTime::now(),
            reason,
            complete: true,
            arena,
            config,
            inputs: Inputs::memory(inputs),
            spacing,
            keyframes: Mutex::new(Vec::new()),
        }
    }

    /// Bytes of its recorded inputs as it holds them (all, or their index).
    fn inputs_bytes(&self) -> u64 {
        self.inputs.bytes()
    }

    /// A replay read back from `store`: its inputs stay there when they are many.
    pub fn from_stored(
        store: &Arc<Store>,
        stored: crate::store::Stored,
    ) -> Result<Replay, LoadError> {
        let settings: StoredSettings = serde_json::from_str(&stored.settings)
            .map_err(|e| LoadError(format!("settings: {e}")))?;
        let config = settings.config().map_err(|e| LoadError(e.to_string()))?;
        let def =
            crate::maps::parse(&stored.map_document).map_err(|e| LoadError(format!("map: {e}")))?;
        let arena = Arc::new(Arena::new(def));
        let inputs = Inputs::of_chunks(Some(store), &stored.listed.id, &stored.chunks)
            .map_err(|e| LoadError(e.to_string()))?;
        let l = stored.listed;
        let at =
            |ms: i64| SystemTime::UNIX_EPOCH + std::time::Duration::from_millis(ms.max(0) as u64);
        Ok(Replay {
            meta: MatchMeta::stored(l.id, l.map, &settings),
            last_tick: l.ticks,
            winner: match l.winner.as_deref() {
                Some("robots") => Some(Side::Robots),
                Some("opponents") => Some(Side::Opponents),
                _ => None,
            },
            players: l.players,
            started_at: at(l.started_at_ms),
            ended_at: at(l.ended_at_ms.unwrap_or(l.started_at_ms)),
            reason: l.reason.as_deref().and_then(crate::store::codec::reason_of),
            complete: l.complete,
            spacing: keyframe_spacing(l.ticks, world_copy(&arena.def, &config)),
            arena,
            config,
            inputs,
            keyframes: Mutex::new(Vec::new()),
        })
    }

    /// Bytes of one copy of this replay's world: a cursor, or a keyframe (the arena shared).
    pub fn world_bytes(&self) -> u64 {
        world_copy(&self.arena.def, &self.config)
    }

    /// The match's settings and map.
    pub fn config(&self) -> &MatchConfig {
        &self.config
    }

    /// The world at the end of tick `tick` (after every input applied at it). Blocking: up
    /// to a whole match of re-simulation the first time, at most a keyframe spacing after.
    pub fn world_at(&self, tick: u64) -> Result<World, ReplayError> {
        if tick > self.last_tick {
            return Err(ReplayError::PastTheEnd {
                asked: tick,
                last: self.last_tick,
            });
        }
        let mut world = self.nearest(tick)?;
        let mut at = self.inputs.walk_from(world.tick);
        // A keyframe holds the world before the inputs of its tick.
        loop {
            self.inputs.apply_at(&mut at, world.tick, |input| {
                let _ = world.apply(input);
            })?;
            if world.tick >= tick || !world.step() {
                break;
            }
            if self
                .spacing
                .is_some_and(|every| world.tick.is_multiple_of(every))
            {
                self.keep_keyframe(&world);
            }
        }
        Ok(world)
    }

    /// A copy of the latest keyframe at or before `tick` (the start when there is none).
    /// The lock is held only for the copy: seeks and [`Replay::prepare`] re-simulate side
    /// by side.
    fn nearest(&self, tick: u64) -> Result<World, ReplayError> {
        if self.spacing.is_none() {
            return Ok(World::new(self.arena.clone(), self.config.clone())?);
        }
        let mut keyframes = self.keyframes.lock().unwrap_or_else(|e| e.into_inner());
        if keyframes.is_empty() {
            keyframes.push(World::new(self.arena.clone(), self.config.clone())?);
        }
        let i = keyframes.partition_point(|w| w.tick <= tick).max(1);
        Ok(keyframes[i - 1].clone())
    }

    /// Keeps a copy of `world` as a keyframe, in tick order, unless one is there already.
    fn keep_keyframe(&self, world: &World) {
        let mut keyframes = self.keyframes.lock().unwrap_or_else(|e| e.into_inner());
        if let Err(i) = keyframes.binary_search_by_key(&world.tick, |w| w.tick) {
            keyframes.insert(i, world.clone());
        }
    }

    /// Re-simulates the whole match once, keeping every keyframe: after it any seek is at
    /// most a spacing of re-simulation. Blocking (a whole match); the history runs it in
    /// the background when a replay is first opened.
    pub fn prepare(&self) {
        let _ = self.world_at(self.last_tick);
    }
}

/// A replay played forward one tick at a time (the replay WebSocket): each tick costs one
/// step, where [`Replay::world_at`] would start again from a keyframe.
#[derive(Debug, Clone)]
pub struct Cursor {
    world: World,
    /// The inputs after its tick.
    inputs: Position,
}

impl Cursor {
    /// The world at the cursor's tick (after every input applied at it).
    pub fn world(&self) -> &World {
        &self.world
    }
}

impl Replay {
    /// A cursor at the end of `tick` (as [`Replay::world_at`] gives it).
    pub fn cursor(&self, tick: u64) -> Result<Cursor, ReplayError> {
        let world = self.world_at(tick)?;
        let inputs = self.inputs.walk_from(world.tick + 1);
        Ok(Cursor { world, inputs })
    }

    /// Moves `cursor` one tick on; false (and nothing changes) at the match's last tick.
    pub fn advance(&self, cursor: &mut Cursor) -> Result<bool, ReplayError> {
        let world = &mut cursor.world;
        if world.tick >= self.last_tick || !world.step() {
            return Ok(false);
        }
        let tick = world.tick;
        self.inputs.apply_at(&mut cursor.inputs, tick, |input| {
            let _ = world.apply(input);
        })?;
        Ok(true)
    }
}

/// Finished matches kept in memory for replay by a server without a store.
pub const HISTORY_CAPACITY: usize = 1000;
/// Finished matches kept in memory beside a store (the rest are loaded when opened).
const CACHED_WITH_STORE: usize = 32;
/// Bytes the finished matches kept in memory may take, their arenas priced as admission
/// prices a map: a stream of matches on large inline maps would otherwise keep 32 (or, with
/// no store, a thousand) arenas that nobody pays for once their matches end. The newest is
/// kept whatever its size; the store, when there is one, still has the others.
pub const CACHED_BYTES: u64 = 128 << 20;
/// Replays whose keyframes are kept (the most recently opened): the rest are re-simulated
/// when opened again, so memory stays bounded whatever people open.
pub const OPEN_REPLAYS: usize = 4;

/// The finished matches a server keeps for replay: the newest in memory, all of them in the
/// store when it has one.
#[derive(Debug)]
pub struct History {
    replays: Mutex<VecDeque<Arc<Replay>>>,
    capacity: usize,
    opened: Mutex<VecDeque<Arc<Replay>>>,
    store: Option<Arc<Store>>,
}

impl Default for History {
    fn default() -> Self {
        History::new(HISTORY_CAPACITY)
    }
}

impl History {
    /// A history in memory only, of at most `capacity` matches.
    pub fn new(capacity: usize) -> History {
        History {
            replays: Mutex::new(VecDeque::new()),
            capacity,
            opened: Mutex::new(VecDeque::new()),
            store: None,
        }
    }

    /// A history kept in `store`.
    pub fn with_store(store: Store) -> History {
        History {
            store: Some(Arc::new(store)),
            ..History::new(CACHED_WITH_STORE)
        }
    }

    pub fn store(&self) -> Option<&Store> {
        self.store.as_deref()
    }

    /// Hands `w` to the store (nothing to do without one); gives it back when the store's
    /// queue is full, for the caller to try again later.
    pub fn record(&self, w: Write) -> Result<(), Box<Write>> {
        match &self.store {
            Some(store) => store.send(w),
            None => Ok(()),
        }
    }

    /// Notes that `replay` is being watched: it keeps its keyframes, and the replay opened
    /// longest ago past [`OPEN_REPLAYS`] drops its own.
    pub fn opened(&self, replay: &Arc<Replay>) {
        let mut o = self.opened.lock().unwrap_or_else(|e| e.into_inner());
        if !o.iter().any(|r| Arc::ptr_eq(r, replay)) {
            prepare_in_background(replay.clone());
        }
        o.retain(|r| !Arc::ptr_eq(r, replay));
        o.push_back(replay.clone());
        while o.len() > OPEN_REPLAYS {
            if let Some(old) = o.pop_front() {
                old.keyframes
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .clear();
            }
        }
    }

    /// Keeps `replay` in memory, forgetting the oldest past the capacity or past
    /// [`CACHED_BYTES`] (the store, if any, has it from the match's own writes).
    pub fn keep(&self, replay: Replay) -> Arc<Replay> {
        let replay = Arc::new(replay);
        let mut r = self.replays.lock().unwrap_or_else(|e| e.into_inner());
        r.retain(|x| x.meta.id != replay.meta.id);
        r.push_back(replay.clone());
        while r.len() > self.capacity || (r.len() > 1 && kept_bytes(&r) > CACHED_BYTES) {
            r.pop_front();
        }
        replay
    }

    /// The replay `id` if it is in memory.
    pub fn get(&self, id: &str) -> Option<Arc<Replay>> {
        let r = self.replays.lock().unwrap_or_else(|e| e.into_inner());
        r.iter().find(|x| x.meta.id == id).cloned()
    }

    /// The replay `id`, from memory or else the store. Blocking (a database read and the
    /// map's arena to build).
    pub fn load(&self, id: &str) -> Result<Option<Arc<Replay>>, HistoryError> {
        if let Some(r) = self.get(id) {
            return Ok(Some(r));
        }
        let Some(store) = &self.store else {
            return Ok(None);
        };
        let Some(stored) = store.read(|b| b.load(id))? else {
            return Ok(None);
        };
        Ok(Some(self.keep(Replay::from_stored(store, stored)?)))
    }

    /// Ended matches, the last to end first: at most `limit`, those that ended before
    /// `before` when given, and none whose id begins with `without_prefix`. Blocking with a
    /// store. (Kept in memory, replays are kept as they end: their order is the end's.)
    pub fn list(
        &self,
        limit: usize,
        before: Option<&str>,
        without_prefix: Option<&str>,
    ) -> Result<Vec<Listed>, HistoryError> {
        if let Some(store) = &self.store {
            return Ok(store.read(|b| b.list(limit, before, without_prefix))?);
        }
        let r = self.replays.lock().unwrap_or_else(|e| e.into_inner());
        let start = before
            .and_then(|b| r.iter().rev().position(|x| x.meta.id == b).map(|i| i + 1))
            .unwrap_or(0);
        Ok(r.iter()
            .rev()
            .skip(start)
            .filter(|x| without_prefix.is_none_or(|p| !x.meta.id.starts_with(p)))
            .take(limit)
            .map(|x| x.listed())
            .collect())
    }
}

/// What keeping `replays` in memory costs: their recorded inputs, and each arena once
/// (priced as admission prices a map; the replays of a stored map share one). Keyframes
/// have their own budget.
fn kept_bytes(replays: &VecDeque<Arc<Replay>>) -> u64 {
    let mut arenas = std::collections::HashSet::new();
    replays
        .iter()
        .map(|r| {
            let arena = if arenas.insert(Arc::as_ptr(&r.arena)) {
                admission::map(&r.arena.def).memory
            } else {
                0
            };
            arena + r.inputs_bytes()
        })
        .sum()
}

/// Fills in `replay`'s keyframes on a background thread (`background`), so that the seeks after its first
/// opening are short wherever they land. One at a time: a replay opened while another is
/// being prepared re-simulates only as its seeks go (still correct, slower at first).
fn prepare_in_background(replay: Arc<Replay>) {
    static PREPARING: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
    use std::sync::atomic::Ordering;
    // Only in a server (a runtime is running): a program that opens replays by itself
    // seeks them as it goes.
    if tokio::runtime::Handle::try_current().is_err() {
        return;
    }
    if PREPARING.swap(true, Ordering::AcqRel) {
        return;
    }
    let spawned = crate::game::background::spawn("replay-prepare", move || {
        replay.prepare();
        PREPARING.store(false, Ordering::Release);
    });
    if spawned.is_err() {
        PREPARING.store(false, Ordering::Release);
    }
}

/// Why the history could not answer.
#[derive(Debug, Clone, thiserror::Error)]
pub enum HistoryError {
    #[error(transparent)]
    Store(#[from] StoreError),
    #[error(transparent)]
    Load(#[from] LoadError),
}

impl Replay {
    /// This replay as lists show it.
    pub fn listed(&self) -> Listed {
        Listed {
            id: self.meta.id.clone(),
            map: self.meta.map.clone(),
            started_at_ms: crate::store::unix_ms(self.started_at),
            ended_at_ms: Some(crate::store::unix_ms(self.ended_at)),
            ticks: self.last_tick,
            winner: self.winner.map(|w| match w {
                Side::Robots => "robots".to_string(),
                Side::Opponents => "opponents".to_string(),
            }),
            reason: self.reason.map(|r| r.name().to_string()),
            complete: self.complete,
            players: self.players.clone(),
        }
    }
}

#[cfg(test)]
mod tests;
