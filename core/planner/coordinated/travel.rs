//! Travel between a map's candidate view positions, for the `search` planner's look-ahead.

use std::sync::Arc;

use crate::nav::DistanceField;
use crate::sim::arena::Arena;
use crate::sim::views::ViewTable;
use nalgebra::Point2;

/// Most candidate positions a map may have for its travel table (its size grows with the
/// square), and most cells its distance fields may visit together (positions × grid cells,
/// about half a second): beyond either, later steps travel in straight lines.
pub const MAX_TABLE_POSITIONS: usize = 800;
pub const MAX_TABLE_WORK: usize = 40_000_000;

/// Shortest-path metres between every two candidate positions of a map's view table
/// (`INFINITY` where one cannot reach the other), built once per map and shared.
#[derive(Debug)]
pub struct PositionTravel {
    positions: usize,
    metres: Vec<f32>,
}

/// The key of a [`PositionTravel`] among a map's derived tables: its positions, bit for bit.
#[derive(Debug, PartialEq)]
struct TravelKey(Vec<[u32; 2]>);

impl PositionTravel {
    /// The table for `views` on `arena`, or `None` when the map has too many positions.
    pub fn of(arena: &Arena, views: &ViewTable) -> Option<Arc<PositionTravel>> {
        let positions = &views.positions;
        if positions.len() > MAX_TABLE_POSITIONS
            || positions.len() * arena.grid.len() > MAX_TABLE_WORK
        {
            return None;
        }
        let key = TravelKey(
            positions
                .iter()
                .map(|p| [p.x.to_bits(), p.y.to_bits()])
                .collect(),
        );
        Some(arena.derived(key, |arena| PositionTravel::build(arena, positions)))
    }

    /// The table built afresh (what [`PositionTravel::of`] does once per map).
    pub fn build(arena: &Arena, positions: &[Point2<f32>]) -> PositionTravel {
        let grid = &arena.grid;
        let n = positions.len();
        let cells: Vec<Option<usize>> = positions.iter().map(|p| grid.cell_of(*p)).collect();
        let mut metres = vec![f32::INFINITY; n * n];
        for (a, from) in positions.iter().enumerate() {
            let Some(field) = DistanceField::from_point(grid, *from) else {
                continue;
            };
            for (b, cell) in cells.iter().enumerate() {
                if let Some(c) = *cell {
                    metres[a * n + b] = field.dist[c];
                }
            }
        }
        PositionTravel {
            positions: n,
            metres,
        }
    }

    /// Metres from position `a` to position `b`.
    pub fn metres(&self, a: usize, b: usize) -> f32 {
        self.metres[a * self.positions + b]
    }
}
