//! What a match task records so that the match can be replayed: every [`WorldInput`] it
//! applied, with the tick it was applied at (before that tick's step). Together with the
//! map, the settings and the seed that is the whole match.
//!
//! Keys are recorded only when they change what the world would do: a person's input
//! repeats every tick while the keys stay down, and the tick a view was drawn at matters
//! only with the trigger pulled.

use lasertag_core::world::{HumanInput, World, WorldInput};

/// The inputs of one match, in the order they were applied.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Recording {
    inputs: Vec<(u64, WorldInput)>,
    /// How many of `inputs` the store already holds.
    stored: usize,
}

impl Recording {
    /// Notes `input`, just applied to `world` (before its next step).
    pub fn note(&mut self, world: &World, input: WorldInput) {
        self.inputs.push((world.tick, input));
    }

    /// The inputs so far, oldest first.
    pub fn inputs(&self) -> &[(u64, WorldInput)] {
        &self.inputs
    }

    /// The inputs the store does not hold yet; they count as stored from now on.
    pub fn take_unstored(&mut self) -> &[(u64, WorldInput)] {
        let from = self.stored;
        self.stored = self.inputs.len();
        &self.inputs[from..]
    }
}

/// `input` as it matters to the world: the drawn tick only with the trigger pulled (so that
/// unchanged keys compare equal).
pub fn normalised(mut input: HumanInput) -> HumanInput {
    if !input.tag {
        input.seen_tick = None;
    }
    input
}
