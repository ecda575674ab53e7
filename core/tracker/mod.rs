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
pub mod features;
pub mod gospa;
mod merge;
mod motion;
mod observe;
mod resample;
mod role;
mod seen;
mod state;

pub use resample::low_variance_resample;
pub use role::{
    Confidence, LaserModel, Role, SUSPICIOUS_CONFIDENCE, Settings, Sighting, TrackerEvent,
    VALID_CONFIDENCE,
};
pub use state::Tracker;

use nalgebra::{Point2, Vector2};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use crate::sim::arena::Arena;
use crate::sim::{AGENT_RADIUS, DT};
use role::{MIN_SPEED_FRACTION, TURN_PROBABILITY};
use seen::would_be_seen;

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
    ///
    /// In two passes over a role: first every particle's step (the only random draws, in
    /// particle order), then every move. A particle's step depends only on its own step of
    /// the tick before and the stream, so this is the same as doing both per particle, and
    /// the moves, free of the stream, run without waiting on it.
    fn motion(&mut self, arena: &Arena) {
        if !self.settings.predict {
            return;
        }
        let max_step = self.settings.opponent_speed * DT;
        let turn_below = (TURN_PROBABILITY * (1u32 << 16) as f32) as u32;
        let g = &arena.grid;
        for role in self.roles.iter_mut().filter(|r| !r.tagged) {
            for v in role.steps.iter_mut() {
                let bits: u32 = self.rng.random();
                if bits & 0xffff < turn_below || *v == Vector2::zeros() {
                    let more: u32 = self.rng.random();
                    let dir = self.directions[(more & 0xff) as usize];
                    let u = (more >> 8) as f32 / (1u32 << 24) as f32;
                    *v = dir * (max_step * (MIN_SPEED_FRACTION + (1.0 - MIN_SPEED_FRACTION) * u));
                }
            }
            motion::step_or_stop(g, &mut role.particles, &mut role.steps);
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
