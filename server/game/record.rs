//! What a match task records so that the match can be replayed: every [`WorldInput`] it
//! applied, with the tick it was applied at (before that tick's step). Together with the
//! map, the settings and the seed that is the whole match.
//!
//! Keys are recorded only when they change what the world would do: a person's input
//! repeats every tick while the keys stay down, and the tick a view was drawn at matters
//! only with the trigger pulled.
//!
//! The recording lives as long as the match and its replay, so what orders from outside
//! (robots' and opponents' commands, which a client sends as fast as it may) add to it is
//! bounded: [`MAX_ORDER_BYTES`] a match, priced with the match when it takes such orders
//! (`admission::match_on`); past it a match refuses further orders. Keys and seats come at
//! most one per player and tick.

use lasertag_core::world::{HumanInput, OpponentOrder, RobotOrder, World, WorldInput};

/// Bytes the orders from outside one match records may take.
pub const MAX_ORDER_BYTES: usize = 4_000_000;

/// The bytes `input` takes in a recording, or `None` for what is not an order from outside.
pub fn order_bytes(input: &WorldInput) -> Option<usize> {
    let base = std::mem::size_of::<(u64, WorldInput)>();
    let point = std::mem::size_of::<nalgebra::Point2<f32>>();
    match input {
        WorldInput::Robot { order, .. } => Some(match order {
            RobotOrder::Waypoints(p) => base + p.len() * point,
            _ => base,
        }),
        WorldInput::Opponent { order, .. } => Some(match order {
            OpponentOrder::Waypoints(p) => base + p.len() * point,
            _ => base,
        }),
        _ => None,
    }
}

/// The inputs of one match, in the order they were applied.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Recording {
    inputs: Vec<(u64, WorldInput)>,
    /// How many of `inputs` the store already holds.
    stored: usize,
    /// Bytes of the orders from outside among `inputs`.
    order_bytes: usize,
}

/// Orders from outside past what a match may record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "the match has recorded {held} bytes of commands, and this one would take it past its bound of {MAX_ORDER_BYTES} bytes (it keeps every command for its replay); it takes no more commands"
)]
pub struct RecordingFull {
    pub held: usize,
}

impl Recording {
    /// Notes `input`, just applied to `world` (before its next step).
    pub fn note(&mut self, world: &World, input: WorldInput) {
        self.order_bytes += order_bytes(&input).unwrap_or(0);
        self.inputs.push((world.tick, input));
    }

    /// Whether the orders among `inputs` fit in what the match may still record.
    pub fn room_for(&self, inputs: &[WorldInput]) -> Result<(), RecordingFull> {
        let more: usize = inputs.iter().filter_map(order_bytes).sum();
        if more > 0 && self.order_bytes + more > MAX_ORDER_BYTES {
            return Err(RecordingFull {
                held: self.order_bytes,
            });
        }
        Ok(())
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
            if let WorldInput::Seat { name, .. } | WorldInput::SeatRobot { name, .. } = input
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
            .any(|(_, i)| matches!(i, WorldInput::Seat { .. } | WorldInput::SeatRobot { .. }))
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

#[cfg(test)]
mod tests {
    use super::*;
    use lasertag_core::world::OpponentOrder;
    use nalgebra::Point2;

    #[test]
    fn orders_past_the_bound_are_refused_and_keys_are_not_counted() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let maps = crate::maps::MapStore::load_dir(&root.join("maps")).expect("shipped maps");
        let arena = maps.get("office").expect("office").arena.clone();
        let world = World::new(arena, Default::default()).expect("world");
        let big = WorldInput::Opponent {
            slot: 0,
            order: OpponentOrder::Waypoints(vec![Point2::new(1.0, 1.0); 1000]),
        };
        let each = order_bytes(&big).unwrap();
        let mut r = Recording::default();
        let fit = MAX_ORDER_BYTES / each;
        for _ in 0..fit {
            assert_eq!(r.room_for(std::slice::from_ref(&big)), Ok(()));
            r.note(&world, big.clone());
        }
        assert!(r.room_for(std::slice::from_ref(&big)).is_err());
        let keys = WorldInput::Keys {
            slot: 0,
            input: HumanInput::default(),
        };
        assert_eq!(r.room_for(&[keys]), Ok(()));
    }
}
