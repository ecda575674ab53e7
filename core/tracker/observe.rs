//! The measurement update, stages 2–4 of [`Tracker::update`]: tags take opponents out,
//! negative information down-weights what the robots' scans would have seen, and positive
//! information gives each detection to the role it most likely belongs to (splitting off a
//! role for one opponent when needed) and updates that role by Bayes' rule.

use nalgebra::{Point2, Vector2};

use crate::sim::arena::Arena;
use crate::sim::sensors::detection_point;
use crate::sim::{AGENT_RADIUS, DT, Pose};
use crate::tracker::role::{
    CONFIDENCE_LOOK_DECAY, CONFIDENCE_TIME_CONSTANT_S, CONTRADICTED_KEEP, LaserModel, Role,
    Sighting, TrackerEvent,
};
use crate::tracker::seen::down_weight_seen;
use crate::tracker::state::Tracker;

/// Lateral spread (m) of a detection's position: sensor noise plus the pose estimate's error.
fn detection_sigma(range: f32) -> f32 {
    0.1 + 0.03 * range
}

/// Likelihood of a detection 4σ from every particle: a prior with less weight near a
/// detection than that has nothing to say about it, and is re-drawn around it.
const FAR_LIKELIHOOD: f32 = 3.354_626_3e-4; // exp(-4² / 2)

/// Spread used to decide which role a detection belongs to: generous, because a tracked
/// opponent's cloud lags a running opponent by a little.
const ASSOCIATION_SIGMA: f32 = 0.75;

impl Tracker {
    /// Log-likelihood-ish score of `z` under role `r`, for association. A role standing for
    /// `count` opponents explains a detection `count` times as well as its cloud alone: each
    /// of them is distributed as the cloud and any one may have made it, so the chance that
    /// one of them stands at `z` is `count` times the cloud's density there. Without the
    /// factor a role of several unseen opponents loses their detections to a role of one
    /// whose cloud is a little denser there, and that role's opponent is dragged away.
    fn association(&self, r: &Role, z: Point2<f32>) -> f32 {
        let inv = 1.0 / (2.0 * ASSOCIATION_SIGMA * ASSOCIATION_SIGMA);
        let mut sum = 0.0f32;
        let mut nearest = f32::INFINITY;
        for (p, w) in r.particles.iter().zip(&r.weights) {
            let d2 = (p - z).norm_squared();
            nearest = nearest.min(d2);
            if d2 < 16.0 * ASSOCIATION_SIGMA * ASSOCIATION_SIGMA {
                sum += w * (-d2 * inv).exp();
            }
        }
        if sum > 1e-30 {
            sum.ln() + (r.count.max(1) as f32).ln()
        } else {
            // No particle near: rank by the nearest particle (always below any real likelihood).
            -1e6 - nearest
        }
    }

    /// The untagged role a detection at `z` most likely belongs to.
    fn associate(&self, z: Point2<f32>) -> Option<usize> {
        self.roles
            .iter()
            .enumerate()
            .filter(|(_, r)| !r.tagged && r.count > 0)
            .map(|(i, r)| (self.association(r, z), i))
            .max_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)))
            .map(|(_, i)| i)
    }

    /// Splits one opponent off role `i` (a copy standing for one) when it stands for more;
    /// returns the index of the role that now stands for exactly that opponent.
    fn split_one(&mut self, i: usize, events: &mut Vec<TrackerEvent>) -> usize {
        if self.roles[i].count <= 1 {
            return i;
        }
        self.roles[i].count -= 1;
        let mut copy = self.roles[i].clone();
        copy.id = self.next_id;
        self.next_id += 1;
        copy.count = 1;
        events.push(TrackerEvent::Split {
            role: copy.id,
            from: self.roles[i].id,
        });
        self.roles.push(copy);
        self.roles.len() - 1
    }

    /// Stage 2: each robot whose shot hit took out one opponent: the one its device hit, the
    /// nearest detection inside the tag cone. When no detection fits (a teammate blocked the
    /// laser but not the shot), the role with the most weight inside the cone loses it: a
    /// hit must always take one count off, or the counts would stop adding up.
    pub(super) fn tags(
        &mut self,
        sightings: &[Sighting],
        used: &mut [Vec<bool>],
        events: &mut Vec<TrackerEvent>,
    ) {
        // Detections are noisy (1° in bearing): allow a little outside the device's cone.
        let half = self.settings.tag_half_angle + 2f32.to_radians();
        let range = self.settings.tag_range + 0.3;
        for (k, s) in sightings.iter().enumerate() {
            if !s.tagged {
                continue;
            }
            let hit = s
                .detections
                .iter()
                .enumerate()
                .filter(|(_, d)| d.bearing.abs() <= half && d.range <= range)
                .min_by(|a, b| a.1.range.total_cmp(&b.1.range));
            let found = match hit {
                Some((j, d)) => {
                    used[k][j] = true;
                    let z = detection_point(s.pose, d);
                    self.associate(z).map(|i| (i, z))
                }
                None => self.most_weight_in_cone(s.pose, half, range),
            };
            let Some((i, z)) = found else { continue };
            let i = self.split_one(i, events);
            let role = &mut self.roles[i];
            role.tagged = true;
            role.confidence = 1.0; // the device reported the hit: a fact
            role.reset(vec![z]);
        }
    }

    /// The untagged role with the most opponents expected inside a tag cone from `pose` (its
    /// weight there times its count, as in [`Tracker::association`]), and the weighted mean
    /// of that weight (or a point straight ahead when no role has any there).
    fn most_weight_in_cone(
        &self,
        pose: Pose,
        half: f32,
        range: f32,
    ) -> Option<(usize, Point2<f32>)> {
        let ahead = pose.pos + pose.heading() * (range / 2.0);
        self.roles
            .iter()
            .enumerate()
            .filter(|(_, r)| !r.tagged && r.count > 0)
            .map(|(i, r)| {
                let (mut w, mut sum) = (0.0f32, Vector2::zeros());
                for (p, pw) in r.particles.iter().zip(&r.weights) {
                    if (p - pose.pos).norm() <= range && pose.bearing_to(*p).abs() <= half {
                        w += pw;
                        sum += p.coords * *pw;
                    }
                }
                let z = if w > 0.0 {
                    Point2::from(sum / w)
                } else {
                    ahead
                };
                (w * r.count as f32, i, z)
            })
            .max_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)))
            .map(|(_, i, z)| (i, z))
    }

    /// Stage 3: down-weight every particle some robot would have seen, and count how long
    /// each role has been looked at in full without being seen.
    pub(super) fn negative(&mut self, sightings: &[Sighting], laser: LaserModel) {
        let p_miss = self.settings.p_miss;
        let before: Vec<f32> = self.roles.iter().map(|r| r.weights.iter().sum()).collect();
        for s in sightings.iter().filter(|s| !s.scan.is_empty()) {
            let (cos, sin) = (s.pose.theta.cos(), s.pose.theta.sin());
            let reach = s.reach(self.settings.opponent_speed);
            for role in self.roles.iter_mut().filter(|r| !r.tagged) {
                down_weight_seen(
                    &role.particles,
                    &mut role.weights,
                    s,
                    laser,
                    cos,
                    sin,
                    reach,
                    p_miss,
                );
            }
        }
        let time_decay = (-DT / CONFIDENCE_TIME_CONSTANT_S).exp();
        for (role, before) in self.roles.iter_mut().zip(before) {
            if role.tagged {
                continue;
            }
            let after: f32 = role.weights.iter().sum();
            // Weight kept = unseen share + p_miss × seen share.
            if after <= (p_miss + CONTRADICTED_KEEP) * before {
                role.unseen_run += 1;
            } else {
                role.unseen_run = 0;
            }
            let seen_share = if before > 0.0 {
                ((before - after) / (before * (1.0 - p_miss))).clamp(0.0, 1.0)
            } else {
                0.0
            };
            role.confidence *= time_decay * (1.0 - CONFIDENCE_LOOK_DECAY * seen_share);
        }
    }

    /// Stage 4: each (unused) detection updates the role it most likely belongs to.
    pub(super) fn positive(
        &mut self,
        arena: &Arena,
        sightings: &[Sighting],
        used: &[Vec<bool>],
        events: &mut Vec<TrackerEvent>,
    ) {
        for (k, s) in sightings.iter().enumerate() {
            for (j, d) in s.detections.iter().enumerate() {
                if used[k][j] {
                    continue;
                }
                let z = detection_point(s.pose, d);
                let Some(i) = self.associate(z) else { continue };
                let i = self.split_one(i, events);
                let sigma = detection_sigma(d.range).hypot(s.reach(self.settings.opponent_speed));
                self.observe(arena, i, z, sigma);
            }
        }
    }

    /// Bayes update of role `i` with a detection at `z`. When the prior has (almost) no
    /// particles where the detection is, the cloud is re-drawn around it instead (sensor
    /// resetting): the detection is far sharper than any prior it could disagree with.
    fn observe(&mut self, arena: &Arena, i: usize, z: Point2<f32>, sigma: f32) {
        let inv = 1.0 / (2.0 * sigma * sigma);
        let role = &mut self.roles[i];
        role.unseen_run = 0; // seen after all
        role.confidence = 1.0;
        let mut total = 0.0f32;
        for (p, w) in role.particles.iter().zip(role.weights.iter_mut()) {
            *w *= (-(p - z).norm_squared() * inv).exp();
            total += *w;
        }
        let n = role.particles.len() as f32;
        let ess = if total > 0.0 {
            let sq: f32 = role.weights.iter().map(|w| (w / total) * (w / total)).sum();
            1.0 / sq
        } else {
            0.0
        };
        // Keep the Bayes update only if it left a usable cloud: weights that underflowed would
        // otherwise be mistaken for an impossible role and scattered over the map. And only
        // if the prior had any weight near the detection: `total` is the detection's
        // likelihood under the prior, and below that of a cloud lying wholly 4σ away the
        // Bayes update would just renormalise the cloud where it is — a tight cloud metres
        // from a confirmed detection (found by the reacquire experiment, whose
        // no-prediction tracker has no motion to carry its cloud to a teammate's detections).
        if total > FAR_LIKELIHOOD && ess >= 0.05 * n {
            return;
        }
        let count = role.particles.len();
        let mut fresh = Vec::with_capacity(count);
        let mut tries = 0;
        while fresh.len() < count && tries < count * 20 {
            tries += 1;
            let q = z + Vector2::new(
                crate::sim::gaussian(&mut self.rng, sigma),
                crate::sim::gaussian(&mut self.rng, sigma),
            );
            if arena
                .grid
                .cell_of(q)
                .is_some_and(|c| arena.grid.clearance[c] >= AGENT_RADIUS)
            {
                fresh.push(q);
            }
        }
        while fresh.len() < count {
            fresh.push(z); // pressed against a wall: the detection itself is the best guess
        }
        self.roles[i].reset(fresh);
    }
}
