//! How far a choosing robot's travel field needs to grow: a pose's worth falls with its
//! travel, so the field can stop where no pose beyond could beat one already reached
//! ([`ChoiceWatch`]). Below `scoring`, which fills in the worths.

use std::sync::Arc;

use nalgebra::Point2;

use crate::nav::{DistanceField, Watch};
use crate::sim::arena::ClearanceGrid;

/// How far below the best value reached so far the most a pose still unreached could be
/// worth must fall before a choosing robot's field stops growing: far above the rounding
/// of the two ways the value is summed (about 1e-7), far below what choices differ by.
const STOP_MARGIN: f32 = 1e-3;

/// In [`cell_positions`]: no candidate position on the cell.
pub const NO_POSITION: u32 = u32::MAX;

/// Grows a choosing robot's travel field only while a pose it has not reached could still be
/// worth more than the best it has: a pose's worth falls with its travel, so once the most
/// any pose is worth before travel, less the travel to the field's edge, is below the best
/// reached, no pose beyond can win. The choice is then the one the whole field gives, pose
/// for pose (the poses past the edge read as unreachable or farther than they are, and lose
/// either way); about a third of the field is searched.
pub(super) struct ChoiceWatch<'a> {
    grid: &'a ClearanceGrid,
    /// Per grid cell, the candidate position on it, or [`NO_POSITION`].
    cell_positions: &'a [u32],
    /// Per position, the most one of its poses is worth before travel and passages.
    tops: Vec<f32>,
    /// The largest of `tops`.
    ceiling: f32,
    /// Worth a metre of travel costs; and at most, with the narrow passages' term.
    per_metre: f32,
    per_metre_most: f32,
    /// The least the best pose reached so far is worth.
    best: f32,
}

impl Watch for ChoiceWatch<'_> {
    fn settled(&mut self, cell: usize, units: u32) {
        let p = self.cell_positions[cell];
        if p != NO_POSITION {
            let metres = DistanceField::metres_of(self.grid, units);
            let least = self.tops[p as usize] - self.per_metre_most * metres;
            self.best = self.best.max(least);
        }
    }

    fn go_on(&mut self, units: u32) -> bool {
        let metres = DistanceField::metres_of(self.grid, units);
        self.ceiling - self.per_metre * metres >= self.best - STOP_MARGIN
    }
}

impl<'a> ChoiceWatch<'a> {
    /// A watch over `grid` whose candidate positions sit on the cells `cell_positions`
    /// names; `tops` holds each position's most worth before travel and passages,
    /// `per_metre` the worth a metre of travel costs and `narrow` what a metre through a
    /// narrow passage may cost besides.
    pub(super) fn new(
        grid: &'a ClearanceGrid,
        cell_positions: &'a [u32],
        tops: Vec<f32>,
        per_metre: f32,
        narrow: f32,
    ) -> ChoiceWatch<'a> {
        ChoiceWatch {
            grid,
            cell_positions,
            ceiling: tops.iter().copied().fold(f32::NEG_INFINITY, f32::max),
            tops,
            per_metre,
            per_metre_most: per_metre + narrow,
            best: f32::NEG_INFINITY,
        }
    }
}

/// Per cell of `grid`, the index of the first of `positions` on it, or [`NO_POSITION`].
pub fn cell_positions(grid: &ClearanceGrid, positions: &[Point2<f32>]) -> Arc<[u32]> {
    let mut cells = vec![NO_POSITION; grid.len()];
    for (p_idx, p) in positions.iter().enumerate() {
        if let Some(cell) = grid.cell_of(*p)
            && cells[cell] == NO_POSITION
        {
            cells[cell] = p_idx as u32;
        }
    }
    cells.into()
}
