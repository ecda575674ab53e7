//! The moves of stage 1 of [`super::Tracker::update`]: each particle takes its step, unless
//! the step would leave the space an opponent fits in; then it stays and its step is zeroed
//! (it picks anew next tick). Eight particles at a time with AVX2 where the CPU has it: the
//! sums and the divisions that find each new point's cell are the same IEEE operations in a
//! vector lane as one at a time, so the result is the same bit for bit (a unit test holds
//! the two to it).

use nalgebra::{Point2, Vector2};

use crate::sim::arena::ClearanceGrid;

/// Moves every particle by its step, or stops it where the step would leave free space.
pub(super) fn step_or_stop(
    grid: &ClearanceGrid,
    particles: &mut [Point2<f32>],
    steps: &mut [Vector2<f32>],
) {
    let n = particles.len().min(steps.len());
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && grid.cols < i32::MAX as usize {
        done = n - n % 8;
        // SAFETY: the CPU has AVX2 (checked above).
        unsafe { step_or_stop_avx2(grid, &mut particles[..done], &mut steps[..done]) };
    }
    for (p, v) in particles[done..n].iter_mut().zip(&mut steps[done..n]) {
        step_one(grid, p, v);
    }
}

fn step_one(grid: &ClearanceGrid, p: &mut Point2<f32>, v: &mut Vector2<f32>) {
    let q = *p + *v;
    if grid.fits_agent(q) {
        *p = q;
    } else {
        *v = Vector2::zeros(); // blocked: choose again next tick
    }
}

/// [`step_or_stop`] eight particles at a time (`particles.len()` a multiple of 8): the new
/// points and their cells (the arithmetic of [`ClearanceGrid::cell_of`]) in vectors, on
/// the points as they lie in memory (x, y, x, y, …); the table look-up and the move, a
/// particle at a time.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn step_or_stop_avx2(
    grid: &ClearanceGrid,
    particles: &mut [Point2<f32>],
    steps: &mut [Vector2<f32>],
) {
    use std::arch::x86_64::*;
    const _: () = assert!(std::mem::size_of::<Point2<f32>>() == 8);
    const _: () = assert!(std::mem::size_of::<Vector2<f32>>() == 8);
    let cell = _mm256_set1_ps(grid.cell);
    let zero = _mm256_setzero_ps();
    let (cols, rows) = (grid.cols as i32, grid.rows.min(i32::MAX as usize) as i32);
    // x lanes against the columns, y lanes against the rows.
    let bounds = _mm256_setr_epi32(cols, rows, cols, rows, cols, rows, cols, rows);
    // A point's cell is row × columns + column: y lanes times the columns, x lanes once.
    let row_scale = _mm256_setr_epi32(1, cols, 1, cols, 1, cols, 1, cols);
    let minus_one = _mm256_set1_epi32(-1);
    for (ps, vs) in particles.chunks_exact_mut(4).zip(steps.chunks_exact_mut(4)) {
        // SAFETY: four points and four steps are eight contiguous floats each.
        let (p, v) = unsafe {
            (
                _mm256_loadu_ps(ps.as_ptr().cast::<f32>()),
                _mm256_loadu_ps(vs.as_ptr().cast::<f32>()),
            )
        };
        let q = _mm256_add_ps(p, v);
        // `cell_of`: both coordinates at least 0 (NaN fails), `(x / cell) as usize` below the
        // columns and likewise y. The conversion saturates where truncation overflows i32
        // (to i32::MIN, which the sign test below refuses, as `as usize` would fail the
        // bound).
        let nonneg = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_GE_OQ>(q, zero));
        let at = _mm256_cvttps_epi32(_mm256_div_ps(q, cell));
        let inside = _mm256_and_si256(
            _mm256_and_si256(nonneg, _mm256_cmpgt_epi32(at, minus_one)),
            _mm256_cmpgt_epi32(bounds, at),
        );
        // Both lanes of a point inside: each lane and its neighbour in the pair.
        let inside = _mm256_and_si256(inside, _mm256_shuffle_epi32::<0b10_11_00_01>(inside));
        let scaled = _mm256_mullo_epi32(at, row_scale);
        let index = _mm256_add_epi32(scaled, _mm256_shuffle_epi32::<0b10_11_00_01>(scaled));
        let mut moved = [0f32; 8];
        let mut cells = [0i32; 8];
        let mut ok = [0i32; 8];
        // SAFETY: unaligned stores of eight lanes into local arrays.
        unsafe {
            _mm256_storeu_ps(moved.as_mut_ptr(), q);
            _mm256_storeu_si256(cells.as_mut_ptr().cast(), index);
            _mm256_storeu_si256(ok.as_mut_ptr().cast(), inside);
        }
        for (k, (p, v)) in ps.iter_mut().zip(vs.iter_mut()).enumerate() {
            if ok[2 * k] != 0 && grid.agent_fits(cells[2 * k] as usize) {
                *p = Point2::new(moved[2 * k], moved[2 * k + 1]);
            } else {
                *v = Vector2::zeros();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Eight at a time and one at a time move and stop the same particles, to the bit: over
    /// a small room, with particles inside, on and past every edge of the grid,
    /// and steps from nothing to far out of it.
    #[test]
    fn eight_at_a_time_moves_exactly_as_one_at_a_time() {
        let arena = crate::sim::arena::open_room([6.0, 3.0, 0.0]);
        let g = &arena.grid;
        let (w, h) = (g.cols as f32 * g.cell, g.rows as f32 * g.cell);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut particles: Vec<Point2<f32>> = (0..4001)
            .map(|_| {
                Point2::new(
                    rng.random_range(-0.5..w + 0.5),
                    rng.random_range(-0.5..h + 0.5),
                )
            })
            .collect();
        let mut steps: Vec<Vector2<f32>> = (0..particles.len())
            .map(|k| match k % 5 {
                0 => Vector2::zeros(),
                1 => Vector2::new(rng.random_range(-1e9..1e9), rng.random_range(-1e9..1e9)),
                _ => Vector2::new(rng.random_range(-0.3..0.3), rng.random_range(-0.3..0.3)),
            })
            .collect();
        // Exactly on the grid's far edges and at the origin.
        particles[0] = Point2::new(w, 1.0);
        particles[1] = Point2::new(1.0, h);
        particles[2] = Point2::new(0.0, 0.0);
        steps[2] = Vector2::new(-0.0, 0.0);
        let (mut p1, mut v1) = (particles.clone(), steps.clone());
        step_or_stop(g, &mut particles, &mut steps);
        for (p, v) in p1.iter_mut().zip(v1.iter_mut()) {
            step_one(g, p, v);
        }
        let bits = |ps: &[Point2<f32>], vs: &[Vector2<f32>]| -> Vec<u32> {
            ps.iter()
                .zip(vs)
                .flat_map(|(p, v)| [p.x, p.y, v.x, v.y].map(f32::to_bits))
                .collect()
        };
        assert_eq!(bits(&particles, &steps), bits(&p1, &v1));
        let stopped = steps.iter().filter(|v| **v == Vector2::zeros()).count();
        assert!(
            stopped > 800 && stopped < 3000,
            "some stop, most move: {stopped}"
        );
    }
}
