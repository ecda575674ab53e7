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

    /// For each pose `(x, y, sin θ, cos θ)`, the sum of [`LikelihoodField::log_likelihood`]
    /// over the beam end points `local` (in the robot's frame) carried into the world by
    /// that pose, added in the order of `local`, into `out`.
    ///
    /// The localiser's hot loop (particles × beams lookups). On a CPU with AVX2 it runs
    /// eight poses a lane each: the same operations in the same order on every lane (IEEE
    /// single precision, no fused multiply-add, truncating conversions of in-range values),
    /// so the sums are the scalar loop's bit for bit (a test compares them).
    pub fn beam_sums(&self, poses: &[[f32; 4]], local: &[(f32, f32)], out: &mut [f32]) {
        let n = poses.len().min(out.len());
        let mut done = 0;
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            done = n - n % 8;
            // SAFETY: the CPU has AVX2 (checked above), and `beam_sums_avx2` reads the
            // table only at indices it has bounds-checked lane by lane.
            unsafe { self.beam_sums_avx2(&poses[..done], local, &mut out[..done]) };
        }
        self.beam_sums_scalar(&poses[done..n], local, &mut out[done..n]);
    }

    pub(super) fn beam_sums_scalar(
        &self,
        poses: &[[f32; 4]],
        local: &[(f32, f32)],
        out: &mut [f32],
    ) {
        for ([px, py, s, c], l) in poses.iter().zip(out) {
            let mut sum = 0.0f32;
            for &(lx, ly) in local {
                let x = px + c * lx - s * ly;
                let y = py + s * lx + c * ly;
                sum += self.log_likelihood(x, y);
            }
            *l = sum;
        }
    }

    /// [`LikelihoodField::beam_sums_scalar`] eight poses at a time (`poses.len()` a multiple
    /// of 8).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn beam_sums_avx2(&self, poses: &[[f32; 4]], local: &[(f32, f32)], out: &mut [f32]) {
        use std::arch::x86_64::*;
        let cols = self.cols as i32;
        let table = self.log_p.as_ptr();
        let ox = _mm256_set1_ps(self.origin.x);
        let oy = _mm256_set1_ps(self.origin.y);
        let step = _mm256_set1_ps(self.step);
        let zero = _mm256_setzero_ps();
        let one = _mm256_set1_ps(1.0);
        let last_col = _mm256_set1_ps((self.cols - 1) as f32);
        let last_row = _mm256_set1_ps((self.rows - 1) as f32);
        let outside = _mm256_set1_ps(self.log_outside);
        let vcols = _mm256_set1_epi32(cols);
        let next_row = _mm256_set1_epi32(cols + 1);
        for (group, sums) in poses.chunks_exact(8).zip(out.chunks_exact_mut(8)) {
            let lane = |k: usize| -> __m256 {
                let v: [f32; 8] = std::array::from_fn(|i| group[i][k]);
                // SAFETY: an unaligned load of eight floats from a local array.
                unsafe { _mm256_loadu_ps(v.as_ptr()) }
            };
            let (px, py, sn, cs) = (lane(0), lane(1), lane(2), lane(3));
            let mut sum = zero;
            for &(lx, ly) in local {
                let (lx, ly) = (_mm256_set1_ps(lx), _mm256_set1_ps(ly));
                // x = px + c * lx - s * ly;  y = py + s * lx + c * ly (left to right).
                let x = _mm256_sub_ps(
                    _mm256_add_ps(px, _mm256_mul_ps(cs, lx)),
                    _mm256_mul_ps(sn, ly),
                );
                let y = _mm256_add_ps(
                    _mm256_add_ps(py, _mm256_mul_ps(sn, lx)),
                    _mm256_mul_ps(cs, ly),
                );
                let fx = _mm256_div_ps(_mm256_sub_ps(x, ox), step);
                let fy = _mm256_div_ps(_mm256_sub_ps(y, oy), step);
                // The scalar bounds check, lane by lane (ordered compares: NaN is outside).
                let inside = _mm256_and_ps(
                    _mm256_and_ps(
                        _mm256_cmp_ps::<_CMP_GE_OQ>(fx, zero),
                        _mm256_cmp_ps::<_CMP_GE_OQ>(fy, zero),
                    ),
                    _mm256_and_ps(
                        _mm256_cmp_ps::<_CMP_LT_OQ>(fx, last_col),
                        _mm256_cmp_ps::<_CMP_LT_OQ>(fy, last_row),
                    ),
                );
                // Outside lanes convert 0 (their values are replaced below).
                let fx = _mm256_and_ps(fx, inside);
                let fy = _mm256_and_ps(fy, inside);
                let c = _mm256_cvttps_epi32(fx);
                let r = _mm256_cvttps_epi32(fy);
                let tx = _mm256_sub_ps(fx, _mm256_cvtepi32_ps(c));
                let ty = _mm256_sub_ps(fy, _mm256_cvtepi32_ps(r));
                let i = _mm256_add_epi32(_mm256_mullo_epi32(r, vcols), c);
                // SAFETY: an inside lane's cell and the next one each way are in the table
                // (the check above); outside lanes are masked off and read nothing.
                let (t0, t1, b0, b1) = unsafe {
                    (
                        _mm256_mask_i32gather_ps::<4>(zero, table, i, inside),
                        _mm256_mask_i32gather_ps::<4>(
                            zero,
                            table,
                            _mm256_add_epi32(i, _mm256_set1_epi32(1)),
                            inside,
                        ),
                        _mm256_mask_i32gather_ps::<4>(
                            zero,
                            table,
                            _mm256_add_epi32(i, vcols),
                            inside,
                        ),
                        _mm256_mask_i32gather_ps::<4>(
                            zero,
                            table,
                            _mm256_add_epi32(i, next_row),
                            inside,
                        ),
                    )
                };
                let one_tx = _mm256_sub_ps(one, tx);
                let lo = _mm256_add_ps(_mm256_mul_ps(t0, one_tx), _mm256_mul_ps(t1, tx));
                let hi = _mm256_add_ps(_mm256_mul_ps(b0, one_tx), _mm256_mul_ps(b1, tx));
                let v = _mm256_add_ps(
                    _mm256_mul_ps(lo, _mm256_sub_ps(one, ty)),
                    _mm256_mul_ps(hi, ty),
                );
                sum = _mm256_add_ps(sum, _mm256_blendv_ps(outside, v, inside));
            }
            // SAFETY: an unaligned store of eight floats into a chunk of eight.
            unsafe { _mm256_storeu_ps(sums.as_mut_ptr(), sum) };
        }
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
