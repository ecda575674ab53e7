//! A replay's recorded inputs: in memory when they are few, else read from the store in
//! windows as a re-simulation reaches them.
//!
//! Commands from outside may fill a match's record up to its bound on disk (tens of MB of
//! waypoints); a replay that held them all would hold that much for as long as it is cached
//! or watched. So past [`MEMORY_BYTES`] a replay keeps only an index (each stored chunk's
//! ticks and size), and whoever walks the inputs (a seek, the replay socket's cursor) holds
//! one window of about [`WINDOW_BYTES`] at a time. A chunk is one append of the match's
//! record (about a second of play), and the chunks of an ended match never change, so a
//! chunk's position is a stable address.

use std::collections::VecDeque;
use std::sync::Arc;

use lasertag_core::world::WorldInput;

use crate::game::record::order_bytes;
use crate::store::codec::decode_inputs;
use crate::store::{Store, StoreError};

/// Inputs a replay keeps in memory (bytes, the waypoints counted): past it they stay in the
/// store. The bound a live match keeps of its own (`record::MEMORY_ORDER_BYTES`).
pub const MEMORY_BYTES: u64 = crate::game::record::MEMORY_ORDER_BYTES as u64;
/// Bytes of inputs one walk over a stored record holds at a time (at least one chunk).
pub const WINDOW_BYTES: u64 = 1 << 20;

/// Why the inputs could not be read.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InputsError {
    #[error("reading the recorded inputs: {0}")]
    Store(String),
    #[error("a chunk of recorded inputs is damaged: {0}")]
    Damaged(String),
    #[error("the match's record left the store while it was replayed")]
    Gone,
}

impl From<StoreError> for InputsError {
    fn from(e: StoreError) -> Self {
        InputsError::Store(e.to_string())
    }
}

/// What an input takes in memory, its waypoints included.
fn bytes_of(input: &WorldInput) -> u64 {
    order_bytes(input).unwrap_or(std::mem::size_of::<(u64, WorldInput)>()) as u64
}

/// One stored chunk, as the index knows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Chunk {
    /// The tick of its last input.
    last_tick: u64,
    /// What its inputs take in memory.
    bytes: u64,
}

/// A replay's inputs.
#[derive(Debug, Clone)]
pub struct Inputs(Source);

/// Where they are.
#[derive(Debug, Clone)]
enum Source {
    /// All of them, oldest first, and what they take (counted once: they never change, and
    /// the history's budget asks on every replay it keeps).
    Memory {
        all: Arc<[(u64, WorldInput)]>,
        bytes: u64,
    },
    /// In the store, chunk by chunk; only their index here.
    Stored {
        store: Arc<Store>,
        id: String,
        chunks: Vec<Chunk>,
    },
}

/// A walk's place in the inputs: the next one to look at, and (for a stored record) the
/// window read around it.
#[derive(Debug, Clone)]
pub struct Position {
    /// In memory, the next input; stored, the next chunk to read.
    next: usize,
    window: VecDeque<(u64, WorldInput)>,
}

impl Inputs {
    /// `inputs`, all in memory.
    pub fn memory(inputs: Vec<(u64, WorldInput)>) -> Inputs {
        let bytes = inputs.iter().map(|(_, i)| bytes_of(i)).sum();
        Inputs(Source::Memory {
            all: inputs.into(),
            bytes,
        })
    }

    /// The inputs of the stored match `id`, from its `chunks` as the store gave them: kept
    /// when they fit in [`MEMORY_BYTES`], else indexed (each chunk decoded once, then let go
    /// of) and read again in windows when walked.
    pub fn of_chunks(
        store: Option<&Arc<Store>>,
        id: &str,
        chunks: &[Vec<u8>],
    ) -> Result<Inputs, InputsError> {
        let mut kept = Vec::new();
        let mut kept_bytes = 0;
        let mut index = Vec::with_capacity(chunks.len());
        for chunk in chunks {
            let inputs = decode_inputs(chunk).map_err(|e| InputsError::Damaged(e.to_string()))?;
            let bytes = inputs.iter().map(|(_, i)| bytes_of(i)).sum::<u64>();
            let last_tick = inputs.last().map_or(0, |(t, _)| *t);
            index.push(Chunk { last_tick, bytes });
            kept_bytes += bytes;
            if kept_bytes <= MEMORY_BYTES || store.is_none() {
                kept.extend(inputs);
            } else {
                kept = Vec::new();
            }
        }
        // An empty chunk's last tick is its predecessor's: the index stays in tick order.
        let mut last = 0;
        for c in &mut index {
            c.last_tick = c.last_tick.max(last);
            last = c.last_tick;
        }
        match store {
            Some(store) if kept_bytes > MEMORY_BYTES => Ok(Inputs(Source::Stored {
                store: store.clone(),
                id: id.to_owned(),
                chunks: index,
            })),
            _ => Ok(Inputs::memory(kept)),
        }
    }

    /// Whether they stay in the store, read in windows.
    #[cfg(test)]
    pub fn stored(&self) -> bool {
        matches!(self.0, Source::Stored { .. })
    }

    /// What holding them costs: all of them in memory, or the index.
    pub fn bytes(&self) -> u64 {
        match &self.0 {
            Source::Memory { bytes, .. } => *bytes,
            Source::Stored { chunks, .. } => (chunks.len() * std::mem::size_of::<Chunk>()) as u64,
        }
    }

    /// A walk that starts at the first input applied at `tick` or later.
    pub fn walk_from(&self, tick: u64) -> Position {
        let next = match &self.0 {
            Source::Memory { all, .. } => all.partition_point(|(t, _)| *t < tick),
            Source::Stored { chunks, .. } => chunks.partition_point(|c| c.last_tick < tick),
        };
        Position {
            next,
            window: VecDeque::new(),
        }
    }

    /// Hands `apply` each input applied at `tick`, in order, passing over any before it;
    /// the walk then stands at the first input after `tick`.
    pub fn apply_at(
        &self,
        at: &mut Position,
        tick: u64,
        mut apply: impl FnMut(&WorldInput),
    ) -> Result<(), InputsError> {
        match &self.0 {
            Source::Memory { all, .. } => {
                while let Some((t, input)) = all.get(at.next)
                    && *t <= tick
                {
                    if *t == tick {
                        apply(input);
                    }
                    at.next += 1;
                }
            }
            Source::Stored { .. } => loop {
                if at.window.is_empty() && !self.read_window(at)? {
                    return Ok(());
                }
                match at.window.front() {
                    Some((t, _)) if *t > tick => return Ok(()),
                    Some(_) => {
                        if let Some((t, input)) = at.window.pop_front()
                            && t == tick
                        {
                            apply(&input);
                        }
                    }
                    None => {}
                }
            },
        }
        Ok(())
    }

    /// Reads the chunks from `at.next` on, up to [`WINDOW_BYTES`] of inputs (at least one
    /// chunk), into `at.window`; false when no chunk is left.
    fn read_window(&self, at: &mut Position) -> Result<bool, InputsError> {
        let Source::Stored { store, id, chunks } = &self.0 else {
            return Ok(false);
        };
        let Some(rest) = chunks.get(at.next..).filter(|r| !r.is_empty()) else {
            return Ok(false);
        };
        let mut count = 0;
        let mut bytes = 0;
        for c in rest {
            if count > 0 && bytes + c.bytes > WINDOW_BYTES {
                break;
            }
            bytes += c.bytes;
            count += 1;
        }
        let read = store.read(|b| b.input_chunks(id, at.next, count))?;
        if read.len() < count {
            return Err(InputsError::Gone);
        }
        for chunk in &read {
            at.window
                .extend(decode_inputs(chunk).map_err(|e| InputsError::Damaged(e.to_string()))?);
        }
        at.next += count;
        Ok(true)
    }
}
