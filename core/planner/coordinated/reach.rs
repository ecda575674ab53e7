//! How far a choosing robot's travel field needs to grow: a pose's worth falls with its
//! travel, so the field can stop where no pose beyond could beat one already reached
//! ([`ChoiceWatch`]). `scoring` grows the field with it.

use std::sync::Arc;

use nalgebra::Point2;

use super::Coordinated;
use crate::nav::{DistanceField, Watch};
use crate::sim::Physics;
use crate::sim::arena::{Arena, ClearanceGrid};

/// How far below the best value reached so far the most a pose still unreached could be
/// worth must fall before a choosing robot's field stops growing: far above the rounding
/// of the two ways the value is summed (about 1e-7), far below what choices differ by.
const STOP_MARGIN: f32 = 1e-3;

/// In [`Coordinated::cell_positions`]: no candidate position on the cell.
pub const NO_POSITION: u32 = u32::MAX;

/// Grows a choosing robot's travel field only while a pose it has not reached could still be
/// worth more than the best it has: a pose's worth falls with its travel, so once the most
/// any pose is worth before travel, less the travel to the field's edge, is below the best
/// reached, no pose beyond can win. The choice is then the one the whole field gives, pose
/// for pose (the poses past the edge read as unreachable or farther than they are, and lose
/// either way); about a third of the field is searched.
///
/// For an uncertain robot it also sums, cell by cell as they settle, the metres of each
/// path through narrow passages: what [`DistanceField::narrow_metres`] gives for the cells
/// settled, in the same additions, so that the worth of a pose reached is exact and the
/// pass over the whole field is spared.
pub(super) struct ChoiceWatch<'a> {
    grid: &'a ClearanceGrid,
    /// Per grid cell, the candidate position on it, or [`NO_POSITION`].
    cell_positions: &'a [u32],
    /// Per position, the most one of its poses is worth before travel and passages.
    tops: Vec<f32>,
    /// The largest of `tops`.
    ceiling: f32,
    /// Worth a metre of travel costs.
    per_metre: f32,
    /// For an uncertain robot: which cells are narrow, the worth a metre through them
    /// costs, and per cell the narrow metres of its path (infinite until settled).
    narrow: Option<Narrow<'a>>,
    /// The least the best pose reached so far is worth.
    best: f32,
}

struct Narrow<'a> {
    cells: &'a [bool],
    per_metre: f32,
    metres: Vec<f32>,
}

impl Watch for ChoiceWatch<'_> {
    fn settled(&mut self, cell: usize, units: u32, from: Option<(usize, u32)>) {
        let metres = DistanceField::metres_of(self.grid, units);
        let mut narrow_cost = 0.0;
        if let Some(n) = &mut self.narrow {
            // As `narrow_metres` sums them: a narrow cell adds its step from the one before.
            let acc = match from {
                None => 0.0,
                Some((prev, prev_units)) => {
                    let mut acc = n.metres[prev];
                    if n.cells.get(cell).copied().unwrap_or(false) {
                        acc += metres - DistanceField::metres_of(self.grid, prev_units);
                    }
                    acc
                }
            };
            n.metres[cell] = acc;
            narrow_cost = n.per_metre * acc;
        }
        let p = self.cell_positions[cell];
        if p != NO_POSITION {
            let least = self.tops[p as usize] - self.per_metre * metres - narrow_cost;
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
    /// names; `tops` holds each position's most worth before travel and passages and
    /// `per_metre` the worth a metre of travel costs. `narrow`: the narrow cells and the
    /// worth a metre through them costs, for a robot that weighs them.
    pub(super) fn new(
        grid: &'a ClearanceGrid,
        cell_positions: &'a [u32],
        tops: Vec<f32>,
        per_metre: f32,
        narrow: Option<(&'a [bool], f32)>,
    ) -> ChoiceWatch<'a> {
        ChoiceWatch {
            grid,
            cell_positions,
            ceiling: tops.iter().copied().fold(f32::NEG_INFINITY, f32::max),
            tops,
            per_metre,
            narrow: narrow.map(|(cells, per_metre)| Narrow {
                cells,
                per_metre,
                metres: vec![f32::INFINITY; grid.len()],
            }),
            best: f32::NEG_INFINITY,
        }
    }

    /// Per cell, the metres of its path through narrow passages: as
    /// [`DistanceField::narrow_metres`] gives them for the cells the field settled, infinite
    /// for the others (none of which can be the choice). `None` when not weighed.
    pub(super) fn into_narrow_metres(self) -> Option<Vec<f32>> {
        self.narrow.map(|n| n.metres)
    }
}

impl Coordinated {
    /// What stops robot `i`'s field growing once no farther pose can be its choice: each
    /// position's most worth before travel and narrow passages, with the same terms
    /// `best_for` adds (crowding near `chosen`, the kept goal's bonus, the landmark).
    pub(super) fn choice_watch<'a>(
        &'a self,
        arena: &'a Arena,
        physics: &Physics,
        i: usize,
        chosen: &[Point2<f32>],
        uncertainty: f32,
    ) -> ChoiceWatch<'a> {
        let s = &self.settings;
        let h = s.headings;
        let current = self.robots[i].goal.map(|g| g.pose);
        let tops: Vec<f32> = self
            .views
            .positions
            .iter()
            .enumerate()
            .map(|(p_idx, p)| {
                let crowding: f32 = chosen
                    .iter()
                    .map(|q| (1.0 - (q - p).norm() / s.crowding_radius).max(0.0))
                    .sum();
                let landmark = if uncertainty > 0.0 && self.sees_landmark[p_idx] {
                    uncertainty * s.landmark_weight
                } else {
                    0.0
                };
                let most = (p_idx * h..(p_idx + 1) * h)
                    .map(|k| {
                        self.seen[k]
                            + if current == Some(k) {
                                s.keep_bonus
                            } else {
                                0.0
                            }
                    })
                    .fold(f32::NEG_INFINITY, f32::max);
                most - s.crowding_weight * crowding + landmark
            })
            .collect();
        let per_metre = s.travel_weight / physics.robot_speed;
        let narrow = self
            .weighs_narrow(uncertainty)
            .then(|| (&self.narrow[..], uncertainty * s.narrow_weight));
        ChoiceWatch::new(&arena.grid, &self.cell_positions, tops, per_metre, narrow)
    }

    /// Whether a robot this uncertain weighs the metres of its paths through narrow
    /// passages: a certain one does not (and the terms vanish exactly, so its choices are
    /// the plain planner's).
    fn weighs_narrow(&self, uncertainty: f32) -> bool {
        uncertainty > 0.0 && self.settings.narrow_weight > 0.0
    }

    /// The narrow metres of every cell's path in `field`, for a robot that weighs them.
    pub(super) fn narrow_metres(
        &self,
        field: &DistanceField,
        uncertainty: f32,
    ) -> Option<Vec<f32>> {
        self.weighs_narrow(uncertainty)
            .then(|| field.narrow_metres(&self.narrow))
    }

    /// Per cell of `grid`, the index of the first of `positions` on it, or
    /// [`NO_POSITION`].
    pub(super) fn cell_positions(grid: &ClearanceGrid, positions: &[Point2<f32>]) -> Arc<[u32]> {
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
}
