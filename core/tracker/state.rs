//! The tracker's state: the team's roles and what updating them needs. The updates are
//! `impl Tracker` blocks beside it (`observe`, `resample`, and the module's own).

use nalgebra::Vector2;
use rand_chacha::ChaCha8Rng;

use crate::tracker::merge;
use crate::tracker::role::{Role, Settings};

#[derive(Debug, Clone)]
pub struct Tracker {
    pub settings: Settings,
    pub roles: Vec<Role>,
    pub(super) next_id: u64,
    pub(super) rng: ChaCha8Rng,
    /// Grid cells where an opponent disc fits: where particles may live.
    pub(super) free_cells: Vec<u32>,
    /// Unit vectors for the random walk (a table: cheaper than sin/cos per particle).
    pub(super) directions: Vec<Vector2<f32>>,
    pub(super) merger: merge::Histograms,
    pub(super) tick: u64,
}

crate::checkpoint::restore_struct!(Tracker {
    plain: [roles, next_id, rng, tick],
    nested: [],
    derived: [settings, free_cells, directions, merger],
});
