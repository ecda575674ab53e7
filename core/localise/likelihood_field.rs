//! The laser's likelihood field: the log-likelihood of a beam end point, precomputed on a
//! lattice over the arena and shared by every robot on a map, and the clearance-grid cells a
//! robot's centre may occupy.

use std::sync::Arc;

use nalgebra::Point2;

use super::tuning::Settings;
use crate::sim::arena::Arena;

/// Log-likelihood of a beam end point, on a lattice over the arena plus a margin.
///
/// The lattice holds exact distances to the nearest wall at its nodes (inside obstacles and
/// beyond the border too), and lookups interpolate bilinearly. Reading the clearance grid's
/// cell values directly biased every estimate by half a cell (5 cm) towards the room's
/// middle: a wall's own cell says 0.05 m and the cell past it is "outside".
#[derive(Debug, Clone)]
pub struct LikelihoodField {
    step: f32,
    /// Lattice origin (the node at index 0), `margin` below and left of the arena.
    origin: Point2<f32>,
    cols: usize,
    rows: usize,
    log_p: Vec<f32>,
    /// Log-likelihood of an end point beyond the lattice (the random term alone).
    pub(super) log_outside: f32,
    /// The arena's clearance grid cells an agent fits in: where injected particles go.
    pub(super) free_cells: Vec<usize>,
    pub(super) grid_cell: f32,
    pub(super) grid_cols: usize,
    grid_rows: usize,
    /// Per clearance-grid cell: can a robot's centre be here (not inside a wall)?
    open: Vec<bool>,
}

/// How far beyond the border the lattice reaches (m): beams that overshoot a wall by laser
/// noise or a pose error must still find that wall near.
const FIELD_MARGIN: f32 = 1.0;

/// What a likelihood field depends on besides the map: σ_hit, z_hit, z_rand and the laser's
/// range, as bit patterns (exact equality is what a cache wants).
#[derive(PartialEq)]
struct FieldKey([u32; 4]);

impl LikelihoodField {
    /// The field for these filter settings and laser range on `arena`, built on first use
    /// (15 ms on `office`) and shared by every robot of every match on this map.
    pub fn of(arena: &Arena, settings: &Settings, laser_range: f32) -> Arc<LikelihoodField> {
        let key = FieldKey([
            settings.sigma_hit.to_bits(),
            settings.z_hit.to_bits(),
            settings.z_rand.to_bits(),
            laser_range.to_bits(),
        ]);
        arena.derived(key, |arena| {
            LikelihoodField::new(arena, settings, laser_range)
        })
    }

    pub fn new(arena: &Arena, settings: &Settings, laser_range: f32) -> LikelihoodField {
        let g = &arena.grid;
        let step = g.cell;
        let origin = Point2::new(-FIELD_MARGIN, -FIELD_MARGIN);
        let cols = ((arena.width() + 2.0 * FIELD_MARGIN) / step).ceil() as usize + 1;
        let rows = ((arena.height() + 2.0 * FIELD_MARGIN) / step).ceil() as usize + 1;
        let rand_term = settings.z_rand / laser_range.max(1e-3);
        let two_s2 = 2.0 * settings.sigma_hit * settings.sigma_hit;
        let mut log_p = Vec::with_capacity(cols * rows);
        for r in 0..rows {
            for c in 0..cols {
                let p = Point2::new(origin.x + c as f32 * step, origin.y + r as f32 * step);
                let d = (arena.closest_wall_point(p) - p).norm();
                let hit = settings.z_hit * (-(d * d) / two_s2).exp();
                log_p.push((hit + rand_term).ln());
            }
        }
        LikelihoodField {
            step,
            origin,
            cols,
            rows,
            log_p,
            log_outside: rand_term.ln(),
            free_cells: (0..g.len()).filter(|&i| g.passable(i)).collect(),
            grid_cell: g.cell,
            grid_cols: g.cols,
            grid_rows: g.rows,
            open: g.clearance.iter().map(|c| *c > 0.0).collect(),
        }
    }

    /// Log-likelihood of a beam ending at (x, y).
    #[inline]
    pub fn log_likelihood(&self, x: f32, y: f32) -> f32 {
        let fx = (x - self.origin.x) / self.step;
        let fy = (y - self.origin.y) / self.step;
        // The cell and the next one each way are in the table: `floor(fx) + 1 < cols` is
        // `fx < cols - 1` (exact in f32 for any table this size); NaN fails as well. The
        // checked bounds make the integer conversions plain truncations.
        let (last_col, last_row) = ((self.cols - 1) as f32, (self.rows - 1) as f32);
        if !(fx >= 0.0 && fy >= 0.0 && fx < last_col && fy < last_row) {
            return self.log_outside;
        }
        let (c, r) = (fx as u32 as usize, fy as u32 as usize);
        let (tx, ty) = (fx - c as f32, fy - r as f32);
        let i = r * self.cols + c;
        // Two cells of this row and two of the next: two bounds checks, not four.
        let (top, bottom) = (
            &self.log_p[i..i + 2],
            &self.log_p[i + self.cols..i + self.cols + 2],
        );
        let lo = top[0] * (1.0 - tx) + top[1] * tx;
        let hi = bottom[0] * (1.0 - tx) + bottom[1] * tx;
        lo * (1.0 - ty) + hi * ty
    }

    /// Can a robot's centre be at (x, y)?
    pub fn open(&self, x: f32, y: f32) -> bool {
        if !(x >= 0.0 && y >= 0.0) {
            return false;
        }
        let c = (x / self.grid_cell) as usize;
        let r = (y / self.grid_cell) as usize;
        c < self.grid_cols && r < self.grid_rows && self.open[r * self.grid_cols + c]
    }
}
