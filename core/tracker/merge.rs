//! Role merging: grid histograms and the symmetric KL divergence between them.
//!
//! A coarse grid (`grid_cell` metres) covers the arena; only cells with free space count.
//! A role's histogram is its particle weights summed per cell, Laplace-smoothed (one pseudo
//! particle per cell) so that no cell has probability zero and the divergence stays finite.

use crate::sim::AGENT_RADIUS;
use crate::sim::arena::Arena;
use crate::tracker::Role;

#[derive(Debug, Clone)]
pub struct Histograms {
    cell: f32,
    cols: usize,
    rows: usize,
    /// Grid cell → histogram bin (only cells with free space have one).
    bin_of: Vec<Option<u32>>,
    bins: usize,
}

impl Histograms {
    pub fn new(arena: &Arena, cell: f32) -> Histograms {
        let cols = (arena.width() / cell).ceil().max(1.0) as usize;
        let rows = (arena.height() / cell).ceil().max(1.0) as usize;
        let mut has_free = vec![false; cols * rows];
        let g = &arena.grid;
        for c in 0..g.len() {
            if g.clearance[c] >= AGENT_RADIUS {
                let p = g.centre(c);
                let (x, y) = ((p.x / cell) as usize, (p.y / cell) as usize);
                if x < cols && y < rows {
                    has_free[y * cols + x] = true;
                }
            }
        }
        let mut bins = 0;
        let bin_of = has_free
            .iter()
            .map(|&f| {
                f.then(|| {
                    bins += 1;
                    bins as u32 - 1
                })
            })
            .collect();
        Histograms {
            cell,
            cols,
            rows,
            bin_of,
            bins: bins.max(1),
        }
    }

    /// The role's smoothed probability per bin.
    pub fn histogram(&self, role: &Role) -> Vec<f32> {
        let mut h = vec![0.0f32; self.bins];
        for (p, w) in role.particles.iter().zip(&role.weights) {
            let (x, y) = ((p.x / self.cell) as usize, (p.y / self.cell) as usize);
            if x < self.cols
                && y < self.rows
                && let Some(b) = self.bin_of[y * self.cols + x]
            {
                h[b as usize] += w;
            }
        }
        // Laplace smoothing: weights scaled to particle counts, plus one per bin.
        let n = role.particles.len() as f32;
        let total: f32 = h.iter().sum::<f32>() * n + self.bins as f32;
        h.iter_mut().for_each(|v| *v = (*v * n + 1.0) / total);
        h
    }
}

/// KL(p‖q) + KL(q‖p) = Σ (p − q) ln(p / q).
pub fn symmetric_kl(p: &[f32], q: &[f32]) -> f32 {
    p.iter().zip(q).map(|(a, b)| (a - b) * (a / b).ln()).sum()
}

/// Replaces `keep`'s cloud by the average of the two distributions: both are resampled to
/// equal weights, then the merged cloud takes every other particle from each.
pub fn average_into(keep: &mut Role, other: &Role, offset: f32) {
    let n = keep.particles.len();
    let mut a = keep.clone();
    let mut b = other.clone();
    crate::tracker::low_variance_resample(&mut a, offset);
    crate::tracker::low_variance_resample(&mut b, offset);
    let pick = |k: usize| {
        if k.is_multiple_of(2) {
            (&a, k)
        } else {
            (&b, k % b.particles.len())
        }
    };
    keep.particles = (0..n)
        .map(|k| {
            let (r, i) = pick(k);
            r.particles[i]
        })
        .collect();
    keep.steps = (0..n)
        .map(|k| {
            let (r, i) = pick(k);
            r.steps[i]
        })
        .collect();
    keep.weights = vec![1.0 / n as f32; n];
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kl_is_zero_for_equal_and_positive_for_different() {
        let p = vec![0.25, 0.25, 0.5];
        let q = vec![0.5, 0.25, 0.25];
        assert!(symmetric_kl(&p, &p).abs() < 1e-7);
        let d = symmetric_kl(&p, &q);
        assert!(d > 0.0 && (d - symmetric_kl(&q, &p)).abs() < 1e-6);
    }
}
