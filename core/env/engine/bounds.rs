//! The engine's bounds (each the server's, so both backends refuse alike) and its
//! refusals: what a caller gives is checked against these before anything is allocated.

use crate::sim::TICK_HZ;
use crate::world::SetupError;

/// Robots on a world's team: the server's bound on `robots` of `POST /api/matches`
/// (`server/protocol/bounds.rs`, whose tests keep these constants equal to its own).
pub const MAX_ROBOTS: usize = 8;
/// Opponents in a world: the server's bound on `opponents`.
pub const MAX_OPPONENTS: usize = 32;
/// Detection slots in a robot's vector: as many as a world may have opponents (a slot
/// past those would always be empty).
pub const MAX_DETECTIONS: usize = MAX_OPPONENTS;
/// A match's time limit in seconds is in (0, this]: the server's bound on `time_limit_s`.
pub const MAX_TIME_LIMIT_S: f64 = 86_400.0;
/// Ticks one step may advance: the server's bound on `ticks` of `act`.
pub const MAX_TICKS_PER_STEP: u64 = 100_000;
/// Steps an episode may be given (`max_steps`): the ticks of the longest match the server
/// starts. A step advances at least one tick, so no episode ever takes more.
pub const MAX_STEPS: u64 = MAX_TIME_LIMIT_S as u64 * TICK_HZ as u64;
/// Ticks one timing run (`time_parts`: steps × ticks per step) may advance: what one
/// request to the server may ([`MAX_TICKS_PER_STEP`]), so a call returns in seconds.
pub const MAX_TIMED_TICKS: u64 = MAX_TICKS_PER_STEP;
/// Robots over all the worlds of one engine (worlds × robots). A world of the default
/// match holds about 220 KB, one of 8 robots and 32 opponents about 530 KB, so the budget
/// keeps an engine under about 4 GB with every setting at its default; each world's own
/// size follows its settings (the tracker's particles, …), each within its declared range.
pub const MAX_AGENTS: usize = 16_384;
/// The largest start coordinate (and heading) given: the server's bound on coordinates of
/// a request (`server/schema.rs`).
pub const MAX_COORDINATE: f32 = 1e6;

/// Why the engine refused a call.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Refusal {
    /// An argument out of its range, or an array of the wrong shape (Python's `ValueError`).
    #[error("{field}: {message}")]
    Value { field: String, message: String },
    /// A world index past the vector's (Python's `IndexError`).
    #[error("world {world}: out of range 0..{worlds}")]
    NoWorld { world: usize, worlds: usize },
    /// Settings the map cannot start a match with (a given start in a wall, no room).
    #[error(transparent)]
    Setup(#[from] SetupError),
    /// A world's next episode, started by itself when the last one ended, could not be
    /// set up with its seed (random placement found no room for every agent). Python's
    /// `RuntimeError`: the call's arguments were fine, the settings leave too little room.
    #[error(
        "world {world}: its next episode (seed {seed}) could not start: {error}; random \
         placement found no room for every agent at least 1 m apart on this map (fewer \
         agents, a larger map, or placement \"spawns\")"
    )]
    Restart {
        world: usize,
        seed: u64,
        error: SetupError,
    },
}

/// A world whose next episode could not be set up ([`Refusal::Restart`] without its index,
/// which the vector adds).
#[derive(Debug, Clone, PartialEq)]
pub struct RestartFailed {
    pub seed: u64,
    pub error: SetupError,
}

impl RestartFailed {
    /// The refusal, naming world `world`.
    pub fn of(self, world: usize) -> Refusal {
        Refusal::Restart {
            world,
            seed: self.seed,
            error: self.error,
        }
    }
}

/// The refusal of `field`.
pub fn refuse(field: impl Into<String>, message: impl Into<String>) -> Refusal {
    Refusal::Value {
        field: field.into(),
        message: message.into(),
    }
}

/// `got` values where `want` are needed.
pub fn check_len(name: &str, got: usize, want: usize) -> Result<(), Refusal> {
    if got == want {
        Ok(())
    } else {
        Err(refuse(
            name,
            format!(
                "{got} values, the engine needs {want} (a C-contiguous array of the right shape)"
            ),
        ))
    }
}

/// An array of shape `got` where `want` is needed: the same number of values in another
/// shape (robots × 3 given as 3 × robots) is refused too, as it would be read wrongly.
pub fn check_shape(name: &str, got: &[usize], want: &[usize]) -> Result<(), Refusal> {
    if got == want {
        Ok(())
    } else {
        Err(refuse(
            name,
            format!("shape {got:?}, the engine needs {want:?}"),
        ))
    }
}

/// A timing run of `steps` steps of `ticks_per_step` ticks each: at least one step, and at
/// most [`MAX_TIMED_TICKS`] ticks in all.
pub fn check_timed(steps: u64, ticks_per_step: u64) -> Result<(), Refusal> {
    let most = MAX_TIMED_TICKS / ticks_per_step.max(1);
    if (1..=most).contains(&steps) {
        Ok(())
    } else {
        Err(refuse(
            "steps",
            format!(
                "{steps} must be in 1..={most} (at most {MAX_TIMED_TICKS} ticks in one call, \
                 as one step request to the server, at {ticks_per_step} a step)"
            ),
        ))
    }
}

/// A match's time limit of `seconds` in ticks, as the server rounds it, once the seconds
/// are finite and within (0, [`MAX_TIME_LIMIT_S`]].
pub fn time_limit_ticks(seconds: f64) -> Result<u64, Refusal> {
    if seconds > 0.0 && seconds <= MAX_TIME_LIMIT_S {
        Ok((seconds * TICK_HZ as f64).round().max(1.0) as u64)
    } else {
        Err(refuse(
            "time_limit_s",
            format!("{seconds} must be finite and in (0, {MAX_TIME_LIMIT_S}]"),
        ))
    }
}
