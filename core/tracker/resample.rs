//! Stage 5 of [`Tracker::update`]: normalise each role's weights, re-seed a role that is
//! impossible or contradicted, and resample when the effective sample size is low
//! (low-variance, systematic resampling).

use rand::RngExt;

use crate::sim::arena::Arena;
use crate::tracker::role::{CONTRADICTED_TICKS, LaserModel, Role, Sighting};
use crate::tracker::state::Tracker;

impl Tracker {
    /// Stage 5.
    pub(super) fn normalise_and_resample(
        &mut self,
        arena: &Arena,
        sightings: &[Sighting],
        laser: LaserModel,
    ) {
        for i in 0..self.roles.len() {
            if self.roles[i].tagged {
                continue;
            }
            let total: f32 = self.roles[i].weights.iter().sum();
            if !(total.is_finite() && total > 1e-30)
                || self.roles[i].unseen_run >= CONTRADICTED_TICKS
            {
                // Every particle became impossible, or the team has looked at the whole cloud
                // for a while and seen nothing: the opponent is somewhere the team has not
                // just looked. Re-seed there rather than lose the role.
                let particles = self.uniform_particles(arena, sightings, laser);
                self.roles[i].reset(particles);
                self.roles[i].confidence = 0.0; // a guess over the unseen space
                continue;
            }
            let role = &mut self.roles[i];
            let mut sq = 0.0;
            for w in role.weights.iter_mut() {
                *w /= total;
                sq += *w * *w;
            }
            if 1.0 / sq < 0.5 * role.weights.len() as f32 {
                let offset = self.rng.random::<f32>();
                low_variance_resample(role, offset);
            }
        }
    }
}

/// Low-variance (systematic) resampling to equal weights.
pub fn low_variance_resample(role: &mut Role, offset: f32) {
    let n = role.particles.len();
    let step = 1.0 / n as f32;
    let mut particles = Vec::with_capacity(n);
    let mut steps = Vec::with_capacity(n);
    let mut c = role.weights[0];
    let mut i = 0;
    for m in 0..n {
        let u = (offset + m as f32) * step;
        while u > c && i + 1 < n {
            i += 1;
            c += role.weights[i];
        }
        particles.push(role.particles[i]);
        steps.push(role.steps[i]);
    }
    role.particles = particles;
    role.steps = steps;
    role.weights = vec![step; n];
}
