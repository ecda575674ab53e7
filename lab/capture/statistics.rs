//! The statistics the studies report: medians, means with their confidence intervals, the
//! Mann–Whitney U test between two sets of runs and the Wilcoxon signed-rank test between two
//! sets of runs paired by seed.

/// Median, mean and the 95% confidence interval of the mean (normal approximation), with
/// runs that timed out counted at the time limit (so the mean is a lower bound for them).
pub(crate) fn stats(times: &[Option<f64>], limit: f64) -> (f64, f64, f64, f64) {
    let mut xs: Vec<f64> = times.iter().map(|t| t.unwrap_or(limit)).collect();
    let median = median(&mut xs);
    let (mean, half) = mean_ci(&xs);
    (median, mean, mean - half, mean + half)
}

/// Mean and the half-width of its 95% confidence interval (normal approximation).
pub(crate) fn mean_ci(xs: &[f64]) -> (f64, f64) {
    let n = xs.len().max(1) as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, 1.96 * (var / n).sqrt())
}

/// Two-sided p-value of the Mann–Whitney U test (normal approximation with tie correction).
pub fn mann_whitney_p(a: &[f64], b: &[f64]) -> f64 {
    let (n1, n2) = (a.len() as f64, b.len() as f64);
    if a.is_empty() || b.is_empty() {
        return f64::NAN;
    }
    let mut all: Vec<(f64, usize)> = a
        .iter()
        .map(|x| (*x, 0))
        .chain(b.iter().map(|x| (*x, 1)))
        .collect();
    all.sort_by(|x, y| x.0.total_cmp(&y.0));
    let mut ranks = vec![0.0; all.len()];
    let mut tie_term = 0.0;
    let mut i = 0;
    while i < all.len() {
        let mut j = i;
        while j + 1 < all.len() && all[j + 1].0 == all[i].0 {
            j += 1;
        }
        let rank = (i + j) as f64 / 2.0 + 1.0;
        ranks[i..=j].iter_mut().for_each(|r| *r = rank);
        let t = (j - i + 1) as f64;
        tie_term += t * t * t - t;
        i = j + 1;
    }
    let r1: f64 = all
        .iter()
        .zip(&ranks)
        .filter(|(x, _)| x.1 == 0)
        .map(|(_, r)| r)
        .sum();
    let u1 = r1 - n1 * (n1 + 1.0) / 2.0;
    let mu = n1 * n2 / 2.0;
    let n = n1 + n2;
    let sigma = (n1 * n2 / 12.0 * ((n + 1.0) - tie_term / (n * (n - 1.0)))).sqrt();
    if sigma == 0.0 {
        return 1.0;
    }
    let z = (u1 - mu).abs() / sigma;
    two_sided_p(z)
}

/// Two-sided p-value of the Wilcoxon signed-rank test of `a[i] − b[i]` (runs paired by seed:
/// the same starts and map, so the starts' spread, which dominates capture times, cancels).
/// Zero differences are dropped (Wilcoxon's rule), tied magnitudes share their mean rank and
/// the variance is corrected for them; normal approximation, as for Mann–Whitney: the studies
/// pair 100 runs or more.
pub fn wilcoxon_signed_rank_p(a: &[f64], b: &[f64]) -> f64 {
    if a.len() != b.len() || a.is_empty() {
        return f64::NAN;
    }
    let mut diffs: Vec<f64> = a
        .iter()
        .zip(b)
        .map(|(x, y)| x - y)
        .filter(|d| *d != 0.0)
        .collect();
    if diffs.is_empty() {
        return 1.0;
    }
    diffs.sort_by(|x, y| x.abs().total_cmp(&y.abs()));
    let n = diffs.len();
    let (mut positive_ranks, mut tie_term) = (0.0, 0.0);
    let mut i = 0;
    while i < n {
        let mut j = i;
        while j + 1 < n && diffs[j + 1].abs() == diffs[i].abs() {
            j += 1;
        }
        let rank = (i + j) as f64 / 2.0 + 1.0;
        positive_ranks += rank * diffs[i..=j].iter().filter(|d| **d > 0.0).count() as f64;
        let t = (j - i + 1) as f64;
        tie_term += t * t * t - t;
        i = j + 1;
    }
    let n = n as f64;
    let mu = n * (n + 1.0) / 4.0;
    let sigma = (n * (n + 1.0) * (2.0 * n + 1.0) / 24.0 - tie_term / 48.0).sqrt();
    if sigma == 0.0 {
        return 1.0;
    }
    let z = (positive_ranks - mu).abs() / sigma;
    two_sided_p(z)
}

/// The two-sided p-value of a standard normal statistic `z >= 0`: erfc(z / √2), from the tail
/// itself (libm's erfc), so that the p-values of large paired studies (1e-12, 1e-40) are
/// figures rather than the rounding error of 1 − Φ(z).
fn two_sided_p(z: f64) -> f64 {
    libm::erfc(z / std::f64::consts::SQRT_2).clamp(0.0, 1.0)
}

/// The longest a robot should stand still while hunting: a team that parks for longer is one
/// a person beats by waiting. Runs with a longer spell are counted.
const PARKED_S: f64 = 10.0;

/// The median and the longest of runs' longest spells of standing still (s), and how many
/// runs had one over [`PARKED_S`].
pub(crate) fn parked(spells: &[f64]) -> (f64, f64, usize) {
    let longest = spells.iter().copied().fold(0.0, f64::max);
    let over = spells.iter().filter(|s| **s > PARKED_S).count();
    (median(&mut spells.to_vec()), longest, over)
}

/// The median of `xs` (sorted in place); `NaN` for none.
pub(crate) fn median(xs: &mut [f64]) -> f64 {
    xs.sort_by(f64::total_cmp);
    match xs.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => xs[n / 2],
        n => (xs[n / 2 - 1] + xs[n / 2]) / 2.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mann_whitney_separates_shifted_samples_and_not_equal_ones() {
        let a: Vec<f64> = (0..50).map(|i| i as f64).collect();
        let b: Vec<f64> = (0..50).map(|i| i as f64 + 30.0).collect();
        assert!(mann_whitney_p(&a, &b) < 1e-6);
        assert!(mann_whitney_p(&a, &a) > 0.99);
        assert!((two_sided_p(1.959_964) - 0.05).abs() < 1e-7);
        // Far in the tail: erfc(10 / √2) = 1.523971e-23.
        assert!((two_sided_p(10.0) / 1.523_971e-23 - 1.0).abs() < 1e-5);
    }

    #[test]
    #[allow(clippy::approx_constant)] // a score of 3.14 in the data, not π
    fn wilcoxon_sees_a_small_shift_that_pairs_reveal_and_mann_whitney_does_not() {
        // Paired runs whose starts spread them widely; the second is 1 s slower in every pair
        // but one. Unpaired, the spread hides the shift; paired, it is plain.
        let a: Vec<f64> = (0..60).map(|i| 5.0 + i as f64).collect();
        let mut b: Vec<f64> = a.iter().map(|x| x + 1.0).collect();
        b[0] = a[0] - 1.0;
        assert!(mann_whitney_p(&a, &b) > 0.5);
        assert!(wilcoxon_signed_rank_p(&a, &b) < 1e-6);
        // Differences symmetric about zero: no evidence either way.
        let c: Vec<f64> = a
            .iter()
            .enumerate()
            .map(|(i, x)| if i % 2 == 0 { x + 1.0 } else { x - 1.0 })
            .collect();
        assert!(wilcoxon_signed_rank_p(&a, &c) > 0.9);
        assert_eq!(wilcoxon_signed_rank_p(&a, &a), 1.0);
        // Hollander and Wolfe's depression scores (R's `wilcox.test` example): W+ = 5 of 55,
        // z = 2.29, so the normal approximation's two-sided p is 0.022 (the exact one 0.039).
        let x = [1.83, 0.50, 1.62, 2.48, 1.68, 1.88, 1.55, 3.06, 1.30, 1.40];
        let y = [
            0.878, 0.647, 0.598, 2.05, 1.06, 1.29, 1.06, 3.14, 1.29, 0.70,
        ];
        let p = wilcoxon_signed_rank_p(&y, &x);
        assert!((0.0215..0.0225).contains(&p), "{p}");
    }

    #[test]
    fn stats_count_timeouts_at_the_limit() {
        let (median, mean, lo, hi) = stats(&[Some(10.0), Some(20.0), None], 300.0);
        assert_eq!(median, 20.0);
        assert!((mean - 110.0).abs() < 1e-9);
        assert!(lo < mean && mean < hi);
    }
}
