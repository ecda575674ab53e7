//! Robot self-localisation: Monte Carlo localisation (a particle filter over the robot's own
//! pose) from noisy odometry, a subset of the laser's beams and landmark sightings.
//!
//! The model follows AMCL (Thrun, Burgard & Fox, *Probabilistic Robotics*, ch. 5–8):
//! - motion: the odometry motion model (rotate, translate, rotate) with noise α1..α4;
//! - laser: the likelihood-field model, a Gaussian of the distance from a beam's end point to
//!   the nearest wall mixed with a uniform "random reading" term (beams at maximum range are
//!   skipped; opponents and teammates in the way are what the random term absorbs);
//! - landmarks: range and bearing to a landmark known by identity;
//! - resampling: KLD-sampling picks the particle count (between `min_particles` and
//!   `max_particles`), augmented MCL (w_slow / w_fast) injects random particles when the
//!   measurements stop fitting, so a kidnapped robot recovers. Injected particles are drawn
//!   half uniformly over free space and half from the poses a landmark sighting allows.
//!
//! Pure core: no clock, no I/O; all randomness comes from the caller's RNG.

pub mod dead_reckoning;
mod likelihood_field;
mod sampling;
mod tuning;

pub use likelihood_field::LikelihoodField;
pub use tuning::Settings;

use sampling::{BinHasher, CumulativeSearch, kld_bound};

use std::collections::HashSet;
use std::hash::BuildHasherDefault;
use std::sync::Arc;

use nalgebra::{Point2, Vector2};
use rand::RngExt;

use crate::sim::arena::Arena;
use crate::sim::sensors::{Detection, LandmarkSighting, OdometryStep, beam_bearing};
use crate::sim::{AGENT_RADIUS, Pose, gaussian, wrap_angle};

/// What a robot senses for one measurement update.
#[derive(Debug, Clone, Copy)]
pub struct Observation<'a> {
    /// The full scan; `laser_range` means no return.
    pub ranges: &'a [f32],
    pub laser_fov: f32,
    pub laser_range: f32,
    pub landmarks: &'a [LandmarkSighting],
    /// Agents the robot knows are in view but not on the map (detected opponents, and
    /// teammates where their estimates say they are), as range and bearing from the robot.
    /// Beams that end on one are skipped: the likelihood field would read a wall there, and
    /// an opponent up close blocking half the beams let a stray particle outscore the truth.
    pub movers: &'a [Detection],
}

/// Odometry changes below this (m and rad) are no motion.
const STILL: f32 = 1e-5;

/// Extra angle and range (rad, m) around a mover inside which a beam counts as ending on it:
/// a teammate's position is only known as well as the two estimates.
const MOVER_MARGIN: f32 = 0.15;

/// Indices of the beams a measurement update uses: about `wanted` evenly spread, returning
/// something, and not ending on a known mover.
fn used_beams(obs: &Observation, wanted: usize) -> impl Iterator<Item = usize> {
    // No beams wanted: a robot that localises from landmarks (and odometry) alone.
    let n = if wanted == 0 { 0 } else { obs.ranges.len() };
    (0..n).step_by(beam_step(n, wanted)).filter(move |&i| {
        let r = obs.ranges[i];
        if r >= obs.laser_range {
            return false;
        }
        let b = beam_bearing(i, n, obs.laser_fov);
        !obs.movers.iter().any(|m| {
            let half = ((AGENT_RADIUS + MOVER_MARGIN) / m.range.max(1e-3))
                .min(1.0)
                .asin();
            wrap_angle(b - m.bearing).abs() <= half && r <= m.range + AGENT_RADIUS + MOVER_MARGIN
        })
    })
}

/// One robot's particle filter.
#[derive(Debug, Clone)]
pub struct Localiser {
    settings: Settings,
    field: Arc<LikelihoodField>,
    landmarks: Vec<Point2<f32>>,
    particles: Vec<Pose>,
    weights: Vec<f64>,
    w_slow: f64,
    w_fast: f64,
    /// The latest odometry reading.
    last_odom: Pose,
    /// The odometry reading the particles were last moved to. As in AMCL, particles move
    /// only before a measurement update, by the whole odometry change since the last one:
    /// moving hundreds of particles with fresh noise at every tick was a fifth of a tick.
    particles_odom: Pose,
    moved_since_update: (f32, f32),
    calls_since_update: u32,
    estimate: Pose,
    spread: f32,
}

impl Localiser {
    /// A cloud around `start` (the team knows where each robot starts); `odom` is the
    /// robot's odometry reading at that moment.
    pub fn new(
        field: Arc<LikelihoodField>,
        arena: &Arena,
        settings: Settings,
        start: Pose,
        odom: Pose,
        rng: &mut impl RngExt,
    ) -> Localiser {
        let n = settings.max_particles.max(1);
        let particles: Vec<Pose> = (0..n)
            .map(|_| {
                Pose::new(
                    start.pos.x + gaussian(rng, settings.init_sigma_xy),
                    start.pos.y + gaussian(rng, settings.init_sigma_xy),
                    wrap_angle(start.theta + gaussian(rng, settings.init_sigma_theta)),
                )
            })
            .collect();
        let mut l = Localiser {
            weights: vec![1.0 / n as f64; n],
            particles,
            field,
            landmarks: arena.def.landmarks.clone(),
            settings,
            w_slow: 0.0,
            w_fast: 0.0,
            last_odom: odom,
            particles_odom: odom,
            moved_since_update: (0.0, 0.0),
            calls_since_update: 0,
            estimate: start,
            spread: 0.0,
        };
        l.summarise();
        l
    }

    pub fn particles(&self) -> &[Pose] {
        &self.particles
    }

    /// The point estimate: the weighted mean pose (circular mean for the heading) at the
    /// last measurement update, moved on by odometry since.
    pub fn estimate(&self) -> Pose {
        self.estimate
    }

    /// Standard deviation of the particles' positions (m).
    pub fn spread(&self) -> f32 {
        self.spread
    }

    /// Takes in the odometry reading of this tick. The estimate follows it at once (noiseless);
    /// the particles follow it, with the motion model's noise, at the next measurement update.
    pub fn predict(&mut self, odom: Pose) {
        let prev = self.last_odom;
        self.last_odom = odom;
        let Some(step) = OdometryStep::between(prev, odom, STILL) else {
            return;
        };
        self.moved_since_update.0 += step.trans.abs();
        self.moved_since_update.1 += wrap_angle(odom.theta - prev.theta).abs();
        // The estimate moves by the noiseless odometry rather than being re-averaged: the
        // cloud may hold freshly injected particles that no measurement has weighed yet.
        self.estimate = step.apply(self.estimate);
    }

    /// Moves every particle by the odometry change since they last moved (odometry motion
    /// model, Probabilistic Robotics table 5.6, in std-dev form).
    fn move_particles(&mut self, rng: &mut impl RngExt) {
        let from = self.particles_odom;
        self.particles_odom = self.last_odom;
        let Some(step) = OdometryStep::between(from, self.last_odom, STILL) else {
            return;
        };
        let OdometryStep { rot1, trans, rot2 } = step;
        let [a1, a2, a3, a4] = self.settings.alpha;
        let s_rot1 = a1 * rot1.abs() + a2 * trans.abs();
        let s_trans = a3 * trans.abs() + a4 * (rot1.abs() + rot2.abs());
        let s_rot2 = a1 * rot2.abs() + a2 * trans.abs();
        for p in &mut self.particles {
            let noisy = OdometryStep {
                rot1: rot1 + gaussian(rng, s_rot1),
                trans: trans + gaussian(rng, s_trans),
                rot2: rot2 + gaussian(rng, s_rot2),
            };
            *p = noisy.apply(*p);
        }
    }

    /// `p` carried on by the odometry the particles have not moved by yet, without noise:
    /// where a particle would be drawn now (the cloud spectators see).
    pub fn carried(&self, p: Pose) -> Pose {
        OdometryStep::between(self.particles_odom, self.last_odom, STILL).map_or(p, |s| s.apply(p))
    }

    /// Moves the particles by the odometry since they last moved, weighs them by what the
    /// robot senses and resamples. Skipped while the robot has barely moved (as AMCL does),
    /// except every `update_every` calls.
    pub fn correct(&mut self, obs: &Observation, rng: &mut impl RngExt) {
        self.calls_since_update += 1;
        let (md, ma) = self.moved_since_update;
        if md < self.settings.update_min_d
            && ma < self.settings.update_min_a
            && self.calls_since_update < self.settings.update_every
        {
            return;
        }
        if obs.ranges.is_empty() && obs.landmarks.is_empty() {
            return; // a frozen robot senses nothing
        }
        self.moved_since_update = (0.0, 0.0);
        self.calls_since_update = 0;
        self.move_particles(rng);
        let n_obs = self.observation_count(obs);
        if n_obs == 0 {
            // Nothing to weigh (no beam used, no landmark in view: a robot localising from
            // landmarks alone, between landmarks). The cloud spreads by the motion and that is
            // all: an "average likelihood" of 1 here would be the best fit possible, and the
            // next real measurement would look like a kidnapping and inject random particles.
            self.summarise();
            return;
        }
        let log_w = self.log_weights(obs);
        let max = log_w.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if !max.is_finite() {
            return;
        }
        // Average per-observation likelihood (geometric mean over beams) for augmented MCL,
        // so that it does not depend on how many beams returned.
        let n_obs = n_obs as f64;
        let w_avg = log_w.iter().map(|l| (l / n_obs).exp()).sum::<f64>() / log_w.len() as f64;
        if self.w_slow == 0.0 {
            self.w_slow = w_avg;
            self.w_fast = w_avg;
        } else {
            self.w_slow += self.settings.alpha_slow * (w_avg - self.w_slow);
            self.w_fast += self.settings.alpha_fast * (w_avg - self.w_fast);
        }
        for (w, l) in self.weights.iter_mut().zip(&log_w) {
            *w *= (l - max).exp();
        }
        let total: f64 = self.weights.iter().sum();
        if total.is_nan() || total <= 0.0 {
            let n = self.weights.len() as f64;
            self.weights.iter_mut().for_each(|w| *w = 1.0 / n);
        } else {
            self.weights.iter_mut().for_each(|w| *w /= total);
        }
        // Summarised while weighed, before resampling injects unweighed random particles.
        self.summarise();
        self.resample(obs, rng);
    }

    fn observation_count(&self, obs: &Observation) -> usize {
        used_beams(obs, self.settings.beams).count() + 2 * obs.landmarks.len()
    }

    /// Log-likelihood of `obs` for every particle.
    fn log_weights(&self, obs: &Observation) -> Vec<f64> {
        let n = obs.ranges.len();
        // Beam end points in the robot's frame, computed once per update, not per particle.
        let local: Vec<(f32, f32)> = used_beams(obs, self.settings.beams)
            .map(|i| {
                let b = beam_bearing(i, n, obs.laser_fov);
                (obs.ranges[i] * b.cos(), obs.ranges[i] * b.sin())
            })
            .collect();
        let sr2 = 2.0 * self.settings.landmark_range_sigma.powi(2);
        let sb2 = 2.0 * self.settings.landmark_bearing_sigma.powi(2);
        // The beams' sums for every particle at once (the field's vectorised loop), then
        // each particle's landmarks after its beams, in the order a particle at a time
        // would add them.
        let poses: Vec<[f32; 4]> = self
            .particles
            .iter()
            .map(|p| {
                let (s, c) = p.theta.sin_cos();
                [p.pos.x, p.pos.y, s, c]
            })
            .collect();
        let mut beams = vec![0.0f32; poses.len()];
        self.field.beam_sums(&poses, &local, &mut beams);
        self.particles
            .iter()
            .zip(beams)
            .map(|(p, mut l)| {
                if !self.field.open(p.pos.x, p.pos.y) {
                    return -1e3; // inside a wall: nearly impossible, but keeps the sum finite
                }
                for sight in obs.landmarks {
                    let Some(m) = self.landmarks.get(sight.id) else {
                        continue;
                    };
                    let range = (m - p.pos).norm();
                    let dr = range - sight.range;
                    let db = wrap_angle(p.bearing_to(*m) - sight.bearing);
                    l -= dr * dr / sr2 + db * db / sb2;
                }
                l as f64
            })
            .collect()
    }

    /// KLD-sampling resampling with augmented-MCL injection.
    fn resample(&mut self, obs: &Observation, rng: &mut impl RngExt) {
        let ratio = self.w_fast / self.w_slow;
        let inject = if ratio < self.settings.inject_below {
            1.0 - ratio
        } else {
            0.0
        };
        let mut cumulative = Vec::with_capacity(self.weights.len());
        let mut acc = 0.0;
        for w in &self.weights {
            acc += w;
            cumulative.push(acc);
        }
        let draw = CumulativeSearch::new(&cumulative);
        let s = &self.settings;
        let mut bins: HashSet<(i32, i32, i32), BuildHasherDefault<BinHasher>> = HashSet::default();
        let mut out: Vec<Pose> = Vec::with_capacity(s.max_particles);
        let mut needed = s.min_particles;
        while out.len() < needed.max(s.min_particles) && out.len() < s.max_particles {
            let p = if inject > 0.0 && (rng.random::<f64>()) < inject {
                self.random_pose(obs, rng)
            } else {
                let u = rng.random::<f64>() * acc;
                let k = draw.first_reaching(u);
                let q = self.particles[k.min(self.particles.len() - 1)];
                Pose::new(
                    q.pos.x + gaussian(rng, s.roughen_xy),
                    q.pos.y + gaussian(rng, s.roughen_xy),
                    wrap_angle(q.theta + gaussian(rng, s.roughen_theta)),
                )
            };
            let bin = (
                (p.pos.x / s.bin_xy).floor() as i32,
                (p.pos.y / s.bin_xy).floor() as i32,
                (wrap_angle(p.theta) / s.bin_theta).floor() as i32,
            );
            if bins.insert(bin) {
                needed = kld_bound(bins.len(), s.kld_err, s.kld_z);
            }
            out.push(p);
        }
        let n = out.len();
        self.particles = out;
        self.weights = vec![1.0 / n as f64; n];
        if inject > 0.0 {
            // Injection resets the averages, as in AMCL, so one bad stretch injects once.
            self.w_slow = 0.0;
            self.w_fast = 0.0;
        }
    }

    /// A pose for an injected particle: from a landmark sighting when there is one (the
    /// poses that see that landmark at that range and bearing), otherwise uniform.
    fn random_pose(&self, obs: &Observation, rng: &mut impl RngExt) -> Pose {
        if !obs.landmarks.is_empty() && rng.random::<bool>() {
            let k = rng.random_range(0..obs.landmarks.len());
            let sight = obs.landmarks[k];
            if let Some(m) = self.landmarks.get(sight.id) {
                let theta = rng.random_range(-std::f32::consts::PI..std::f32::consts::PI);
                let r = sight.range + gaussian(rng, self.settings.landmark_range_sigma);
                let b = sight.bearing + gaussian(rng, self.settings.landmark_bearing_sigma);
                let dir = Vector2::new((theta + b).cos(), (theta + b).sin());
                let pos = m - dir * r;
                return Pose { pos, theta };
            }
        }
        let cells = &self.field.free_cells;
        if cells.is_empty() {
            return self.estimate;
        }
        let idx = cells[rng.random_range(0..cells.len())];
        let (r, c) = (idx / self.field.grid_cols, idx % self.field.grid_cols);
        let cell = self.field.grid_cell;
        Pose::new(
            (c as f32 + rng.random::<f32>()) * cell,
            (r as f32 + rng.random::<f32>()) * cell,
            rng.random_range(-std::f32::consts::PI..std::f32::consts::PI),
        )
    }

    /// Recomputes the point estimate and the spread from the particles.
    ///
    /// The estimate is the weighted mean of the heaviest cluster (as AMCL reports), not of
    /// the whole cloud: while a kidnapped or confused robot holds two hypotheses, the mean
    /// of both lies between them, often inside a wall. The spread is the whole cloud's, so
    /// it stays large until the hypotheses have been settled.
    fn summarise(&mut self) {
        let total: f64 = self.weights.iter().sum();
        if total.is_nan() || total <= 0.0 || self.particles.is_empty() {
            return;
        }
        let keep = heaviest_cluster(&self.particles, &self.weights);
        let (mut x, mut y, mut s, mut c, mut w_sum) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0);
        let (mut ax, mut ay) = (0.0f64, 0.0f64);
        for (k, (p, w)) in self.particles.iter().zip(&self.weights).enumerate() {
            ax += w * p.pos.x as f64;
            ay += w * p.pos.y as f64;
            if !keep[k] {
                continue;
            }
            w_sum += w;
            x += w * p.pos.x as f64;
            y += w * p.pos.y as f64;
            s += w * p.theta.sin() as f64;
            c += w * p.theta.cos() as f64;
        }
        let (ax, ay) = (ax / total, ay / total);
        let mut var = 0.0f64;
        for (p, w) in self.particles.iter().zip(&self.weights) {
            var += w * ((p.pos.x as f64 - ax).powi(2) + (p.pos.y as f64 - ay).powi(2));
        }
        if w_sum > 0.0 {
            self.estimate = Pose::new((x / w_sum) as f32, (y / w_sum) as f32, s.atan2(c) as f32);
        }
        self.spread = (var / total).sqrt() as f32;
    }
}

/// Side of the square bins clusters are built from (m): particles in touching bins (8
/// neighbours) belong to one cluster.
const CLUSTER_BIN: f32 = 0.5;

/// Marks the particles of the cluster holding the most weight.
///
/// The bins are a sorted vector searched by bisection (a sorted map's order, so ties between
/// clusters break the same way every run, without a tree's allocations): each bin's weight
/// sums its particles in their order, clusters are numbered in key order and flooded
/// depth-first, so every sum is taken in one fixed order.
fn heaviest_cluster(particles: &[Pose], weights: &[f64]) -> Vec<bool> {
    let key = |p: &Pose| {
        (
            (p.pos.x / CLUSTER_BIN).floor() as i32,
            (p.pos.y / CLUSTER_BIN).floor() as i32,
        )
    };
    let keys: Vec<(i32, i32)> = particles.iter().map(key).collect();
    // Particle indices by key, and within a key in particle order (a stable sort).
    let mut order: Vec<u32> = (0..particles.len() as u32).collect();
    order.sort_by_key(|&i| keys[i as usize]);
    // One entry a bin: (key, weight, cluster); and each particle's bin.
    let mut bins: Vec<((i32, i32), f64, usize)> = Vec::new();
    let mut bin_of = vec![0u32; particles.len()];
    for &i in &order {
        let k = keys[i as usize];
        if bins.last().is_none_or(|b| b.0 != k) {
            bins.push((k, 0.0, usize::MAX));
        }
        let last = bins.len() - 1;
        bins[last].1 += weights[i as usize];
        bin_of[i as usize] = last as u32;
    }
    let find = |bins: &[((i32, i32), f64, usize)], k: (i32, i32)| {
        bins.binary_search_by(|b| b.0.cmp(&k)).ok()
    };
    let mut cluster_weight: Vec<f64> = Vec::new();
    let mut stack = Vec::new();
    for start in 0..bins.len() {
        if bins[start].2 != usize::MAX {
            continue;
        }
        let id = cluster_weight.len();
        let mut weight = 0.0;
        bins[start].2 = id;
        stack.push(start);
        while let Some(b) = stack.pop() {
            weight += bins[b].1;
            let (bx, by) = bins[b].0;
            for dx in -1..=1 {
                for dy in -1..=1 {
                    if let Some(n) = find(&bins, (bx + dx, by + dy))
                        && bins[n].2 == usize::MAX
                    {
                        bins[n].2 = id;
                        stack.push(n);
                    }
                }
            }
        }
        cluster_weight.push(weight);
    }
    let best = cluster_weight
        .iter()
        .enumerate()
        .fold((0, f64::NEG_INFINITY), |acc, (i, w)| {
            if *w > acc.1 { (i, *w) } else { acc }
        })
        .0;
    bin_of.iter().map(|&b| bins[b as usize].2 == best).collect()
}

/// Every how many beams to use so that about `wanted` of `n` are used.
fn beam_step(n: usize, wanted: usize) -> usize {
    (n / wanted.max(1)).max(1)
}

crate::checkpoint::restore_struct!(Localiser {
    plain: [
        particles,
        weights,
        w_slow,
        w_fast,
        last_odom,
        particles_odom,
        moved_since_update,
        calls_since_update,
        estimate,
        spread,
    ],
    nested: [],
    derived: [settings, field, landmarks],
});

#[cfg(test)]
mod tests;
