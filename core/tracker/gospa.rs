//! Tracking quality: the GOSPA metric (Generalized Optimal Sub-Pattern Assignment;
//! Rahmathullah, García-Fernández and Svensson, 2017) between the points the team believes
//! opponents are at and where they are.
//!
//! Why GOSPA: the filters and capture experiments count roles and time to tag, neither of
//! which says how close the belief is to the truth. GOSPA does, for sets of different sizes,
//! and splits into parts one can read: how far the matched estimates are (localisation),
//! how many opponents no estimate is near (missed) and how many estimates no opponent is
//! near (false). With α = 2 (the only α with that split), cut-off `c` and order `p`:
//!
//! ```text
//! d(X, Y)^p = min over assignments γ of  Σ_{(x,y)∈γ} d(x,y)^p + c^p/2 · (|X| + |Y| − 2|γ|)
//! ```
//!
//! where each assigned pair is nearer than `c`. Equivalently, with `m = min(|X|, |Y|)` and
//! `n = max(|X|, |Y|)`: the best one-to-one matching of the smaller set into the larger under
//! the cost `min(d, c)^p`, plus `c^p/2` per point of the larger set left over (a pair at `c`
//! or farther costs `c^p`, a miss and a false target). That matching is exact: the Hungarian
//! algorithm below, O(m²n), tiny for a team's at most 16 opponents. Pure: no randomness.
//!
//! Turning a role's cloud into points is [`super::estimate`]'s job.

use nalgebra::Point2;

/// Cut-off and order of the metric (α is 2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Params {
    /// Cut-off in metres (> 0): the most an estimate may be off and still count as finding
    /// its opponent; a miss or a false target costs `c^p / 2`.
    pub c: f32,
    /// Order, at least 1 (the triangle inequality needs it): how much large errors
    /// outweigh small ones.
    pub p: f32,
}

/// `c` = 2 m: an estimate within 2 m of an opponent sends a robot to look where the opponent
/// is in view (the laser reaches 8 m, the tag device 6 m); 2 m is also what an opponent walks
/// in 2 s, so a cloud that lags a runner by a few ticks still finds it. Farther off, the
/// estimate is as good as none. `p` = 2: large errors weigh more than small ones, and the
/// localisation part reads as a root-sum-square error in metres.
impl Default for Params {
    fn default() -> Self {
        Params { c: 2.0, p: 2.0 }
    }
}

/// The metric and its split: `distance^p = localisation^p + c^p/2 · (missed + false_targets)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gospa {
    /// The GOSPA distance (metres).
    pub distance: f32,
    /// `(Σ d^p)^(1/p)` over the assigned pairs (each nearer than `c`), metres.
    pub localisation: f32,
    /// True points no estimate was assigned to.
    pub missed: usize,
    /// Estimates assigned to no true point.
    pub false_targets: usize,
}

impl Gospa {
    /// Zero: both sets empty, or every estimate exactly on its opponent.
    pub const ZERO: Gospa = Gospa {
        distance: 0.0,
        localisation: 0.0,
        missed: 0,
        false_targets: 0,
    };
}

/// GOSPA between `estimates` and `truth` (α = 2): see the module docs. Symmetric in its
/// arguments except that `missed` and `false_targets` swap.
pub fn gospa(estimates: &[Point2<f32>], truth: &[Point2<f32>], params: Params) -> Gospa {
    debug_assert!(params.c > 0.0 && params.p >= 1.0, "{params:?}");
    let (c, p) = (params.c as f64, params.p as f64);
    let cp = c.powf(p);
    // Rows: the smaller set, so every row is matched to a distinct column.
    let swapped = estimates.len() > truth.len();
    let (rows, cols) = if swapped {
        (truth, estimates)
    } else {
        (estimates, truth)
    };
    let dist = |a: &Point2<f32>, b: &Point2<f32>| {
        let (dx, dy) = (a.x as f64 - b.x as f64, a.y as f64 - b.y as f64);
        dx.hypot(dy)
    };
    let cost: Vec<f64> = rows
        .iter()
        .flat_map(|r| cols.iter().map(move |q| dist(r, q).min(c).powf(p)))
        .collect();
    let matched = assign(&cost, rows.len(), cols.len());
    let (mut local, mut pairs) = (0.0f64, 0usize);
    for (i, &j) in matched.iter().enumerate() {
        let d = dist(&rows[i], &cols[j]);
        // A pair at the cut-off costs the same as a miss and a false target: count it so.
        if d < c {
            local += d.powf(p);
            pairs += 1;
        }
    }
    let missed = truth.len() - pairs;
    let false_targets = estimates.len() - pairs;
    let total = local + cp / 2.0 * (missed + false_targets) as f64;
    Gospa {
        distance: total.powf(1.0 / p) as f32,
        localisation: local.powf(1.0 / p) as f32,
        missed,
        false_targets,
    }
}

/// The cheapest assignment of each of `n` rows to a distinct one of `m ≥ n` columns under
/// `cost` (row-major, `n × m`, finite): `result[row] = column`. The Hungarian algorithm in
/// its shortest-augmenting-path form with potentials (Kuhn–Munkres as improved by Jonker and
/// Volgenant): each row is added along the cheapest path in reduced costs, O(n²m) in all.
pub fn assign(cost: &[f64], n: usize, m: usize) -> Vec<usize> {
    assert!(n <= m && cost.len() == n * m, "{n} rows, {m} columns");
    // 1-based, with row 0 / column 0 the virtual start of each augmenting path.
    let mut u = vec![0.0f64; n + 1]; // row potentials
    let mut v = vec![0.0f64; m + 1]; // column potentials
    let mut row_of = vec![0usize; m + 1]; // the row each column holds (0: none)
    let mut way = vec![0usize; m + 1]; // the column before this one on the path
    for i in 1..=n {
        row_of[0] = i;
        let mut j0 = 0;
        let mut min_to = vec![f64::INFINITY; m + 1];
        let mut used = vec![false; m + 1];
        loop {
            used[j0] = true;
            let i0 = row_of[j0];
            let (mut delta, mut j1) = (f64::INFINITY, 0);
            for j in 1..=m {
                if used[j] {
                    continue;
                }
                let reduced = cost[(i0 - 1) * m + (j - 1)] - u[i0] - v[j];
                if reduced < min_to[j] {
                    min_to[j] = reduced;
                    way[j] = j0;
                }
                if min_to[j] < delta {
                    delta = min_to[j];
                    j1 = j;
                }
            }
            for j in 0..=m {
                if used[j] {
                    u[row_of[j]] += delta;
                    v[j] -= delta;
                } else {
                    min_to[j] -= delta;
                }
            }
            j0 = j1;
            if row_of[j0] == 0 {
                break;
            }
        }
        // Flip the path: every column on it takes the row of the column before it.
        while j0 != 0 {
            let j1 = way[j0];
            row_of[j0] = row_of[j1];
            j0 = j1;
        }
    }
    let mut result = vec![0; n];
    for j in 1..=m {
        if row_of[j] != 0 {
            result[row_of[j] - 1] = j - 1;
        }
    }
    result
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn pt(x: f32, y: f32) -> Point2<f32> {
        Point2::new(x, y)
    }

    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() < 1e-5
    }

    const P: Params = Params { c: 2.0, p: 2.0 };

    #[test]
    fn two_empty_sets_are_at_zero() {
        assert_eq!(gospa(&[], &[], P), Gospa::ZERO);
    }

    /// No estimates: every opponent missed, each costing c^p/2 = 2, so √(3·2).
    #[test]
    fn no_estimates_misses_every_opponent() {
        let truth = [pt(0.0, 0.0), pt(5.0, 5.0), pt(9.0, 1.0)];
        let g = gospa(&[], &truth, P);
        assert_eq!((g.missed, g.false_targets), (3, 0));
        assert!(
            close(g.distance, 6f32.sqrt()) && g.localisation == 0.0,
            "{g:?}"
        );
    }

    /// Estimates and nobody left: every estimate false.
    #[test]
    fn estimates_of_nobody_are_all_false() {
        let g = gospa(&[pt(1.0, 1.0), pt(2.0, 2.0)], &[], P);
        assert_eq!((g.missed, g.false_targets), (0, 2));
        assert!(close(g.distance, 2.0), "{g:?}"); // √(2·2)
    }

    /// One to one, within the cut-off: pairs (0.3 m, 0.4 m) → √(0.09 + 0.16) = 0.5; the
    /// crossed pairing would cost far more.
    #[test]
    fn one_to_one_takes_the_best_pairing() {
        let est = [pt(0.3, 0.0), pt(10.0, 0.4)];
        let truth = [pt(10.0, 0.0), pt(0.0, 0.0)];
        let g = gospa(&est, &truth, P);
        assert_eq!((g.missed, g.false_targets), (0, 0));
        assert!(
            close(g.distance, 0.5) && close(g.localisation, 0.5),
            "{g:?}"
        );
    }

    /// Beyond the cut-off an estimate finds nobody: 3 m and 30 m off both cost c^p (one miss,
    /// one false), so the distance saturates at c·√n however far off.
    #[test]
    fn errors_saturate_at_the_cut_off() {
        let truth = [pt(0.0, 0.0)];
        let near = gospa(&[pt(3.0, 0.0)], &truth, P);
        let far = gospa(&[pt(30.0, 0.0)], &truth, P);
        assert_eq!(near, far);
        assert_eq!((near.missed, near.false_targets), (1, 1));
        assert!(
            close(near.distance, 2.0) && near.localisation == 0.0,
            "{near:?}"
        );
        // Just inside the cut-off it is a localisation error.
        let inside = gospa(&[pt(1.9, 0.0)], &truth, P);
        assert_eq!((inside.missed, inside.false_targets), (0, 0));
        assert!(close(inside.distance, 1.9), "{inside:?}");
    }

    /// Mixed: one estimate 1 m off its opponent, one opponent nobody is near and one estimate
    /// far from everyone: 1² + c²/2 + c²/2 = 5, so √5.
    #[test]
    fn a_mixed_case_splits_into_its_parts() {
        let est = [pt(1.0, 0.0), pt(20.0, 20.0)];
        let truth = [pt(0.0, 0.0), pt(10.0, 0.0)];
        let g = gospa(&est, &truth, P);
        assert_eq!((g.missed, g.false_targets), (1, 1));
        assert!(
            close(g.localisation, 1.0) && close(g.distance, 5f32.sqrt()),
            "{g:?}"
        );
        // Order 1: 1 + 1 + 1.
        let g1 = gospa(&est, &truth, Params { c: 2.0, p: 1.0 });
        assert!(close(g1.distance, 3.0), "{g1:?}");
    }

    /// More estimates than opponents: the extra one is false, and the swap of the arguments
    /// swaps missed and false only.
    #[test]
    fn unequal_sizes_leave_the_extra_points_over() {
        let est = [pt(0.0, 0.0), pt(0.0, 0.5), pt(8.0, 8.0)];
        let truth = [pt(0.0, 0.1), pt(8.0, 8.2)];
        let g = gospa(&est, &truth, P);
        assert_eq!((g.missed, g.false_targets), (0, 1));
        let h = gospa(&truth, &est, P);
        assert_eq!((h.missed, h.false_targets), (1, 0));
        assert!(close(g.distance, h.distance));
        assert!(close(g.localisation, (0.01f32 + 0.04).sqrt()), "{g:?}");
    }

    /// Every permutation of `cols` columns taken `rows` at a time: the brute-force optimum.
    fn brute_force(cost: &[f64], rows: usize, cols: usize) -> f64 {
        fn go(cost: &[f64], cols: usize, row: usize, rows: usize, used: &mut [bool]) -> f64 {
            if row == rows {
                return 0.0;
            }
            let mut best = f64::INFINITY;
            for j in 0..cols {
                if !used[j] {
                    used[j] = true;
                    let c = cost[row * cols + j] + go(cost, cols, row + 1, rows, used);
                    best = best.min(c);
                    used[j] = false;
                }
            }
            best
        }
        go(cost, cols, 0, rows, &mut vec![false; cols])
    }

    fn points(max: usize) -> impl Strategy<Value = Vec<Point2<f32>>> {
        proptest::collection::vec((0.0f32..6.0, 0.0f32..6.0), 0..=max)
            .prop_map(|v| v.into_iter().map(|(x, y)| pt(x, y)).collect())
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

        #[test]
        fn the_assignment_is_optimal(
            rows in 1usize..5,
            extra in 0usize..3,
            values in proptest::collection::vec(0.0f64..10.0, 7 * 7),
        ) {
            let cols = rows + extra;
            let cost: Vec<f64> = values[..rows * cols].to_vec();
            let a = assign(&cost, rows, cols);
            let mut seen = vec![false; cols];
            for &j in &a {
                prop_assert!(!seen[j], "column {} used twice", j);
                seen[j] = true;
            }
            let total: f64 = a.iter().enumerate().map(|(i, &j)| cost[i * cols + j]).sum();
            prop_assert!((total - brute_force(&cost, rows, cols)).abs() < 1e-9);
        }

        /// A metric: identity, symmetry, triangle inequality (on small sets, a 6 m square so
        /// that both sides of the cut-off occur), for orders 1 and 2.
        #[test]
        fn gospa_is_a_metric(
            x in points(4),
            y in points(4),
            z in points(4),
            p in prop_oneof![Just(1.0f32), Just(2.0f32)],
        ) {
            let params = Params { c: 2.0, p };
            let d = |a: &[Point2<f32>], b: &[Point2<f32>]| gospa(a, b, params).distance;
            prop_assert_eq!(d(&x, &x), 0.0);
            prop_assert!((d(&x, &y) - d(&y, &x)).abs() < 1e-5);
            if d(&x, &y) == 0.0 {
                let sorted = |s: &[Point2<f32>]| {
                    let mut v: Vec<(f32, f32)> = s.iter().map(|q| (q.x, q.y)).collect();
                    v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
                    v
                };
                prop_assert_eq!(sorted(&x), sorted(&y));
            }
            prop_assert!(d(&x, &z) <= d(&x, &y) + d(&y, &z) + 1e-4,
                "d(x,z) {} > d(x,y) {} + d(y,z) {}", d(&x, &z), d(&x, &y), d(&y, &z));
        }
    }
}
