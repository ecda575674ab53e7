//! Scoring for the coordinated planner: the expected opponents per scoring cell (stage 1),
//! teammates' claims on them (stage 2) and each robot's choice of the candidate pose worth
//! the most (stage 3), with the uncertainty-aware terms for landmarks and narrow passages.

use nalgebra::Point2;

use super::search::{self, Ranked};
use super::{Coordinated, Goal};
use crate::nav::{DistanceField, PathFollower, Unwatched, Watch};
use crate::planner::view::{Knowledge, TeamView};
use crate::sim::arena::Arena;
use crate::sim::{AGENT_RADIUS, Physics, Pose, wrap_angle};
use crate::tracker::{Confidence, Tracker};

/// One robot's best choice in a round.
#[derive(Debug, Clone, Copy)]
struct Choice {
    pose: usize,
    value: f32,
    worth: f32,
}

impl Coordinated {
    /// Stage 1: expected opponents per scoring cell. Returns their total.
    pub(super) fn bin_mass(&mut self, tracker: &Tracker) -> f32 {
        self.mass.iter_mut().for_each(|m| *m = 0.0);
        let mut total = 0.0;
        for role in tracker.roles.iter().filter(|r| !r.tagged && r.count > 0) {
            // Active feedback (Coltin et al.): a role the team is no longer sure of is worth
            // checking on, so its hypotheses weigh more than a confirmed role's or a guess's.
            let boost = match role.confidence_state() {
                Confidence::Suspicious => self.settings.suspicious_weight,
                _ => 1.0,
            };
            let count = role.count as f32 * boost;
            for (p, w) in role.particles().iter().zip(role.weights()) {
                if let Some(c) = self.views.cell_of(*p) {
                    self.mass[c] += w * count;
                }
            }
            total += count;
        }
        total
    }

    /// Share of all hypotheses (weighted towards the centre of view) that pose `k` sees.
    fn worth_of(&self, k: usize, total: f32) -> f32 {
        let (cells, centring) = self.views.view(k);
        let cw = self.settings.centring_weight;
        let sum: f32 = cells
            .iter()
            .zip(centring)
            .map(|(&c, &f)| self.mass[c as usize] * (1.0 + cw * f))
            .sum();
        sum / ((1.0 + cw) * total)
    }

    pub(super) fn drop_worthless(&mut self, searching: &[usize], total: f32) {
        for &i in searching {
            if let Some(g) = self.robots[i].goal {
                let now = self.worth_of(g.pose, total);
                if now < self.settings.worthless_floor
                    || now < self.settings.worthless_share * g.worth
                {
                    self.robots[i].replan = true;
                }
            }
        }
    }

    /// Discounts the mass a pose will observe: a teammate is taking care of it.
    fn claim(&mut self, k: usize) {
        let keep = self.settings.claim_keep;
        let views = self.views.clone();
        for &c in views.view(k).0 {
            self.mass[c as usize] *= keep;
        }
    }

    /// The candidate pose nearest to what `pose` sees now.
    pub(super) fn nearest_pose(&self, pose: Pose) -> Option<usize> {
        let h = self.settings.headings;
        let i = self
            .views
            .positions
            .iter()
            .enumerate()
            .min_by(|a, b| {
                (a.1 - pose.pos)
                    .norm_squared()
                    .total_cmp(&(b.1 - pose.pos).norm_squared())
            })?
            .0;
        let step = std::f32::consts::TAU / h as f32;
        let heading =
            (wrap_angle(pose.theta).rem_euclid(std::f32::consts::TAU) / step).round() as usize % h;
        Some(i * h + heading)
    }

    /// Stages 2 and 3 for robot `i`: claim what its teammates will see, then choose.
    pub(super) fn choose(
        &mut self,
        arena: &Arena,
        physics: &Physics,
        view: &TeamView,
        know: &Knowledge,
        i: usize,
        total: f32,
    ) {
        // Claims of robots that keep what they do: pursuers look where they look; searchers
        // that are not choosing keep their goals.
        let mates = self.mates(know, view, i);
        for m in mates.iter().filter(|m| !m.frozen) {
            let j = m.index;
            let k = if know.shared_memory() {
                if view.robots[j].outside && self.settings.outside_claims {
                    self.nearest_pose(super::ahead(view.robots[j].pose))
                } else if self.robots[j].seeing {
                    self.nearest_pose(view.robots[j].pose)
                } else {
                    self.robots[j].goal.map(|g| g.pose)
                }
            } else {
                know.heard(i, j).and_then(|h| h.status.claim)
            };
            if let Some(k) = k.filter(|&k| k < self.views.len()) {
                self.claim(k);
            }
        }
        let taken: Vec<Point2<f32>> = mates
            .iter()
            .filter(|m| !m.frozen)
            .filter_map(|m| m.goal)
            .collect();
        self.score_poses(total);
        let uncertainty = self.uncertainty(view.robots[i].spread);
        // The look-ahead ranks every pose (and follows the robot's current goal, however
        // far): it needs the whole field.
        let (field, narrow) = if self.searching {
            let field = self.field_for(arena, view, know, i, &mut Unwatched);
            let narrow = field
                .as_ref()
                .and_then(|f| self.narrow_metres(f, uncertainty));
            (field, narrow)
        } else {
            let mut watch = self.choice_watch(arena, physics, i, &taken, uncertainty);
            let field = self.field_for(arena, view, know, i, &mut watch);
            (field, watch.into_narrow_metres())
        };
        let best = field.as_ref().and_then(|f| {
            self.best_for(arena, physics, i, f, narrow.as_deref(), &taken, uncertainty)
                .map(|c| (c, f))
        });
        let from = view.robots[i].pose.pos;
        let state = &mut self.robots[i];
        state.replan = false;
        state.due = false;
        state.avoid_team = false;
        state.chosen_at = view.tick;
        let Some((c, field)) = best else {
            // Nothing reachable (walled in by teammates? the next try plans without them).
            state.goal = None;
            state.path = PathFollower::default();
            return;
        };
        let (pos, _) = self.views.pose(c.pose);
        let path = arena
            .grid
            .cell_of(pos)
            .and_then(|cell| field.path_to(&arena.grid, from, cell))
            .unwrap_or_else(|| vec![from]);
        state.goal = Some(Goal {
            pose: c.pose,
            worth: c.worth,
        });
        state.path = PathFollower::new(path);
        state.progress = None;
    }

    fn field_for(
        &self,
        arena: &Arena,
        view: &TeamView,
        know: &Knowledge,
        i: usize,
        watch: &mut impl Watch,
    ) -> Option<DistanceField> {
        let from = view.robots[i].pose.pos;
        if self.robots[i].avoid_team {
            let others: Vec<(Point2<f32>, f32)> = self
                .mates(know, view, i)
                .iter()
                // A teammate pressed against this robot must not wall in its start cell:
                // the disc stops short of it.
                .map(|m| {
                    let gap = (m.pos - from).norm() - 1.5 * arena.grid.cell;
                    (m.pos, (3.0 * AGENT_RADIUS).min(gap.max(0.0)))
                })
                .collect();
            if let Some(f) = DistanceField::from_point_watched(&arena.grid, from, &others, watch) {
                return Some(f);
            }
        }
        DistanceField::from_point_watched(&arena.grid, from, &[], watch)
    }

    /// Per-pose worth under the current (claimed) mass: [`Coordinated::worth_of`] for every
    /// pose, four poses at a time. Each pose's sum is taken in its own order, as one pose at
    /// a time would (so the same bits), but four chains of additions are in flight at once
    /// instead of one, each add waiting on the one before.
    fn score_poses(&mut self, total: f32) {
        const LANES: usize = 4;
        let cw = self.settings.centring_weight;
        let norm = (1.0 + cw) * total;
        self.norm = norm;
        let (views, mass) = (&*self.views, &self.mass[..]);
        let term = |c: u32, f: f32| mass[c as usize] * (1.0 + cw * f);
        let n = views.len();
        let mut k = 0;
        while k + LANES <= n {
            let group: [(&[u32], &[f32]); LANES] = std::array::from_fn(|j| views.view(k + j));
            let common = group.iter().map(|v| v.0.len()).min().unwrap_or(0);
            // `f32`'s `Sum` starts from −0.0: so do these.
            let mut sums = [-0.0f32; LANES];
            for i in 0..common {
                for (sum, (cells, centring)) in sums.iter_mut().zip(&group) {
                    *sum += term(cells[i], centring[i]);
                }
            }
            for (j, (sum, (cells, centring))) in sums.iter_mut().zip(&group).enumerate() {
                for (&c, &f) in cells[common..].iter().zip(&centring[common..]) {
                    *sum += term(c, f);
                }
                self.seen[k + j] = *sum / norm;
            }
            k += LANES;
        }
        for k in k..n {
            self.seen[k] = self.worth_of(k, total);
        }
    }

    /// How uncertain a robot with localisation `spread` counts as: 0 up to
    /// `uncertainty_spread`, rising to 1 at twice that.
    pub(super) fn uncertainty(&self, spread: f32) -> f32 {
        let t = self.settings.uncertainty_spread;
        if spread > t {
            ((spread - t) / t).min(1.0)
        } else {
            0.0
        }
    }

    /// Robot `i`'s best pose given the scored worths. An `uncertainty` above 0 adds
    /// Fabiani & Latombe's trade: destinations that see a landmark gain, paths through
    /// narrow passages (`narrow`: their metres on each cell's path, for a robot that weighs
    /// them) lose.
    #[allow(clippy::too_many_arguments)] // the choice's inputs, each read once
    fn best_for(
        &self,
        arena: &Arena,
        physics: &Physics,
        i: usize,
        field: &DistanceField,
        narrow: Option<&[f32]>,
        chosen: &[Point2<f32>],
        uncertainty: f32,
    ) -> Option<Choice> {
        let s = &self.settings;
        // The `search` planner ranks every pose by the same score, then looks ahead from the
        // best few (see `search`).
        let mut ranked: Vec<Ranked> = Vec::new();
        let h = s.headings;
        let current = self.robots[i].goal.map(|g| g.pose);
        let mut best: Option<Choice> = None;
        for (p_idx, p) in self.views.positions.iter().enumerate() {
            let Some(cell) = arena.grid.cell_of(*p) else {
                continue;
            };
            if !field.reachable(cell) {
                continue;
            }
            let travel_s = field.dist[cell] / physics.robot_speed;
            let crowding: f32 = chosen
                .iter()
                .map(|q| (1.0 - (q - p).norm() / s.crowding_radius).max(0.0))
                .sum();
            let mut cost = s.travel_weight * travel_s + s.crowding_weight * crowding;
            if uncertainty > 0.0 {
                let landmark = if self.sees_landmark[p_idx] {
                    s.landmark_weight
                } else {
                    0.0
                };
                let narrow_m = narrow.map_or(0.0, |n| n[cell]);
                cost += uncertainty * (s.narrow_weight * narrow_m - landmark);
            }
            for k in p_idx * h..(p_idx + 1) * h {
                let keep = if current == Some(k) {
                    s.keep_bonus
                } else {
                    0.0
                };
                let value = self.seen[k] - cost + keep;
                if self.searching {
                    ranked.push(Ranked {
                        pose: k,
                        score: value,
                    });
                    continue;
                }
                if best.is_none_or(|b| value > b.value) {
                    best = Some(Choice {
                        pose: k,
                        value,
                        worth: self.seen[k],
                    });
                }
            }
        }
        if self.searching {
            let firsts = search::firsts(ranked, s.search_branching as usize, current);
            let n = self.search_best(physics, &firsts)?;
            let k = firsts[n].pose;
            return Some(Choice {
                pose: k,
                value: firsts[n].score,
                worth: self.seen[k],
            });
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::planner::coordinated::Settings;
    use crate::planner::coordinated::test_maps::corridor;
    use crate::sim::arena::MapDef;

    /// Robot 0's choice from `from` with `spread`, the mass set by hand.
    fn choice(
        arena: &Arena,
        settings: Settings,
        from: Point2<f32>,
        mass: &[(Point2<f32>, f32)],
        spread: f32,
    ) -> (Point2<f32>, Choice) {
        let physics = Physics::default();
        let mut c = Coordinated::new(arena, &physics, settings, 1);
        let mut total = 0.0;
        for &(p, m) in mass {
            let cell = c.views.cell_of(p).unwrap();
            c.mass[cell] += m;
            total += m;
        }
        c.score_poses(total);
        let field = DistanceField::from_point(&arena.grid, from).unwrap();
        let u = c.uncertainty(spread);
        let narrow = c.narrow_metres(&field, u);
        let best = c
            .best_for(arena, &physics, 0, &field, narrow.as_deref(), &[], u)
            .unwrap();
        (c.views.pose(best.pose).0, best)
    }

    /// An open 10 m × 6 m room with one landmark by its west wall.
    fn room_with_landmark() -> Arena {
        Arena::new(MapDef {
            name: "room".into(),
            width: 10.0,
            height: 6.0,
            obstacles: vec![],
            robot_spawns: vec![[5.0, 3.0, 0.0]],
            opponent_spawns: vec![Point2::new(9.0, 3.0)],
            landmarks: vec![Point2::new(0.5, 3.0)],
        })
    }

    #[test]
    fn an_uncertain_robot_prefers_a_destination_that_sees_a_landmark() {
        let arena = room_with_landmark();
        let from = Point2::new(5.0, 3.0);
        // Hypotheses at either end, too far apart (8.8 m) for one view; a little more of
        // them east, away from the landmark.
        let mass = [(Point2::new(0.6, 3.0), 0.48), (Point2::new(9.4, 3.0), 0.52)];
        let landmark = Point2::new(0.5, 3.0);
        let range = Physics::default().landmark_range;
        let plain = Settings {
            landmark_weight: 0.0,
            narrow_weight: 0.0,
            ..Settings::default()
        };
        let (old, old_choice) = choice(&arena, plain, from, &mass, 0.0);
        assert!(
            old.x > 5.0,
            "without the landmark term it goes east: {old:?}"
        );
        // Localised (spread under the threshold): exactly the old choice, value and all.
        for spread in [0.0, 0.05, 0.15] {
            let (_, c) = choice(&arena, Settings::default(), from, &mass, spread);
            assert_eq!(
                (c.pose, c.value, c.worth),
                (old_choice.pose, old_choice.value, old_choice.worth)
            );
        }
        // Lost (spread twice the threshold): it goes where it can see the landmark.
        let (new, _) = choice(&arena, Settings::default(), from, &mass, 0.3);
        assert!(
            (new - landmark).norm() <= range,
            "goes within sight of the landmark: {new:?}"
        );
    }

    #[test]
    fn an_uncertain_robot_avoids_a_narrow_corridor() {
        let arena = corridor();
        let from = Point2::new(3.0, 3.0);
        // Slightly more hypotheses in the far room's corner (out of sight of the corridor)
        // than in this room's; travel is free, so only the corridor can tell them apart.
        let mass = [
            (Point2::new(15.5, 0.5), 0.53),
            (Point2::new(3.0, 0.5), 0.47),
        ];
        let settings = Settings {
            travel_weight: 0.0,
            ..Settings::default()
        };
        let (sure, sure_choice) = choice(&arena, settings.clone(), from, &mass, 0.1);
        assert!(sure.x > 10.0, "a localised robot goes through: {sure:?}");
        let plain = Settings {
            narrow_weight: 0.0,
            landmark_weight: 0.0,
            ..settings.clone()
        };
        let (_, old) = choice(&arena, plain, from, &mass, 0.1);
        assert_eq!((sure_choice.pose, sure_choice.value), (old.pose, old.value));
        let (unsure, _) = choice(&arena, settings, from, &mass, 0.3);
        assert!(
            unsure.x < 6.0,
            "an uncertain one stays out of the corridor: {unsure:?}"
        );
    }

    /// Scoring four poses at a time gives every pose exactly its own worth, bit for bit.
    #[test]
    fn scoring_all_poses_at_once_gives_each_pose_its_own_worth() {
        use rand::{RngExt, SeedableRng};
        let arena = room_with_landmark();
        let mut c = Coordinated::new(&arena, &Physics::default(), Settings::default(), 1);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut total = 0.0;
        for m in c.mass.iter_mut() {
            *m = if rng.random::<f32>() < 0.3 {
                rng.random::<f32>()
            } else {
                0.0
            };
            total += *m;
        }
        c.score_poses(total);
        assert!(c.views.len() > 8 && c.seen.iter().any(|&w| w > 0.0));
        for k in 0..c.views.len() {
            assert_eq!(
                c.seen[k].to_bits(),
                c.worth_of(k, total).to_bits(),
                "pose {k}"
            );
        }
    }

    /// The field that stops growing once no farther pose can win gives every choice the
    /// whole field gives, pose, value and worth, over random beliefs, starts, teammates'
    /// goals, current goals and localisation spreads (the narrow passages' and landmarks'
    /// terms on and off); and it does stop early.
    #[test]
    fn a_field_grown_only_as_far_as_a_choice_needs_makes_the_same_choice() {
        use rand::{RngExt, SeedableRng};
        let physics = Physics::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut stopped_early = 0;
        for trial in 0..300 {
            let arena = if trial % 2 == 0 {
                corridor()
            } else {
                std::sync::Arc::new(room_with_landmark())
            };
            let settings = Settings {
                keep_bonus: if trial % 3 == 0 { 0.05 } else { 0.0 },
                ..Settings::default()
            };
            let mut c = Coordinated::new(&arena, &physics, settings, 1);
            let (w, h) = (arena.def.width, arena.def.height);
            let point = |rng: &mut rand_chacha::ChaCha8Rng| {
                Point2::new(rng.random::<f32>() * w, rng.random::<f32>() * h)
            };
            let mut total = 0.0;
            for _ in 0..rng.random_range(1..6) {
                let p = point(&mut rng);
                if let Some(cell) = c.views.cell_of(p) {
                    let m = rng.random::<f32>();
                    c.mass[cell] += m;
                    total += m;
                }
            }
            if total == 0.0 {
                continue;
            }
            c.score_poses(total);
            let from = point(&mut rng);
            let taken: Vec<Point2<f32>> = (0..rng.random_range(0..3))
                .map(|_| point(&mut rng))
                .collect();
            if rng.random::<f32>() < 0.5 {
                let pose = rng.random_range(0..c.views.len());
                c.robots[0].goal = Some(Goal { pose, worth: 0.5 });
            }
            let spread = [0.0, 0.2, 0.3][rng.random_range(0..3)];
            let u = c.uncertainty(spread);
            let Some(whole) = DistanceField::from_point(&arena.grid, from) else {
                continue;
            };
            let mut watch = c.choice_watch(&arena, &physics, 0, &taken, u);
            let grown =
                DistanceField::from_point_watched(&arena.grid, from, &[], &mut watch).unwrap();
            let whole_narrow = c.narrow_metres(&whole, u);
            let grown_narrow = watch.into_narrow_metres();
            assert_eq!(whole_narrow.is_some(), grown_narrow.is_some());
            let full = c.best_for(
                &arena,
                &physics,
                0,
                &whole,
                whole_narrow.as_deref(),
                &taken,
                u,
            );
            let part = c.best_for(
                &arena,
                &physics,
                0,
                &grown,
                grown_narrow.as_deref(),
                &taken,
                u,
            );
            // The narrow metres summed as the field grew are the whole field's, cell by
            // cell, wherever the field settled.
            if let (Some(w), Some(g)) = (&whole_narrow, &grown_narrow) {
                for cell in 0..g.len() {
                    if g[cell].is_finite() {
                        assert_eq!(
                            g[cell].to_bits(),
                            w[cell].to_bits(),
                            "trial {trial}, cell {cell}"
                        );
                    }
                }
            }
            assert_eq!(
                full.map(|b| (b.pose, b.value.to_bits(), b.worth.to_bits())),
                part.map(|b| (b.pose, b.value.to_bits(), b.worth.to_bits())),
                "trial {trial}"
            );
            let settled = |f: &DistanceField| f.dist.iter().filter(|d| d.is_finite()).count();
            if settled(&grown) < settled(&whole) {
                stopped_early += 1;
            }
        }
        assert!(stopped_early > 50, "{stopped_early}");
    }
}
