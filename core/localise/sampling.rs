//! The resampler's tools: drawing from a cumulative sum in about one step, KLD-sampling's
//! bins and its particle count.

use std::hash::Hasher;

/// The first index of a non-decreasing cumulative sum whose value reaches `u`, in about one
/// step: a guide table (Chen and Asau's) holds, for each of as many equal slices of the sum
/// as there are entries, the first index reaching the slice's start; a search begins at the
/// slice before `u`'s and walks on. The answer is `partition_point(|c| c < u)`'s exactly (a
/// test compares them); a bisection per draw was about a twentieth of an update (`perf`).
pub(super) struct CumulativeSearch<'a> {
    cumulative: &'a [f64],
    guide: Vec<u32>,
    /// Slices per unit of the sum.
    scale: f64,
}

impl<'a> CumulativeSearch<'a> {
    pub(super) fn new(cumulative: &'a [f64]) -> CumulativeSearch<'a> {
        let n = cumulative.len();
        let total = cumulative.last().copied().unwrap_or(0.0);
        let scale = if total > 0.0 && total.is_finite() {
            n as f64 / total
        } else {
            0.0
        };
        let mut guide = Vec::with_capacity(n);
        let mut i = 0;
        for j in 0..n {
            let start = j as f64 / scale;
            while i < n && cumulative[i] < start {
                i += 1;
            }
            guide.push(i as u32);
        }
        CumulativeSearch {
            cumulative,
            guide,
            scale,
        }
    }

    pub(super) fn first_reaching(&self, u: f64) -> usize {
        let slice = (u * self.scale).floor();
        // The slice before `u`'s starts at or below `u` whatever the rounding (and a NaN or
        // a sum of zero starts at the beginning).
        let start = if slice >= 1.0 {
            let j = (slice as usize - 1).min(self.guide.len().saturating_sub(1));
            self.guide[j] as usize
        } else {
            0
        };
        let mut i = start;
        while i < self.cumulative.len() && self.cumulative[i] < u {
            i += 1;
        }
        i
    }
}

/// The hash of KLD-sampling's bins (FxHash's multiply and rotate). The standard SipHash
/// resists keys an adversary chooses, which bins of the filter's own particles are not, and
/// cost more than the rest of a particle's resampling; the set's answers (is this bin new?)
/// do not depend on the hash. Written here because the core depends on no hashing crate.
#[derive(Default)]
pub(super) struct BinHasher(u64);

impl Hasher for BinHasher {
    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.write_u64(*b as u64);
        }
    }

    fn write_i32(&mut self, v: i32) {
        self.write_u64(v as u32 as u64);
    }

    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x517c_c1b7_2722_0a95);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

/// KLD-sampling's particle count for `k` occupied bins (Fox 2003, eq. 12).
pub(super) fn kld_bound(k: usize, err: f64, z: f64) -> usize {
    if k <= 1 {
        return 1;
    }
    let k1 = (k - 1) as f64;
    let a = 2.0 / (9.0 * k1);
    let b = 1.0 - a + a.sqrt() * z;
    (k1 / (2.0 * err) * b * b * b).ceil() as usize
}
