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

    /// The inputs the store does not hold yet.
    pub fn unstored(&self) -> &[(u64, WorldInput)] {
        &self.inputs[self.stored..]
    }

    /// The first `n` of [`Recording::unstored`] are in the store now.
    pub fn mark_stored(&mut self, n: usize) {
        self.stored = (self.stored + n).min(self.inputs.len());
    }

    /// Everyone who took a seat so far, in the order they first did.
    pub fn names(&self) -> Vec<String> {
        let mut names: Vec<String> = Vec::new();
        for (_, input) in &self.inputs {
            if let WorldInput::Seat { name, .. } = input
                && !names.contains(name)
            {
                names.push(name.clone());
            }
        }
        names
    }

    /// Whether any of the unstored inputs seats someone.
    pub fn seats_unstored(&self) -> bool {
        self.unstored()
            .iter()
            .any(|(_, i)| matches!(i, WorldInput::Seat { .. }))
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
