//! The team's opponent tracker: role-factored particle filters under occlusion (sections 2–3
//! of Rosencrantz, Gordon and Thrun).
//!
//! The team's belief is a set of [`Role`]s. A role is one particle filter over an opponent's
//! `(x, y)` plus the number of opponents it stands for; opponents in one role share one
//! distribution. The match starts with one role for every opponent, uniform over free space.
//! Each tick, [`Tracker::update`] runs:
//! 1. motion — every particle moves at most the opponents' top speed in a random direction,
//!    never into an obstacle. A particle keeps its direction and speed for a random while
//!    (a new one with probability `TURN_PROBABILITY` per tick, and whenever a wall stops it):
//!    people walk in lines, and a memoryless random walk would spread the cloud only as
//!    √t, far slower than an opponent can actually get away;
//! 2. tags — a robot whose shot hit takes one opponent out of the role its target was
//!    associated with (the nearest detection in the tag cone) (a role left with no opponents disappears; the tagged one is kept as a
//!    `tagged` role for display and never hunted again);
//! 3. negative information — every particle that a robot's scan would have seen (in its field
//!    of view, nearer than the beam at its bearing reports) is down-weighted by the
//!    probability of a missed detection;
//! 4. positive information — each detection goes to the role of maximum likelihood (a role
//!    standing for k opponents is k times as likely to have made it as its cloud alone says);
//!    a role standing for several opponents first splits off a copy for one;
//! 5. normalise, recover roles whose every particle became impossible, resample when the
//!    effective sample size is low;
//! 6. every `merge_interval` ticks, merge roles whose grid histograms are closer than
//!    `kl_cutoff` in symmetric KL divergence (see [`merge`]); the merged cloud mixes the two
//!    in proportion to the opponents each stands for.
//!
//! Pure and deterministic: all randomness comes from the tracker's own ChaCha stream.
//!
//! How good the belief is, measured against the truth by those who may see it (the lab, the
//! spectators' state): [`gospa`], the metric, and [`estimate`], a belief's point estimates.
//! The tracker itself never calls them.

pub mod estimate;
pub mod gospa;
mod merge;
mod observe;
mod resample;

pub use resample::low_variance_resample;

use nalgebra::{Point2, Vector2};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use crate::sim::arena::Arena;
use crate::sim::sensors::Detection;
use crate::sim::{AGENT_RADIUS, DT, Pose};
use observe::would_be_seen;

crate::settings! {
    /// Settings of the team's opponent tracker (the match's `tracker` object).
    #[derive(Debug, Clone, PartialEq)]
    pub struct Settings as "tracker" {
        /// Particles in each role's filter.
        pub particles_per_role: usize = 1000, range(10, 100_000);
        /// Merge roles whose clouds become indistinguishable.
        pub merge: bool = true;
        /// Ticks between merge checks.
        pub merge_interval: u64 = 20, range(1, 10_000);
        /// Symmetric KL divergence under which two roles merge.
        pub kl_cutoff: f32 = 0.7, above(0.0, 1e6);
        /// Cell size in metres of the merge histogram.
        pub grid_cell: f32 = 1.0, range(0.1, 10.0);
    }
    internal {
        /// Probability that an opponent in plain view goes undetected.
        pub p_miss: f32 = 0.05;
        /// Top speed assumed for opponents (m/s).
        pub opponent_speed: f32 = 1.0;
        /// The robots' tag device (to tell which opponent a hit took out).
        pub tag_half_angle: f32 = 5f32.to_radians();
        pub tag_range: f32 = 6.0;
        /// Predict where unseen opponents go (the motion stage). Off, hypotheses stay where
        /// they were last supported: the reacquire experiment's "no prediction" conditions.
        pub predict: bool = true;
    }
}

/// One role: a particle filter standing for `count` opponents.
#[derive(Debug, Clone, PartialEq)]
pub struct Role {
    pub id: u64,
    pub count: u32,
    /// A role holding tagged opponents: kept where they were tagged, never updated or hunted.
    pub tagged: bool,
    // The cloud: private so that it only changes through the tracker, which keeps the three
    // the same length and the weights summing to 1.
    particles: Vec<Point2<f32>>,
    weights: Vec<f32>,
    /// Each particle's current step per tick (metres).
    steps: Vec<Vector2<f32>>,
    /// Consecutive ticks in which robots looked at (nearly) all of this role's weight and
    /// saw nothing of it: see [`CONTRADICTED_TICKS`].
    pub unseen_run: u32,
    /// How much the team trusts this role's cloud (Coltin et al.'s world-model confidence):
    /// 1 when a detection confirms it, decaying with time and faster while robots look where
    /// it should be and see nothing; 0 for a guess over the whole map. See [`Confidence`].
    pub confidence: f32,
}

/// What a role's confidence says about it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Confidence {
    /// Recently confirmed: act on it.
    Valid,
    /// Not confirmed for a while, or looked for and not found: worth a look (the planner
    /// weighs suspicious roles up, so a robot goes to check).
    Suspicious,
    /// Long unconfirmed or never confirmed: a guess.
    Invalid,
}

/// Confidence at or above which a role is valid, and above which it is suspicious.
pub const VALID_CONFIDENCE: f32 = 0.5;
pub const SUSPICIOUS_CONFIDENCE: f32 = 0.15;
/// Confidence lost per second without confirmation: halves in about 21 s (time constant 30 s).
const CONFIDENCE_TIME_CONSTANT_S: f32 = 30.0;
/// Confidence lost per tick while robots look at all of the role's weight and see nothing:
/// 10% (so half in about 7 ticks of a full, fruitless look).
const CONFIDENCE_LOOK_DECAY: f32 = 0.1;

impl Role {
    pub fn confidence_state(&self) -> Confidence {
        if self.confidence >= VALID_CONFIDENCE {
            Confidence::Valid
        } else if self.confidence >= SUSPICIOUS_CONFIDENCE {
            Confidence::Suspicious
        } else {
            Confidence::Invalid
        }
    }
}

impl Role {
    /// Where this role's opponents may be.
    pub fn particles(&self) -> &[Point2<f32>] {
        &self.particles
    }

    /// One weight per particle, summing to 1.
    pub fn weights(&self) -> &[f32] {
        &self.weights
    }

    /// Each particle's current step per tick (metres).
    pub fn steps(&self) -> &[Vector2<f32>] {
        &self.steps
    }

    /// This role's clouds in several trackers pooled into one, each tracker's weight
    /// scaled by `1 / parts.len()` so the sum stays 1 (the team's merged view of a role).
    /// Everything but the cloud comes from `template`.
    pub fn pooled(template: &Role, parts: &[&Role]) -> Role {
        let share = 1.0 / parts.len() as f32;
        let mut pooled = Role {
            particles: Vec::new(),
            weights: Vec::new(),
            steps: Vec::new(),
            ..template.clone()
        };
        for p in parts {
            pooled.particles.extend_from_slice(&p.particles);
            pooled.weights.extend(p.weights.iter().map(|w| w * share));
            pooled.steps.extend_from_slice(&p.steps);
        }
        pooled
    }

    /// Replaces the cloud by `particles` with equal weights, standing still.
    pub fn reset(&mut self, particles: Vec<Point2<f32>>) {
        let n = particles.len();
        self.particles = particles;
        self.weights = vec![1.0 / n as f32; n];
        self.steps = vec![Vector2::zeros(); n];
        self.unseen_run = 0;
    }
}

/// What one robot contributes to the tracker this tick.
#[derive(Debug, Clone, Copy)]
pub struct Sighting<'a> {
    /// The robot's estimate of its pose.
    pub pose: Pose,
    pub scan: &'a [f32],
    pub detections: &'a [Detection],
    /// True when this robot's shot tagged an opponent this tick.
    pub tagged: bool,
    /// Ticks since it was sensed: 0 for a robot's own sensing, the radio's latency for a
    /// teammate's. An opponent may have moved up to `age × top speed` since, so a late
    /// sighting contradicts only hypotheses that far inside what it saw, and places what it
    /// detected that much less sharply.
    pub age_ticks: u32,
}

impl Sighting<'_> {
    /// How far an opponent may have moved since this was sensed (m).
    fn reach(&self, opponent_speed: f32) -> f32 {
        self.age_ticks as f32 * opponent_speed * DT
    }
}

/// Laser geometry the negative-information update needs.
#[derive(Debug, Clone, Copy)]
pub struct LaserModel {
    pub fov: f32,
    pub range: f32,
}

#[derive(Debug, Clone, PartialEq)]
pub enum TrackerEvent {
    /// Role `role` was split off `from` to stand for one opponent.
    Split { role: u64, from: u64 },
    /// Role `from` merged into `role`, which now stands for `count` opponents.
    Merge { role: u64, from: u64, count: u32 },
}

/// Chance per tick that a particle picks a new direction and speed (mean run: 2.5 s).
const TURN_PROBABILITY: f32 = 0.02;
/// Slowest speed a particle picks, as a fraction of top speed: a hiding opponent may stand
/// still, but the belief must keep up with one that runs.
const MIN_SPEED_FRACTION: f32 = 0.3;

/// A role is contradicted when robots have looked at (nearly) all of its weight — all but
/// `CONTRADICTED_KEEP` of it, counting the `p_miss` each seen particle keeps — for this many
/// ticks in a row without seeing anything of it. Renormalising such a cloud would leave it
/// where it is, and robots would stare at an empty spot for ever; instead it is re-seeded over
/// the space nobody is looking at. Ten ticks of misses leave 0.05^10 of the evidence: the
/// opponent is elsewhere.
const CONTRADICTED_TICKS: u32 = 10;
const CONTRADICTED_KEEP: f32 = 0.02;

#[derive(Debug, Clone)]
pub struct Tracker {
    pub settings: Settings,
    pub roles: Vec<Role>,
    next_id: u64,
    rng: ChaCha8Rng,
    /// Grid cells where an opponent disc fits: where particles may live.
    free_cells: Vec<u32>,
    /// Unit vectors for the random walk (a table: cheaper than sin/cos per particle).
    directions: Vec<Vector2<f32>>,
    merger: merge::Histograms,
    tick: u64,
}

impl Tracker {
    /// A tracker with one role for all `opponents`, uniform over free space.
    pub fn new(arena: &Arena, settings: Settings, opponents: u32, rng: ChaCha8Rng) -> Tracker {
        let counts: &[u32] = if opponents > 0 { &[opponents] } else { &[] };
        Tracker::with_roles(arena, settings, counts, rng)
    }

    /// A tracker with one role per entry of `counts`, each uniform over free space (a belief
    /// that has already split, for benchmarks and tests).
    pub fn with_roles(
        arena: &Arena,
        settings: Settings,
        counts: &[u32],
        rng: ChaCha8Rng,
    ) -> Tracker {
        let g = &arena.grid;
        let free_cells: Vec<u32> = (0..g.len())
            .filter(|&c| g.clearance[c] >= AGENT_RADIUS)
            .map(|c| c as u32)
            .collect();
        let directions = (0..256)
            .map(|k| {
                let a = k as f32 / 256.0 * std::f32::consts::TAU;
                Vector2::new(a.cos(), a.sin())
            })
            .collect();
        let merger = merge::Histograms::new(arena, settings.grid_cell);
        let mut t = Tracker {
            settings,
            roles: Vec::new(),
            next_id: 0,
            rng,
            free_cells,
            directions,
            merger,
            tick: 0,
        };
        let nothing_seen = LaserModel {
            fov: 0.0,
            range: 0.0,
        };
        for &count in counts {
            let particles = t.uniform_particles(arena, &[], nothing_seen);
            t.push_role(count, particles);
        }
        t
    }

    fn push_role(&mut self, count: u32, particles: Vec<Point2<f32>>) -> u64 {
        let id = self.next_id;
        self.next_id += 1;
        let mut role = Role {
            id,
            count,
            tagged: false,
            particles: Vec::new(),
            weights: Vec::new(),
            steps: Vec::new(),
            unseen_run: 0,
            confidence: 0.0, // a prior over the whole map confirms nothing
        };
        role.reset(particles);
        self.roles.push(role);
        id
    }

    /// Opponents the tracker still hunts (the sum of untagged roles' counts).
    pub fn untagged_count(&self) -> u32 {
        self.roles
            .iter()
            .filter(|r| !r.tagged)
            .map(|r| r.count)
            .sum()
    }

    /// `particles_per_role` points uniform over free space, avoiding what `seen` would see.
    fn uniform_particles(
        &mut self,
        arena: &Arena,
        seen: &[Sighting],
        laser: LaserModel,
    ) -> Vec<Point2<f32>> {
        let g = &arena.grid;
        let n = self.settings.particles_per_role;
        let mut out = Vec::with_capacity(n);
        let trig: Vec<(f32, f32)> = seen
            .iter()
            .map(|s| (s.pose.theta.cos(), s.pose.theta.sin()))
            .collect();
        let mut tries = 0usize;
        while out.len() < n && !self.free_cells.is_empty() {
            tries += 1;
            let cell = self.free_cells[self.rng.random_range(0..self.free_cells.len())] as usize;
            let c = g.centre(cell);
            let p = Point2::new(
                c.x + (self.rng.random::<f32>() - 0.5) * g.cell,
                c.y + (self.rng.random::<f32>() - 0.5) * g.cell,
            );
            if !self.free_at(arena, p) {
                continue;
            }
            // After many failures (the team sees nearly everything) accept seen places too.
            let visible = seen.iter().zip(&trig).any(|(s, (cos, sin))| {
                would_be_seen(
                    p,
                    s,
                    laser,
                    *cos,
                    *sin,
                    s.reach(self.settings.opponent_speed),
                )
            });
            if visible && tries < 50 * n {
                continue;
            }
            out.push(p);
        }
        if out.is_empty() {
            // A map with no free space at all: keep the filter well-formed.
            out.push(Point2::new(arena.width() / 2.0, arena.height() / 2.0));
        }
        out
    }

    fn free_at(&self, arena: &Arena, p: Point2<f32>) -> bool {
        arena
            .grid
            .cell_of(p)
            .is_some_and(|c| arena.grid.clearance[c] >= AGENT_RADIUS)
    }

    /// One tick of tracking. `sightings` are the robots that sensed this tick (frozen robots
    /// sense nothing and are left out).
    pub fn update(
        &mut self,
        arena: &Arena,
        laser: LaserModel,
        sightings: &[Sighting],
    ) -> Vec<TrackerEvent> {
        self.tick += 1;
        let mut events = Vec::new();
        self.motion(arena);
        let mut used: Vec<Vec<bool>> = sightings
            .iter()
            .map(|s| vec![false; s.detections.len()])
            .collect();
        self.tags(sightings, &mut used, &mut events);
        self.negative(sightings, laser);
        self.positive(arena, sightings, &used, &mut events);
        self.normalise_and_resample(arena, sightings, laser);
        if self.settings.merge && self.tick.is_multiple_of(self.settings.merge_interval) {
            self.merge_similar(&mut events);
        }
        events
    }

    /// Stage 1: each particle runs on in its direction, now and then picking a new direction
    /// and speed (at most top speed); a step that would leave free space is refused and the
    /// particle picks anew.
    fn motion(&mut self, arena: &Arena) {
        if !self.settings.predict {
            return;
        }
        let max_step = self.settings.opponent_speed * DT;
        let turn_below = (TURN_PROBABILITY * (1u32 << 16) as f32) as u32;
        let g = &arena.grid;
        for role in self.roles.iter_mut().filter(|r| !r.tagged) {
            for (p, v) in role.particles.iter_mut().zip(role.steps.iter_mut()) {
                let bits: u32 = self.rng.random();
                if bits & 0xffff < turn_below || *v == Vector2::zeros() {
                    let more: u32 = self.rng.random();
                    let dir = self.directions[(more & 0xff) as usize];
                    let u = (more >> 8) as f32 / (1u32 << 24) as f32;
                    *v = dir * (max_step * (MIN_SPEED_FRACTION + (1.0 - MIN_SPEED_FRACTION) * u));
                }
                let q = *p + *v;
                if g.cell_of(q).is_some_and(|c| g.clearance[c] >= AGENT_RADIUS) {
                    *p = q;
                } else {
                    *v = Vector2::zeros(); // blocked: choose again next tick
                }
            }
        }
    }

    /// Stage 6: merge the most similar pair under the cutoff, repeatedly.
    fn merge_similar(&mut self, events: &mut Vec<TrackerEvent>) {
        loop {
            let active: Vec<usize> = (0..self.roles.len())
                .filter(|&i| !self.roles[i].tagged)
                .collect();
            if active.len() < 2 {
                return;
            }
            let hists: Vec<Vec<f32>> = active
                .iter()
                .map(|&i| self.merger.histogram(&self.roles[i]))
                .collect();
            let mut best: Option<(f32, usize, usize)> = None;
            for a in 0..active.len() {
                for b in a + 1..active.len() {
                    let d = merge::symmetric_kl(&hists[a], &hists[b]);
                    if d < self.settings.kl_cutoff && best.is_none_or(|(bd, _, _)| d < bd) {
                        best = Some((d, active[a], active[b]));
                    }
                }
            }
            let Some((_, a, b)) = best else { return };
            let offset = self.rng.random::<f32>();
            let other = self.roles.remove(b);
            let keep = &mut self.roles[a];
            merge::average_into(keep, &other, offset);
            keep.count += other.count;
            // The merged cloud is no better known than the less trusted of the two, and has
            // not been looked at in full as a whole yet.
            keep.confidence = keep.confidence.min(other.confidence);
            keep.unseen_run = keep.unseen_run.min(other.unseen_run);
            events.push(TrackerEvent::Merge {
                role: keep.id,
                from: other.id,
                count: keep.count,
            });
        }
    }
}

#[cfg(test)]
mod tests;
