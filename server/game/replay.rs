//! Replays: a finished match rebuilt from its map, settings, seed and recorded inputs
//! (`game::record`), at any tick.
//!
//! The core is deterministic, so re-simulating the inputs gives back the match bit for bit:
//! the state and belief a replay shows at tick N are what the live endpoints showed. To reach
//! any tick quickly, the re-simulation keeps copies of the world (keyframes) at regular
//! ticks as it passes them; a later seek starts from the nearest one before it. At most
//! [`MAX_KEYFRAMES`] are kept, so a long match gets them farther apart rather than more.
//!
//! Re-simulating is real work (a whole match, the first time): callers run it off the async
//! workers.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::SystemTime;

use lasertag_core::sim::arena::Arena;
use lasertag_core::world::{MatchConfig, MatchStatus, SetupError, World, WorldInput};

use crate::protocol::MatchMeta;

/// Keyframes kept per replay: about 300 KB each for an office match, so at most tens of MB.
pub const MAX_KEYFRAMES: u64 = 120;
/// The closest keyframes may be (ticks): a seek then re-simulates at most this many.
pub const MIN_KEYFRAME_SPACING: u64 = 50;

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
    arena: Arc<Arena>,
    config: MatchConfig,
    inputs: Arc<[(u64, WorldInput)]>,
    spacing: u64,
    /// Worlds at multiples of `spacing`, in tick order (the start is always first).
    keyframes: Mutex<Vec<World>>,
}

/// Why a tick of a replay could not be shown.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReplayError {
    #[error("tick: {asked} is past the match's last tick, {last}")]
    PastTheEnd { asked: u64, last: u64 },
    #[error("the match could not be set up again: {0}")]
    Setup(#[from] SetupError),
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
        Replay {
            meta,
            last_tick,
            winner: world.winner,
            players,
            started_at,
            ended_at: SystemTime::now(),
            reason,
            arena,
            config,
            inputs: inputs.into(),
            spacing: MIN_KEYFRAME_SPACING.max(last_tick.div_ceil(MAX_KEYFRAMES)),
            keyframes: Mutex::new(Vec::new()),
        }
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
        let mut keyframes = self.keyframes.lock().unwrap_or_else(|e| e.into_inner());
        if keyframes.is_empty() {
            keyframes.push(World::new(self.arena.clone(), self.config.clone())?);
        }
        let mut world = keyframes
            .iter()
            .rev()
            .find(|w| w.tick <= tick)
            .cloned()
            .unwrap_or_else(|| keyframes[0].clone());
        let mut next = self.inputs.partition_point(|(t, _)| *t < world.tick);
        // A keyframe holds the world before the inputs of its tick.
        loop {
            while let Some((t, input)) = self.inputs.get(next)
                && *t == world.tick
            {
                let _ = world.apply(input);
                next += 1;
            }
            if world.tick >= tick || world.status == MatchStatus::Finished {
                break;
            }
            world.step();
            if world.tick % self.spacing == 0
                && keyframes.last().is_some_and(|k| k.tick < world.tick)
            {
                keyframes.push(world.clone());
            }
        }
        Ok(world)
    }
}

/// A replay played forward one tick at a time (the replay WebSocket): each tick costs one
/// step, where [`Replay::world_at`] would start again from a keyframe.
#[derive(Debug, Clone)]
pub struct Cursor {
    world: World,
    /// The first input not applied yet.
    next: usize,
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
        let next = self.inputs.partition_point(|(t, _)| *t <= world.tick);
        Ok(Cursor { world, next })
    }

    /// Moves `cursor` one tick on; false (and nothing changes) at the match's last tick.
    pub fn advance(&self, cursor: &mut Cursor) -> bool {
        let world = &mut cursor.world;
        if world.tick >= self.last_tick || world.status == MatchStatus::Finished {
            return false;
        }
        world.step();
        while let Some((t, input)) = self.inputs.get(cursor.next)
            && *t <= world.tick
        {
            if *t == world.tick {
                let _ = world.apply(input);
            }
            cursor.next += 1;
        }
        true
    }
}

/// Finished matches kept for replay by default.
pub const HISTORY_CAPACITY: usize = 1000;
/// Replays whose keyframes are kept (the most recently opened): the rest are re-simulated
/// when opened again, so memory stays bounded whatever people open.
const OPEN_REPLAYS: usize = 4;

/// The finished matches a server keeps for replay, newest last, at most `capacity`.
#[derive(Debug)]
pub struct History {
    replays: Mutex<VecDeque<Arc<Replay>>>,
    capacity: usize,
    opened: Mutex<VecDeque<Arc<Replay>>>,
}

impl Default for History {
    fn default() -> Self {
        History::new(HISTORY_CAPACITY)
    }
}

impl History {
    pub fn new(capacity: usize) -> History {
        History {
            replays: Mutex::new(VecDeque::new()),
            capacity,
            opened: Mutex::new(VecDeque::new()),
        }
    }

    /// Notes that `replay` is being watched: it keeps its keyframes, and the replay opened
    /// longest ago past [`OPEN_REPLAYS`] drops its own.
    pub fn opened(&self, replay: &Arc<Replay>) {
        let mut o = self.opened.lock().unwrap_or_else(|e| e.into_inner());
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

    /// Keeps `replay`, forgetting the oldest past the capacity.
    pub fn keep(&self, replay: Replay) {
        let mut r = self.replays.lock().unwrap_or_else(|e| e.into_inner());
        r.push_back(Arc::new(replay));
        while r.len() > self.capacity {
            r.pop_front();
        }
    }

    pub fn get(&self, id: &str) -> Option<Arc<Replay>> {
        let r = self.replays.lock().unwrap_or_else(|e| e.into_inner());
        r.iter().find(|x| x.meta.id == id).cloned()
    }

    /// Newest first: at most `limit`, those older than `before` when given.
    pub fn list(&self, limit: usize, before: Option<&str>) -> Vec<Arc<Replay>> {
        let r = self.replays.lock().unwrap_or_else(|e| e.into_inner());
        let newest_first = r.iter().rev();
        let start = before
            .and_then(|b| r.iter().rev().position(|x| x.meta.id == b).map(|i| i + 1))
            .unwrap_or(0);
        newest_first.skip(start).take(limit).cloned().collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::maps::MapStore;
    use crate::protocol::Clock;
    use lasertag_core::world::{ControlKind, HumanInput};

    /// A two-minute office match with a person's keys changing now and then.
    fn recorded() -> Replay {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let maps = MapStore::load_dir(&root.join("maps")).expect("shipped maps");
        let arena = maps.get("office").expect("office").arena.clone();
        let config = MatchConfig {
            opponent_control: ControlKind::Human,
            seed: 3,
            ..MatchConfig::default()
        };
        let mut world = World::new(arena.clone(), config.clone()).expect("world");
        let mut inputs = Vec::new();
        for t in 0..400u64 {
            if t.is_multiple_of(37) {
                let input = WorldInput::Keys {
                    slot: 0,
                    input: HumanInput {
                        forward: if t.is_multiple_of(74) { 1.0 } else { -0.5 },
                        turn: 0.3,
                        ..HumanInput::default()
                    },
                };
                world.apply(&input).expect("keys");
                inputs.push((world.tick, input));
            }
            world.step();
        }
        let meta = MatchMeta {
            id: "m".into(),
            map: "office".into(),
            clock: Clock::Manual,
            players: 0,
            spectators: 0,
            free_slots: 0,
            bots_joinable: false,
            spectator_delay_ticks: 0,
        };
        Replay::of(&world, meta, arena, config, inputs, SystemTime::now())
    }

    #[test]
    fn a_cursor_played_forward_meets_every_seek() {
        let replay = recorded();
        let mut cursor = replay.cursor(100).expect("cursor");
        let mut steps = 0;
        while replay.advance(&mut cursor) {
            steps += 1;
            let tick = cursor.world().tick;
            if tick.is_multiple_of(23) || tick == replay.last_tick {
                let seek = replay.world_at(tick).expect("seek");
                assert_eq!(seek.digest(), cursor.world().digest(), "tick {tick}");
            }
        }
        assert_eq!(steps, replay.last_tick - 100);
        assert!(!replay.advance(&mut cursor));
    }
}
