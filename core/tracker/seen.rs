//! Negative information's test: which hypotheses a robot's scan would have seen. One
//! particle at a time ([`would_be_seen`], for any sighting), and a whole cloud's weights at
//! once ([`down_weight_seen`]), eight particles at a time with AVX2 where the CPU has it.
//! The eight-wide kernel computes exactly what the one-particle test does, operation for
//! operation in the same order (IEEE arithmetic is the same in a vector lane), so a match's
//! numbers do not depend on the CPU: a unit test holds the two to bit-identical weights.

use nalgebra::Point2;

use crate::sim::AGENT_RADIUS;
use crate::tracker::role::{LaserModel, Sighting};

/// Particles that a robot's scan would have seen: negative information.
/// `reach`: how far an opponent may have moved since the scan (0 for a fresh one). A
/// hypothesis at `p` is contradicted only if every point within `reach` of it was seen, so
/// that an opponent there now could not have stood outside the seen area then.
pub(super) fn would_be_seen(
    p: Point2<f32>,
    s: &Sighting,
    laser: LaserModel,
    cos: f32,
    sin: f32,
    reach: f32,
) -> bool {
    if s.scan.is_empty() {
        return false; // a robot frozen while sensing saw nothing
    }
    let dx = p.x - s.pose.pos.x;
    let dy = p.y - s.pose.pos.y;
    let d2 = dx * dx + dy * dy;
    let far = laser.range - reach;
    if far <= 0.0 || d2 > far * far {
        return false;
    }
    let forward = dx * cos + dy * sin;
    let lateral = -dx * sin + dy * cos;
    let half = laser.fov / 2.0;
    // Behind the robot, with a field of view of at most π: outside it, so the arctangent is
    // not needed. Exactly the answer the test below gives: there `fast_atan2` is at least
    // π/2 plus one rounding step once |forward| exceeds a millionth of |lateral| (nearer
    // the side, rounding could make it π/2 itself, so those go the long way).
    if half <= std::f32::consts::FRAC_PI_2 && forward < -1e-6 * lateral.abs() {
        return false;
    }
    let bearing = fast_atan2(lateral, forward);
    let d = d2.sqrt();
    // The bearings the disc of radius `reach` around `p` spans (all of them when it holds
    // the robot).
    let spread = if reach <= 0.0 {
        0.0
    } else if reach >= d {
        return false;
    } else {
        (reach / d).asin()
    };
    if bearing.abs() + spread > half {
        return false;
    }
    let n = s.scan.len();
    let beam_at = |b: f32| -> f32 {
        let i = (((b + half) / laser.fov) * (n - 1) as f32).round() as usize;
        s.scan[i.min(n - 1)]
    };
    let mut beam = beam_at(bearing);
    if spread > 0.0 {
        // Every beam across the disc must have reached past its far side.
        let beams = ((2.0 * spread / laser.fov) * (n - 1) as f32).ceil() as usize + 1;
        for k in 0..=beams {
            let b = bearing - spread + 2.0 * spread * k as f32 / beams as f32;
            beam = beam.min(beam_at(b));
        }
    }
    // An opponent centred at `p` would have stopped this beam at its near edge, d − R, and
    // been detected. So the beam reaching past d − R (with a margin for the laser's noise and
    // the beam not passing exactly through p) means nobody stands at `p`. Requiring the beam
    // to reach d + R instead would hide every hypothesis hugging a wall from negative
    // information for ever: robots would stare at an empty strip along a wall.
    d + reach < beam + AGENT_RADIUS - SEEN_MARGIN
}

/// Laser noise (3σ = 0.06 m), the bit a beam that passes a little off a particle's centre
/// meets the disc later (about 0.01 m), and some slack.
const SEEN_MARGIN: f32 = 0.1;

/// atan2 to within about 0.0015 rad (a beam is 0.017 rad wide), several times faster than libm.
pub(super) fn fast_atan2(y: f32, x: f32) -> f32 {
    use std::f32::consts::{FRAC_PI_2, PI};
    if x == 0.0 && y == 0.0 {
        return 0.0;
    }
    let (ax, ay) = (x.abs(), y.abs());
    let a = ax.min(ay) / ax.max(ay);
    let s = a * a;
    let mut r = ((-0.046_496_473 * s + 0.159_314_22) * s - 0.327_622_77) * s * a + a;
    if ay > ax {
        r = FRAC_PI_2 - r;
    }
    if x < 0.0 {
        r = PI - r;
    }
    if y < 0.0 { -r } else { r }
}

/// Multiplies by `p_miss` the weight of every particle of a cloud that `s` would have seen
/// ([`would_be_seen`] with this `reach`).
#[allow(clippy::too_many_arguments)] // the test's own inputs, plus the cloud and the factor
pub(super) fn down_weight_seen(
    particles: &[Point2<f32>],
    weights: &mut [f32],
    s: &Sighting,
    laser: LaserModel,
    cos: f32,
    sin: f32,
    reach: f32,
    p_miss: f32,
) {
    let n = particles.len().min(weights.len());
    let mut done = 0;
    // The kernel handles the common case, a robot's own fresh scan (no reach to spread
    // over); a teammate's late sighting takes the one-particle path.
    #[cfg(target_arch = "x86_64")]
    if reach == 0.0 && !s.scan.is_empty() && std::arch::is_x86_feature_detected!("avx2") {
        done = n - n % 8;
        // SAFETY: the CPU has AVX2 (checked above); the kernel reads the scan only at
        // indices it has clamped into it.
        unsafe {
            down_weight_seen_avx2(
                &particles[..done],
                &mut weights[..done],
                s,
                laser,
                cos,
                sin,
                p_miss,
            )
        };
    }
    for (p, w) in particles[done..n].iter().zip(&mut weights[done..n]) {
        if would_be_seen(*p, s, laser, cos, sin, reach) {
            *w *= p_miss;
        }
    }
}

/// [`down_weight_seen`] for a fresh sighting (`reach` 0) with a non-empty scan, eight
/// particles at a time (`particles.len()` a multiple of 8). Each step mirrors a line of
/// [`would_be_seen`]; where that returns early, the lane is masked off instead.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn down_weight_seen_avx2(
    particles: &[Point2<f32>],
    weights: &mut [f32],
    s: &Sighting,
    laser: LaserModel,
    cos: f32,
    sin: f32,
    p_miss: f32,
) {
    use std::arch::x86_64::*;
    use std::f32::consts::{FRAC_PI_2, PI};
    let far = laser.range;
    if far <= 0.0 {
        return; // nothing within reach: no particle was seen
    }
    let last = s.scan.len() - 1;
    let half = laser.fov / 2.0;
    let behind_skips = half <= FRAC_PI_2;
    let scan = s.scan.as_ptr();
    let (ox, oy) = (_mm256_set1_ps(s.pose.pos.x), _mm256_set1_ps(s.pose.pos.y));
    let far2 = _mm256_set1_ps(far * far);
    let (vcos, vsin) = (_mm256_set1_ps(cos), _mm256_set1_ps(sin));
    let vhalf = _mm256_set1_ps(half);
    let vfov = _mm256_set1_ps(laser.fov);
    let scale = _mm256_set1_ps(last as f32);
    let zero = _mm256_setzero_ps();
    let sign = _mm256_set1_ps(-0.0);
    let abs = |v: __m256| _mm256_andnot_ps(sign, v);
    let behind_factor = _mm256_set1_ps(-1e-6);
    let near_edge = _mm256_set1_ps(AGENT_RADIUS);
    let margin = _mm256_set1_ps(SEEN_MARGIN);
    let vmiss = _mm256_set1_ps(p_miss);
    let (c3, c2, c1) = (
        _mm256_set1_ps(-0.046_496_473),
        _mm256_set1_ps(0.159_314_22),
        _mm256_set1_ps(0.327_622_77),
    );
    let (quarter, halfturn) = (_mm256_set1_ps(FRAC_PI_2), _mm256_set1_ps(PI));
    let vlast = _mm256_set1_epi32(last as i32);
    let half_step = _mm256_set1_ps(0.5);
    // A point is two floats, x then y (nalgebra's points are `repr(C)` arrays).
    const _: () = assert!(std::mem::size_of::<Point2<f32>>() == 8);
    for (group, w) in particles.chunks_exact(8).zip(weights.chunks_exact_mut(8)) {
        // SAFETY: the group's eight points are sixteen contiguous floats (x0 y0 x1 y1 …),
        // read unaligned as two vectors.
        let (lo, hi) = unsafe {
            let at = group.as_ptr().cast::<f32>();
            (_mm256_loadu_ps(at), _mm256_loadu_ps(at.add(8)))
        };
        // Even floats to x, odd to y: the shuffle leaves x0 x1 x4 x5 x2 x3 x6 x7, and the
        // permutation puts the pairs in order.
        let unzip = |v: __m256| {
            _mm256_castpd_ps(_mm256_permute4x64_pd::<0b11_01_10_00>(_mm256_castps_pd(v)))
        };
        let x = unzip(_mm256_shuffle_ps::<0b10_00_10_00>(lo, hi));
        let y = unzip(_mm256_shuffle_ps::<0b11_01_11_01>(lo, hi));
        let dx = _mm256_sub_ps(x, ox);
        let dy = _mm256_sub_ps(y, oy);
        let d2 = _mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy));
        // `d2 > far²` returns false: keep the lanes where it does not hold (NaN included).
        let mut live = _mm256_cmp_ps::<_CMP_NGT_UQ>(d2, far2);
        if _mm256_movemask_ps(live) == 0 {
            continue; // the whole group is out of reach: the common case
        }
        let forward = _mm256_add_ps(_mm256_mul_ps(dx, vcos), _mm256_mul_ps(dy, vsin));
        // −dx·sin + dy·cos: adding a negated product is subtracting it, bit for bit.
        let lateral = _mm256_sub_ps(_mm256_mul_ps(dy, vcos), _mm256_mul_ps(dx, vsin));
        if behind_skips {
            let behind =
                _mm256_cmp_ps::<_CMP_LT_OQ>(forward, _mm256_mul_ps(behind_factor, abs(lateral)));
            live = _mm256_andnot_ps(behind, live);
        }
        // fast_atan2(lateral, forward).
        let (ax, ay) = (abs(forward), abs(lateral));
        let a = _mm256_div_ps(_mm256_min_ps(ax, ay), _mm256_max_ps(ax, ay));
        let sq = _mm256_mul_ps(a, a);
        let poly = _mm256_sub_ps(
            _mm256_mul_ps(_mm256_add_ps(_mm256_mul_ps(c3, sq), c2), sq),
            c1,
        );
        let r = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(poly, sq), a), a);
        let r = _mm256_blendv_ps(
            r,
            _mm256_sub_ps(quarter, r),
            _mm256_cmp_ps::<_CMP_GT_OQ>(ay, ax),
        );
        let r = _mm256_blendv_ps(
            r,
            _mm256_sub_ps(halfturn, r),
            _mm256_cmp_ps::<_CMP_LT_OQ>(forward, zero),
        );
        let r = _mm256_blendv_ps(
            r,
            _mm256_xor_ps(r, sign),
            _mm256_cmp_ps::<_CMP_LT_OQ>(lateral, zero),
        );
        let origin = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_EQ_OQ>(forward, zero),
            _mm256_cmp_ps::<_CMP_EQ_OQ>(lateral, zero),
        );
        let bearing = _mm256_andnot_ps(origin, r);
        // `|bearing| + 0 > half` returns false.
        live = _mm256_and_ps(live, _mm256_cmp_ps::<_CMP_NGT_UQ>(abs(bearing), vhalf));
        // The beam at the bearing: round(((bearing + half) / fov) · (n − 1)), rounding half
        // away from zero as `f32::round` does (the index is never negative in a live lane,
        // and `x − trunc(x)` is exact), clamped into the scan.
        let at = _mm256_mul_ps(_mm256_div_ps(_mm256_add_ps(bearing, vhalf), vfov), scale);
        let whole = _mm256_cvttps_epi32(at);
        let up =
            _mm256_cmp_ps::<_CMP_GE_OQ>(_mm256_sub_ps(at, _mm256_cvtepi32_ps(whole)), half_step);
        // An all-ones lane is −1: subtracting it adds one.
        let i = _mm256_sub_epi32(whole, _mm256_castps_si256(up));
        let i = _mm256_min_epi32(_mm256_max_epi32(i, _mm256_setzero_si256()), vlast);
        // SAFETY: every index is clamped into the scan, and dead lanes read nothing.
        let beam = unsafe { _mm256_mask_i32gather_ps::<4>(zero, scan, i, live) };
        let d = _mm256_sqrt_ps(d2);
        let reached =
            _mm256_cmp_ps::<_CMP_LT_OQ>(d, _mm256_sub_ps(_mm256_add_ps(beam, near_edge), margin));
        let seen = _mm256_and_ps(live, reached);
        // SAFETY: unaligned load and store of eight weights from this group's slice.
        unsafe {
            let wv = _mm256_loadu_ps(w.as_ptr());
            let wv = _mm256_blendv_ps(wv, _mm256_mul_ps(wv, vmiss), seen);
            _mm256_storeu_ps(w.as_mut_ptr(), wv);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::Pose;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The batch (eight-wide where the CPU allows) and the one-particle test give the same
    /// weights bit for bit: over random scans, poses and fields of view (π, wider, all
    /// round), with particles everywhere from the robot's own position to past the laser's
    /// reach, on the field of view's edges and right behind.
    #[test]
    fn the_batch_down_weights_exactly_what_the_one_particle_test_sees() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut seen_any = 0;
        for round in 0..200 {
            let fov = [std::f32::consts::PI, 4.7, std::f32::consts::TAU][round % 3];
            let laser = LaserModel { fov, range: 8.0 };
            let beams = [181, 30, 2][(round / 3) % 3];
            let scan: Vec<f32> = (0..beams).map(|_| rng.random_range(0.1..9.0)).collect();
            let pose = Pose::new(
                rng.random_range(0.0..20.0),
                rng.random_range(0.0..20.0),
                rng.random_range(-4.0..4.0),
            );
            let s = Sighting {
                pose,
                scan: &scan,
                detections: &[],
                tagged: false,
                age_ticks: 0,
            };
            let (cos, sin) = (pose.theta.cos(), pose.theta.sin());
            let mut particles: Vec<Point2<f32>> = (0..1003)
                .map(|_| {
                    let r = rng.random_range(0.0..10.0f32);
                    let a = rng.random_range(-4.0..4.0f32);
                    pose.pos + nalgebra::Vector2::new(r * a.cos(), r * a.sin())
                })
                .collect();
            // The robot's own position, straight behind it and on the edges of its view.
            particles[0] = pose.pos;
            for (k, a) in [std::f32::consts::PI, fov / 2.0, -fov / 2.0]
                .iter()
                .enumerate()
            {
                let b = pose.theta + a;
                particles[1 + k] = pose.pos + nalgebra::Vector2::new(2.0 * b.cos(), 2.0 * b.sin());
            }
            let mut batch: Vec<f32> = (0..particles.len()).map(|_| rng.random()).collect();
            let mut one = batch.clone();
            down_weight_seen(&particles, &mut batch, &s, laser, cos, sin, 0.0, 0.05);
            for (p, w) in particles.iter().zip(&mut one) {
                if would_be_seen(*p, &s, laser, cos, sin, 0.0) {
                    *w *= 0.05;
                    seen_any += 1;
                }
            }
            let batch: Vec<u32> = batch.iter().map(|w| w.to_bits()).collect();
            let one: Vec<u32> = one.iter().map(|w| w.to_bits()).collect();
            assert_eq!(
                batch, one,
                "round {round}: fov {fov}, {beams} beams, {pose:?}"
            );
        }
        assert!(seen_any > 10_000, "the test must see particles: {seen_any}");
    }
}
