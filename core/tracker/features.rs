//! The team belief as one robot can use it to act: a fixed set of numbers from its own
//! tracker (or the team's shared one) and its own pose estimate, for a learned policy's
//! observation (`crate::env::Layout`) and the API's robot observation.
//!
//! - a coarse egocentric grid of belief mass: the expected share of the opponents still in
//!   the arena in each of [`SECTORS`] bearing sectors (ahead first, counter-clockwise) times
//!   [`RINGS`] distance rings around the robot, summing to 1 while any is untagged;
//! - the same mass by the way to walk to it: for the belief within [`PATH_REACH_M`] of
//!   travel, the share in each bearing sector of the point [`PATH_AHEAD_M`] along the
//!   shortest path to it (through doors, around walls: what the straight-line grid cannot
//!   say in a building);
//! - the [`ROLE_SLOTS`] untagged roles whose clouds' means are nearest, nearest first: how
//!   many opponents each stands for, where its mean lies ahead and to the left, how wide the
//!   cloud is, how much the team trusts it and how long robots have looked at it in vain;
//! - the share of the opponents the robot believes are still untagged.
//!
//! Every value is rounded to a ten-thousandth in `f64` before it becomes `f32`, as the API
//! writes it, so the HTTP environment and the in-process one build the same vector bit for
//! bit. Sectors are told apart by comparisons, not by `atan2`, so no platform's libm is in
//! the answer. Nothing here reads the truth: only the roles a robot's tracker holds.

use nalgebra::{Point2, Vector2};

use crate::nav::ReachCache;
use crate::sim::Pose;
use crate::sim::arena::ClearanceGrid;
use crate::tracker::Role;

/// Bearing sectors of the grid, 45° each.
pub const SECTORS: usize = 8;
/// Distance rings of the grid: nearer than [`NEAR_RING_M`], and the rest.
pub const RINGS: usize = 2;
/// Cells of the grid.
pub const GRID_CELLS: usize = SECTORS * RINGS;
/// Metres: the inner ring's radius (about where a robot's tag device reaches well).
pub const NEAR_RING_M: f64 = 4.0;
/// Metres of travel within which belief mass is sorted by the way to walk to it (the search
/// stops there: a robot's few metres cost a fraction of a whole map's field).
pub const PATH_REACH_M: f32 = 6.0;
/// Metres along a shortest path to the point whose bearing sorts the mass at its end.
pub const PATH_AHEAD_M: f32 = 1.0;
/// Untagged roles summarised, nearest first.
pub const ROLE_SLOTS: usize = 2;
/// Values of one role's summary: present, count share, ahead, left, spread, confidence,
/// looked-at-in-vain.
pub const ROLE_VALUES: usize = 7;
/// Metres: a role's mean ahead and to the left is divided by this (and clipped to ±1).
pub const POSITION_SCALE_M: f64 = 10.0;
/// Metres: a cloud's spread is divided by this (and saturates at 1).
pub const SPREAD_SCALE_M: f64 = 5.0;
/// Ticks: a role's run of looks in vain is divided by this (and saturates at 1).
pub const UNSEEN_SCALE_TICKS: f64 = 100.0;
/// Every value of the features: the grid, the path sectors, the role slots, the untagged
/// share.
pub const VALUES: usize = GRID_CELLS + SECTORS + ROLE_SLOTS * ROLE_VALUES + 1;

/// One robot's belief features (see the module's documentation), each already rounded to a
/// ten-thousandth.
#[derive(Debug, Clone, PartialEq)]
pub struct BeliefFeatures {
    pub grid: [f64; GRID_CELLS],
    /// The share of the untagged opponents within [`PATH_REACH_M`] of travel, by the sector
    /// one sets off in to reach them (sums to at most 1).
    pub paths: [f64; SECTORS],
    pub roles: [[f64; ROLE_VALUES]; ROLE_SLOTS],
    pub untagged: f64,
}

impl Default for BeliefFeatures {
    fn default() -> Self {
        BeliefFeatures {
            grid: [0.0; GRID_CELLS],
            paths: [0.0; SECTORS],
            roles: [[0.0; ROLE_VALUES]; ROLE_SLOTS],
            untagged: 0.0,
        }
    }
}

impl BeliefFeatures {
    /// The features of `roles` seen from `pose` (the robot's own estimate), in a match of
    /// `opponents` opponents on the arena whose clearance grid is `nav`.
    pub fn of(roles: &[Role], pose: Pose, opponents: usize, nav: &ClearanceGrid) -> BeliefFeatures {
        BeliefFeatures::of_with(roles, pose, opponents, nav, &mut ReachCache::default())
    }

    /// [`BeliefFeatures::of`] with the robot's own [`ReachCache`]: the same values, without
    /// a search while the robot's estimate stays in a cell the cache has a field from.
    pub fn of_with(
        roles: &[Role],
        pose: Pose,
        opponents: usize,
        nav: &ClearanceGrid,
        reach: &mut ReachCache,
    ) -> BeliefFeatures {
        let mut out = BeliefFeatures::default();
        let (sin, cos) = (pose.theta as f64).sin_cos();
        let origin = Vector2::new(pose.pos.x as f64, pose.pos.y as f64);
        // Into the robot's frame: x ahead, y to the left.
        let local = |p: Point2<f32>| {
            let d = Vector2::new(p.x as f64, p.y as f64) - origin;
            Vector2::new(d.x * cos + d.y * sin, -d.x * sin + d.y * cos)
        };
        let untagged: Vec<&Role> = roles.iter().filter(|r| !r.tagged && r.count > 0).collect();
        // A fold from +0 (an empty `sum` of floats is -0, which the API would write as
        // "-0.0" and a JSON reader may read as 0: the two environments would differ).
        let total = untagged.iter().fold(0.0f64, |t, r| t + r.count as f64);
        let mut grid = [0.0f64; GRID_CELLS];
        let mut paths = [0.0f64; SECTORS];
        let ways = reach.ways(nav, pose.pos, PATH_REACH_M, PATH_AHEAD_M);
        // The bearing sector of each waypoint, worked out when a particle first needs it:
        // a thousand particles share a few hundred waypoints.
        let mut way_sectors = vec![UNKNOWN; ways.map_or(0, |m| m.waypoints().len())];
        let mut summaries: Vec<(f64, [f64; ROLE_VALUES])> = Vec::with_capacity(untagged.len());
        let mut scratch: Vec<(Vector2<f64>, f64)> = Vec::new();
        for role in &untagged {
            let (particles, weights) = (role.particles(), role.weights());
            let sum_w = weights.iter().fold(0.0f64, |t, w| t + *w as f64);
            if particles.is_empty() || !(sum_w > 0.0 && sum_w.is_finite()) {
                continue;
            }
            let share = role.count as f64 / total;
            // Each particle's weight share and place in the robot's frame, worked out once
            // for both passes below (the same values the passes would each work out).
            scratch.clear();
            scratch.extend(
                particles
                    .iter()
                    .zip(weights)
                    .map(|(p, w)| (local(*p), *w as f64 / sum_w)),
            );
            let mut mean = Vector2::zeros();
            for (p, &(l, w)) in particles.iter().zip(&scratch) {
                grid[cell(l)] += share * w;
                if let Some((id, m)) = ways.and_then(|m| Some((m.id_ahead(nav, *p)?, m))) {
                    let s = &mut way_sectors[id];
                    if *s == UNKNOWN {
                        *s = sector(local(nav.centre(m.waypoints()[id]))) as u8;
                    }
                    paths[*s as usize] += share * w;
                }
                mean += l * w;
            }
            let mut var = 0.0;
            for &(l, w) in &scratch {
                var += w * (l - mean).norm_squared();
            }
            let summary = [
                1.0,
                role.count as f64 / opponents.max(1) as f64,
                (mean.x / POSITION_SCALE_M).clamp(-1.0, 1.0),
                (mean.y / POSITION_SCALE_M).clamp(-1.0, 1.0),
                (var.sqrt() / SPREAD_SCALE_M).min(1.0),
                (role.confidence as f64).clamp(0.0, 1.0),
                (role.unseen_run as f64 / UNSEEN_SCALE_TICKS).min(1.0),
            ];
            summaries.push((mean.norm_squared(), summary));
        }
        // Nearest first; equals keep the tracker's order (a stable sort).
        summaries.sort_by(|a, b| a.0.total_cmp(&b.0));
        for (slot, (_, s)) in out.roles.iter_mut().zip(&summaries) {
            for (v, x) in slot.iter_mut().zip(s) {
                *v = round4(*x);
            }
        }
        for (v, x) in out.grid.iter_mut().zip(grid) {
            *v = round4(x);
        }
        for (v, x) in out.paths.iter_mut().zip(paths) {
            *v = round4(x);
        }
        out.untagged = round4((total / opponents.max(1) as f64).min(1.0));
        out
    }

    /// Every value in the layout's order: the grid, the path sectors, the role slots, the
    /// untagged share.
    pub fn values(&self) -> impl Iterator<Item = f64> + '_ {
        self.grid
            .iter()
            .chain(&self.paths)
            .chain(self.roles.iter().flatten())
            .chain(std::iter::once(&self.untagged))
            .copied()
    }
}

/// A waypoint's sector not yet worked out.
const UNKNOWN: u8 = u8::MAX;

/// A ten-thousandth, as the API writes these values.
fn round4(v: f64) -> f64 {
    (v * 10_000.0).round() / 10_000.0
}

/// The grid cell of a point in the robot's frame: its sector (see [`sector`]), then its
/// ring.
fn cell(l: Vector2<f64>) -> usize {
    let ring = if l.x * l.x + l.y * l.y < NEAR_RING_M * NEAR_RING_M {
        0
    } else {
        1
    };
    ring * SECTORS + sector(l)
}

/// The 45° sector of a point in the robot's frame, counted counter-clockwise from straight
/// ahead (sector 0 spans 0°..45° to the left).
fn sector(l: Vector2<f64>) -> usize {
    let (x, y) = (l.x, l.y);
    // Octants by comparisons: which half-plane, which quadrant, which side of the diagonal.
    if y >= 0.0 {
        if x > 0.0 {
            if y < x { 0 } else { 1 }
        } else if y > -x {
            2
        } else {
            3
        }
    } else if x <= 0.0 {
        if -y < -x { 4 } else { 5 }
    } else if -y > x {
        6
    } else {
        7
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sectors_go_counter_clockwise_from_ahead() {
        let at = |deg: f64, r: f64| {
            let a = deg.to_radians();
            cell(Vector2::new(r * a.cos(), r * a.sin()))
        };
        for k in 0..8 {
            assert_eq!(at(22.5 + 45.0 * k as f64, 1.0), k, "sector {k}");
            assert_eq!(at(22.5 + 45.0 * k as f64, 6.0), 8 + k, "far sector {k}");
        }
    }

    #[test]
    fn mass_sums_to_one_and_sits_where_the_cloud_is() {
        let ahead = role(vec![Point2::new(5.0, 1.0); 10]);
        // Facing +x from the origin: the cloud is 5 m ahead, a little to the left.
        let f = BeliefFeatures::of(
            &[ahead],
            Pose {
                pos: Point2::new(0.0, 0.0),
                theta: 0.0,
            },
            2,
            &room().grid,
        );
        assert_eq!(f.grid[8], 1.0, "{:?}", f.grid);
        assert_eq!(f.grid.iter().sum::<f64>(), 1.0);
        assert_eq!(f.roles[0][..4], [1.0, 0.5, 0.5, 0.1]);
        assert_eq!(f.roles[1], [0.0; ROLE_VALUES]);
        assert_eq!(f.untagged, 0.5);
        // From past the cloud, facing the same way: behind, a little to the right.
        let g = BeliefFeatures::of(
            &[role(vec![Point2::new(5.0, 1.0); 10])],
            Pose {
                pos: Point2::new(10.0, 1.5),
                theta: 0.0,
            },
            2,
            &room().grid,
        );
        assert_eq!(g.grid[8 + 4], 1.0, "{:?}", g.grid);
        // A turn of the robot turns the grid: facing -x, the cloud is ahead.
        let h = BeliefFeatures::of(
            &[role(vec![Point2::new(5.0, 1.0); 10])],
            Pose {
                pos: Point2::new(10.0, 1.5),
                theta: std::f32::consts::PI,
            },
            2,
            &room().grid,
        );
        assert_eq!(h.grid[8], 1.0, "{:?}", h.grid);
    }

    #[test]
    fn tagged_roles_are_left_out_and_nearest_roles_come_first() {
        let mut gone = role(vec![Point2::new(1.0, 0.0); 4]);
        gone.tagged = true;
        let far = role(vec![Point2::new(8.0, 0.0); 4]);
        let near = role(vec![Point2::new(2.0, 0.0); 4]);
        let f = BeliefFeatures::of(
            &[gone, far, near],
            Pose {
                pos: Point2::origin(),
                theta: 0.0,
            },
            3,
            &room().grid,
        );
        assert_eq!(f.roles[0][2], 0.2);
        assert_eq!(f.roles[1][2], 0.8);
        assert_eq!(f.untagged, 0.6667);
        assert_eq!(f.grid[0], 0.5);
        assert_eq!(f.grid[8], 0.5);
        assert_eq!(f.values().count(), VALUES);
    }

    #[test]
    fn paths_sort_the_mass_by_the_way_to_walk_to_it() {
        // Beyond the wall at x = 5 and a little ahead, to the robot's right as the crow
        // flies; the way there sets off straight ahead, to the door at its north end.
        let a = two_rooms();
        let facing_north = Pose {
            pos: Point2::new(4.2, 2.0),
            theta: std::f32::consts::FRAC_PI_2,
        };
        let f = BeliefFeatures::of(
            &[role(vec![Point2::new(6.0, 2.5); 10])],
            facing_north,
            1,
            &a.grid,
        );
        assert_eq!(f.grid[6], 1.0, "{:?}", f.grid);
        assert_eq!(f.paths[0] + f.paths[7], 1.0, "{:?}", f.paths);
        // Mass farther than the reach in travel is left out of the paths (not of the grid).
        let far = BeliefFeatures::of(
            &[role(vec![Point2::new(9.5, 0.5); 10])],
            Pose {
                pos: Point2::new(0.5, 0.5),
                theta: 0.0,
            },
            1,
            &a.grid,
        );
        assert_eq!(far.paths, [0.0; SECTORS]);
        assert_eq!(far.grid.iter().sum::<f64>(), 1.0);
        assert_eq!(far.values().count(), VALUES);
    }

    /// An empty room 12 m × 6 m.
    fn room() -> crate::sim::arena::Arena {
        crate::sim::arena::open_room([1.0, 1.0, 0.0])
    }

    /// Two rooms 10 m × 6 m in all, joined by a door (y 4.0–5.2) in a wall at x = 5.
    fn two_rooms() -> crate::sim::arena::Arena {
        let slab = |y0: f32, y1: f32| {
            vec![
                Point2::new(4.9, y0),
                Point2::new(5.1, y0),
                Point2::new(5.1, y1),
                Point2::new(4.9, y1),
            ]
        };
        crate::sim::arena::Arena::new(crate::sim::arena::MapDef {
            name: "two".into(),
            width: 10.0,
            height: 6.0,
            obstacles: vec![slab(0.0, 4.0), slab(5.2, 6.0)],
            robot_spawns: vec![[1.0, 1.0, 0.0]],
            opponent_spawns: vec![Point2::new(9.0, 1.0)],
            landmarks: vec![],
        })
    }

    fn role(particles: Vec<Point2<f32>>) -> Role {
        let n = particles.len();
        Role {
            id: 1,
            count: 1,
            tagged: false,
            weights: vec![1.0 / n as f32; n],
            steps: vec![Vector2::zeros(); n],
            particles,
            unseen_run: 0,
            confidence: 1.0,
        }
    }
}
