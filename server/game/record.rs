//! What a match task records so that the match can be replayed and resumed: every
//! [`WorldInput`] it applied, with the tick it was applied at (before that tick's step).
//! Together with the map, the settings and the seed that is the whole match.
//!
//! Keys are recorded only when they change what the world would do: a person's input
//! repeats every tick while the keys stay down, and the tick a view was drawn at matters
//! only with the trigger pulled.
//!
//! The record streams to the store about once a second (`task/history.rs`), so what bounds
//! the orders from outside (robots' and opponents' commands, which a client sends as fast
//! as it may) is the store: [`MAX_RECORD_BYTES`] a match, on disk, priced with the match when
//! it takes such orders (`admission::match_on`'s `disk`); past it a match refuses further
//! orders. In memory a recording keeps the newest orders within [`MEMORY_ORDER_BYTES`] and
//! lets go of older ones once the store has them, so a match driven for an hour holds no more
//! memory than one driven for a minute; its replay then reads them from the store in windows
//! (`replay/inputs.rs`). Without a store
//! nothing may be let go of, and the memory bound is the match's bound. Keys and seats come
//! at most one per player and tick.

use lasertag_core::world::{HumanInput, OpponentOrder, RobotOrder, World, WorldInput};

/// Bytes the orders from outside one match may record, in the store: an hour of `act`
/// commands for 8 robots at 20 Hz (576,000 orders) is about 28 MB.
pub const MAX_RECORD_BYTES: usize = 64_000_000;
/// Bytes of orders from outside a recording keeps in memory (the newest; the store has the
/// rest), and all a match may record without a store.
pub const MEMORY_ORDER_BYTES: usize = 4_000_000;

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
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// The inputs still in memory, oldest first: all of them but the first `dropped`.
    inputs: Vec<(u64, WorldInput)>,
    /// Inputs let go of from memory (the store has them).
    dropped: usize,
    /// How many inputs (of all, counting the dropped) the store already holds.
    stored: usize,
    /// Bytes of the orders from outside among all inputs, and among those in memory.
    order_bytes: usize,
    kept_order_bytes: usize,
    /// Whether the match has a store to let inputs go to.
    spills: bool,
    /// Everyone who took a seat so far, in the order they first did.
    names: Vec<String>,
}

/// Orders from outside past what a match may record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "the match has recorded {held} bytes of commands, and this one would take it past its bound of {max} bytes {kept} (every command is kept for its replay); it takes no more commands"
)]
pub struct RecordingFull {
    pub held: usize,
    pub max: usize,
    /// Where the bound is: "on disk" (a store keeps the record), or "in memory".
    pub kept: &'static str,
}

impl Recording {
    /// An empty recording; `spills`: a store keeps what memory lets go of.
    pub fn new(spills: bool) -> Recording {
        Recording {
            inputs: Vec::new(),
            dropped: 0,
            stored: 0,
            order_bytes: 0,
            kept_order_bytes: 0,
            spills,
            names: Vec::new(),
        }
    }

    /// A recording of `inputs`, all of which the store holds already (a resumed match).
    pub fn stored(spills: bool, inputs: Vec<(u64, WorldInput)>) -> Recording {
        let mut r = Recording::new(spills);
        for (tick, input) in inputs {
            r.push(tick, input);
        }
        r.stored = r.inputs.len();
        r.let_go();
        r
    }

    /// The most bytes of orders this recording may hold.
    fn max_bytes(&self) -> usize {
        if self.spills {
            MAX_RECORD_BYTES
        } else {
            MEMORY_ORDER_BYTES
        }
    }

    fn push(&mut self, tick: u64, input: WorldInput) {
        let bytes = order_bytes(&input).unwrap_or(0);
        self.order_bytes += bytes;
        self.kept_order_bytes += bytes;
        if let WorldInput::Seat { name, .. } | WorldInput::SeatRobot { name, .. } = &input
            && !self.names.contains(name)
        {
            self.names.push(name.clone());
        }
        self.inputs.push((tick, input));
    }

    /// Notes `input`, just applied to `world` (before its next step).
    pub fn note(&mut self, world: &World, input: WorldInput) {
        self.push(world.tick, input);
    }

    /// Whether the orders among `inputs` fit in what the match may still record.
    pub fn room_for(&self, inputs: &[WorldInput]) -> Result<(), RecordingFull> {
        let more: usize = inputs.iter().filter_map(order_bytes).sum();
        let max = self.max_bytes();
        if more > 0 && self.order_bytes + more > max {
            return Err(RecordingFull {
                held: self.order_bytes,
                max,
                kept: if self.spills { "on disk" } else { "in memory" },
            });
        }
        Ok(())
    }

    /// Every input, oldest first, when memory still holds them all (`None` once some were
    /// let go of: the store has the whole recording).
    pub fn inputs(&self) -> Option<&[(u64, WorldInput)]> {
        (self.dropped == 0).then_some(&self.inputs[..])
    }

    /// How many inputs it holds, counting those let go of from memory.
    pub fn recorded(&self) -> usize {
        self.dropped + self.inputs.len()
    }

    /// The inputs the store does not hold yet.
    pub fn unstored(&self) -> &[(u64, WorldInput)] {
        &self.inputs[self.stored - self.dropped..]
    }

    /// The first `n` of [`Recording::unstored`] are in the store now: past the memory bound,
    /// memory lets go of the oldest of them.
    pub fn mark_stored(&mut self, n: usize) {
        self.stored = (self.stored + n).min(self.dropped + self.inputs.len());
        self.let_go();
    }

    /// Drops stored inputs from the front while the orders in memory are past their bound.
    fn let_go(&mut self) {
        if !self.spills || self.kept_order_bytes <= MEMORY_ORDER_BYTES {
            return;
        }
        let storable = self.stored - self.dropped;
        let mut n = 0;
        let mut freed = 0;
        while n < storable && self.kept_order_bytes - freed > MEMORY_ORDER_BYTES / 2 {
            freed += order_bytes(&self.inputs[n].1).unwrap_or(0);
            n += 1;
        }
        self.inputs.drain(..n);
        self.dropped += n;
        self.kept_order_bytes -= freed;
    }

    /// Everyone who took a seat so far, in the order they first did.
    pub fn names(&self) -> Vec<String> {
        self.names.clone()
    }

    /// Whether any of the unstored inputs seats someone or frees a seat.
    pub fn seats_unstored(&self) -> bool {
        self.unstored().iter().any(|(_, i)| {
            matches!(
                i,
                WorldInput::Seat { .. }
                    | WorldInput::SeatRobot { .. }
                    | WorldInput::Unseat { .. }
                    | WorldInput::UnseatRobot { .. }
            )
        })
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
        let mut r = Recording::new(false);
        let fit = MEMORY_ORDER_BYTES / each;
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
        assert_eq!(r.inputs().map(<[_]>::len), Some(fit), "nothing let go of");
    }

    #[test]
    fn with_a_store_memory_lets_go_of_stored_orders_and_the_store_bounds_them() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let maps = crate::maps::MapStore::load_dir(&root.join("maps")).expect("shipped maps");
        let arena = maps.get("office").expect("office").arena.clone();
        let world = World::new(arena, Default::default()).expect("world");
        let order = WorldInput::Robot {
            robot: 0,
            order: RobotOrder::Stop,
        };
        let each = order_bytes(&order).unwrap();
        let mut r = Recording::new(true);
        let mut all = 0;
        // Past the memory bound several times over, storing as the task does every second.
        while all * each < 3 * MEMORY_ORDER_BYTES {
            for _ in 0..1000 {
                assert_eq!(r.room_for(std::slice::from_ref(&order)), Ok(()));
                r.note(&world, order.clone());
                all += 1;
            }
            let n = r.unstored().len();
            assert_eq!(n, 1000, "every input reaches the store once");
            r.mark_stored(n);
            assert!(r.kept_order_bytes <= MEMORY_ORDER_BYTES + 1000 * each);
        }
        assert!(r.inputs().is_none(), "some were let go of");
        assert_eq!(r.dropped + r.inputs.len(), all);
        // The bound is the store's.
        let mut full = r.clone();
        full.order_bytes = MAX_RECORD_BYTES;
        assert!(full.room_for(std::slice::from_ref(&order)).is_err());
        // A resumed recording holds what the store gave it, stored.
        let again = Recording::stored(true, vec![(3, order.clone()); 10]);
        assert!(again.unstored().is_empty());
        assert_eq!(again.inputs().map(<[_]>::len), Some(10));
    }
}
