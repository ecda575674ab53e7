//! What the tracker is made of: its settings, its roles (one particle filter each, for
//! some of the opponents), what robots contribute each tick, what it reports, and the
//! constants of its motion and contradiction models.

use nalgebra::{Point2, Vector2};

use crate::sim::DT;
use crate::sim::Pose;
use crate::sim::sensors::Detection;

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
    // The cloud: the tracker's files alone change it, keeping the three
    // the same length and the weights summing to 1.
    pub(super) particles: Vec<Point2<f32>>,
    pub(super) weights: Vec<f32>,
    /// Each particle's current step per tick (metres).
    pub(super) steps: Vec<Vector2<f32>>,
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
pub(super) const CONFIDENCE_TIME_CONSTANT_S: f32 = 30.0;
/// Confidence lost per tick while robots look at all of the role's weight and see nothing:
/// 10% (so half in about 7 ticks of a full, fruitless look).
pub(super) const CONFIDENCE_LOOK_DECAY: f32 = 0.1;

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
    pub(super) fn reach(&self, opponent_speed: f32) -> f32 {
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
pub(super) const TURN_PROBABILITY: f32 = 0.02;
/// Slowest speed a particle picks, as a fraction of top speed: a hiding opponent may stand
/// still, but the belief must keep up with one that runs.
pub(super) const MIN_SPEED_FRACTION: f32 = 0.3;

/// A role is contradicted when robots have looked at (nearly) all of its weight — all but
/// `CONTRADICTED_KEEP` of it, counting the `p_miss` each seen particle keeps — for this many
/// ticks in a row without seeing anything of it. Renormalising such a cloud would leave it
/// where it is, and robots would stare at an empty spot for ever; instead it is re-seeded over
/// the space nobody is looking at. Ten ticks of misses leave 0.05^10 of the evidence: the
/// opponent is elsewhere.
pub(super) const CONTRADICTED_TICKS: u32 = 10;
pub(super) const CONTRADICTED_KEEP: f32 = 0.02;

crate::checkpoint::plain_struct!(Role {
    id,
    count,
    tagged,
    particles,
    weights,
    steps,
    unseen_run,
    confidence,
});
