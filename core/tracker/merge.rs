//! Role merging: grid histograms and the symmetric KL divergence between them, and the
//! merged cloud, a mixture of the two weighted by the opponents each role stands for.
//!
//! A coarse grid (`grid_cell` metres) covers the arena; only cells with free space count.
//! A role's histogram is its particle weights summed per cell, Laplace-smoothed (one pseudo
//! particle per cell) so that no cell has probability zero and the divergence stays finite.

use crate::sim::AGENT_RADIUS;
use crate::sim::arena::Arena;
use crate::tracker::role::Role;

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

/// Replaces `keep`'s cloud by the mixture of the two distributions, each weighted by the
/// opponents its role stands for: the merged role stands for `a + b` opponents, `a` of them
/// drawn from `keep`'s cloud and `b` from `other`'s, so `a / (a + b)` of the merged cloud is
/// `keep`'s (the paper's "average" is the case a = b). Each share is drawn from its cloud by
/// systematic resampling with the same `offset`, so both come out equally weighted.
pub fn average_into(keep: &mut Role, other: &Role, offset: f32) {
    let n = keep.particles.len();
    let (a, b) = (keep.count as usize, other.count as usize);
    // Half and half only if neither count says anything (untagged roles have at least one).
    let from_keep = (n * a + (a + b) / 2).checked_div(a + b).unwrap_or(n / 2);
    let mut particles = Vec::with_capacity(n);
    let mut steps = Vec::with_capacity(n);
    for (role, m) in [(&*keep, from_keep), (other, n - from_keep)] {
        for i in systematic(&role.weights, m, offset) {
            particles.push(role.particles[i]);
            steps.push(role.steps[i]);
        }
    }
    keep.particles = particles;
    keep.steps = steps;
    keep.weights = vec![1.0 / n as f32; n];
}

/// `m` indices drawn from `weights` by systematic (low-variance) resampling, `offset` in
/// [0, 1): one draw at each of `(offset + k) / m` of the cumulative weight.
fn systematic(weights: &[f32], m: usize, offset: f32) -> Vec<usize> {
    let mut out = Vec::with_capacity(m);
    let Some(&first) = weights.first() else {
        return out;
    };
    let step = weights.iter().sum::<f32>() / m as f32;
    let (mut c, mut i) = (first, 0);
    for k in 0..m {
        let u = (offset + k as f32) * step;
        while u > c && i + 1 < weights.len() {
            i += 1;
            c += weights[i];
        }
        out.push(i);
    }
    out
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

    #[test]
    fn systematic_resampling_draws_in_proportion_to_weight() {
        let picks = systematic(&[0.5, 0.0, 0.25, 0.25], 8, 0.5);
        assert_eq!(picks, vec![0, 0, 0, 0, 2, 2, 3, 3]);
        assert!(systematic(&[], 4, 0.5).is_empty());
    }
}
