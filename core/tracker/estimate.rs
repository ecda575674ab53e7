//! Point estimates of the belief, for measuring it against the truth ([`super::gospa`]).
//!
//! A role stands for `count` opponents, each distributed as its cloud: they are
//! interchangeable draws from one distribution. So a role becomes `count` points that
//! summarise the cloud as `count` draws would spread over it: the weighted k-means
//! (Lloyd's) centres of its particles with k = `count`. For one opponent that is the cloud's
//! weighted mean, the estimate of least squared error. Repeating the mean `count` times
//! instead would put a role of several opponents on one spot: a prior over the whole map
//! for three opponents would score as three misses even when its cloud covers each of them,
//! and a merged role of two opponents a metre apart would place both between them.
//!
//! Tagged roles give no points: the opponents they stand for have left the arena, and the
//! truth to compare with is the opponents still in it. Deterministic (no randomness; a
//! deterministic initialisation), and bounded: k-means runs on at most [`KMEANS_POINTS`] points of
//! the cloud, drawn by systematic resampling.

use nalgebra::{Point2, Vector2};

use crate::tracker::Role;
use crate::tracker::gospa::{Gospa, Params, gospa};

/// Points of a cloud that k-means runs on (the cloud thinned by systematic resampling): 8
/// per centre for 16 opponents, and it bounds a round at 16 × 128 distances.
pub const KMEANS_POINTS: usize = 128;
/// Lloyd rounds at most. The first few move the centres most; over a uniform prior the
/// boundaries then creep for dozens more, for little gain, and a spectator's frame cannot
/// wait for them (20 rounds on 256 points took 150 µs for 20 opponents, 10 on 128 about a
/// quarter of that).
pub const KMEANS_ROUNDS: usize = 10;

/// The points the untagged roles put their opponents at: `count` per role.
pub fn belief_points(roles: &[Role]) -> Vec<Point2<f32>> {
    roles
        .iter()
        .filter(|r| !r.tagged)
        .flat_map(role_points)
        .collect()
}

/// GOSPA between the untagged roles' points and `truth`, the opponents still in the arena.
pub fn tracking_quality(roles: &[Role], truth: &[Point2<f32>], params: Params) -> Gospa {
    gospa(&belief_points(roles), truth, params)
}

/// `role.count` points: the weighted mean for one opponent, k-means centres for more.
pub fn role_points(role: &Role) -> Vec<Point2<f32>> {
    let k = role.count as usize;
    if k == 0 || role.particles.is_empty() {
        return Vec::new();
    }
    if k == 1 {
        return vec![weighted_mean(&role.particles, &role.weights)];
    }
    let sample = systematic(&role.particles, &role.weights, KMEANS_POINTS.max(k));
    k_means(&sample, k)
}

/// The weighted mean (the first particle when the weights are unusable).
fn weighted_mean(points: &[Point2<f32>], weights: &[f32]) -> Point2<f32> {
    let (mut sum, mut total) = (Vector2::<f64>::zeros(), 0.0f64);
    for (p, w) in points.iter().zip(weights) {
        let w = *w as f64;
        sum += Vector2::new(p.x as f64, p.y as f64) * w;
        total += w;
    }
    if total > 0.0 && total.is_finite() {
        Point2::new((sum.x / total) as f32, (sum.y / total) as f32)
    } else {
        points[0]
    }
}

/// `m` equally weighted points that represent the weighted cloud: systematic resampling
/// with a fixed offset of a half step (an even stride when the weights are unusable).
fn systematic(points: &[Point2<f32>], weights: &[f32], m: usize) -> Vec<Point2<f32>> {
    let total: f64 = weights.iter().map(|w| *w as f64).sum();
    if !(total > 0.0 && total.is_finite()) || weights.len() != points.len() {
        return (0..m)
            .map(|j| points[(j * points.len()) / m % points.len()])
            .collect();
    }
    let mut out = Vec::with_capacity(m);
    let mut cum = weights[0] as f64 / total;
    let mut i = 0;
    for j in 0..m {
        let u = (j as f64 + 0.5) / m as f64;
        while cum < u && i + 1 < points.len() {
            i += 1;
            cum += weights[i] as f64 / total;
        }
        out.push(points[i]);
    }
    out
}

/// Lloyd's k-means of equally weighted `points` into `k` centres. Initialised by
/// farthest-point traversal (the point nearest the mean, then each time the point farthest
/// from the centres so far; the first on ties), which spreads the centres over the cloud
/// without a random draw. A centre left with no points stays where it was; coinciding
/// points may leave centres on top of each other, which is right for a cloud on one spot.
fn k_means(points: &[Point2<f32>], k: usize) -> Vec<Point2<f32>> {
    let d2 = |a: &Point2<f32>, b: &Point2<f32>| (a - b).norm_squared();
    let mean = weighted_mean(points, &vec![1.0; points.len()]);
    let first = nearest(points.iter().map(|p| d2(p, &mean)));
    let mut centres = vec![points[first]];
    let mut to_centre: Vec<f32> = points.iter().map(|p| d2(p, &centres[0])).collect();
    while centres.len() < k {
        let far = (0..points.len()).fold(0, |best, i| {
            if to_centre[i] > to_centre[best] {
                i
            } else {
                best
            }
        });
        let c = points[far];
        centres.push(c);
        for (t, p) in to_centre.iter_mut().zip(points) {
            *t = t.min(d2(p, &c));
        }
    }
    let mut label = vec![usize::MAX; points.len()];
    for _ in 0..KMEANS_ROUNDS {
        let mut changed = false;
        for (l, p) in label.iter_mut().zip(points) {
            let best = nearest(centres.iter().map(|c| d2(p, c)));
            changed |= *l != best;
            *l = best;
        }
        if !changed {
            break;
        }
        let mut sums = vec![(Vector2::<f64>::zeros(), 0usize); k];
        for (l, p) in label.iter().zip(points) {
            sums[*l].0 += Vector2::new(p.x as f64, p.y as f64);
            sums[*l].1 += 1;
        }
        for (c, (sum, n)) in centres.iter_mut().zip(sums) {
            if n > 0 {
                *c = Point2::new((sum.x / n as f64) as f32, (sum.y / n as f64) as f32);
            }
        }
    }
    centres
}

/// The index of the smallest value (the first on ties).
fn nearest(values: impl Iterator<Item = f32>) -> usize {
    values
        .enumerate()
        .fold(
            (0, f32::INFINITY),
            |(bi, bv), (i, v)| {
                if v < bv { (i, v) } else { (bi, bv) }
            },
        )
        .0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn role(count: u32, particles: Vec<Point2<f32>>) -> Role {
        let mut r = Role {
            id: 0,
            count,
            tagged: false,
            particles: Vec::new(),
            weights: Vec::new(),
            steps: Vec::new(),
            unseen_run: 0,
            confidence: 0.0,
        };
        r.reset(particles);
        r
    }

    /// Three tight blobs, 100 particles each.
    fn three_blobs() -> Vec<Point2<f32>> {
        let centres = [(1.0, 1.0), (8.0, 2.0), (4.0, 9.0)];
        (0..300)
            .map(|i| {
                let (x, y) = centres[i / 100];
                let j = (i % 100) as f32;
                Point2::new(x + (j % 10.0) * 0.01, y + (j / 10.0).floor() * 0.01)
            })
            .collect()
    }

    #[test]
    fn one_opponent_is_the_weighted_mean() {
        let mut r = role(1, vec![Point2::new(0.0, 0.0), Point2::new(4.0, 0.0)]);
        r.weights = vec![0.75, 0.25];
        assert_eq!(role_points(&r), vec![Point2::new(1.0, 0.0)]);
    }

    /// A role of three opponents over three blobs puts one point on each: the mean repeated
    /// would put all three between them and miss every opponent.
    #[test]
    fn several_opponents_spread_over_the_cloud() {
        let r = role(3, three_blobs());
        let mut pts = role_points(&r);
        pts.sort_by(|a, b| a.x.total_cmp(&b.x));
        let expect = [(1.045, 1.045), (4.045, 9.045), (8.045, 2.045)];
        for (p, (x, y)) in pts.iter().zip(expect) {
            assert!((p - Point2::new(x, y)).norm() < 0.05, "{pts:?}");
        }
        let truth: Vec<Point2<f32>> = expect.iter().map(|&(x, y)| Point2::new(x, y)).collect();
        let g = tracking_quality(&[r], &truth, Params::default());
        assert_eq!((g.missed, g.false_targets), (0, 0));
        assert!(g.distance < 0.1, "{g:?}");
    }

    #[test]
    fn tagged_roles_give_no_points_and_a_cloud_on_one_spot_gives_count_points() {
        let mut tagged = role(1, vec![Point2::new(3.0, 3.0)]);
        tagged.tagged = true;
        let spot = role(2, vec![Point2::new(5.0, 5.0); 50]);
        let pts = belief_points(&[tagged, spot]);
        assert_eq!(pts, vec![Point2::new(5.0, 5.0); 2]);
    }
}
