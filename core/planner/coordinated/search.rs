//! The `search` planner's choice: the coordinated planner's belief, claims and negotiation,
//! with each robot choosing its next view pose by looking several poses ahead rather than
//! one (docs/search-planner.md).
//!
//! A plan is a sequence of view poses. Its value is the coordinated planner's score of its
//! first pose (the share of the team's claimed hypotheses it sees, less the travel and the
//! other costs) plus `search_weight` times the value of the rest: the share each later pose
//! would see for the first time, discounted by how long after the arrival at the first pose
//! the robot gets there (`0.5^(t / search_half_life)`). What an earlier pose of the plan
//! already saw counts nothing again (negative information along the simulated views). The
//! first pose of the best plan is the robot's goal; the rest is only the reason for it, and
//! the robot chooses again on its next turn.
//!
//! The search is a depth-first look-ahead, `search_depth` poses deep, that follows at each
//! level the `search_branching` continuations worth the most on their own (a beam search over
//! macro-actions "go to that pose and look"). The first level ranks every candidate pose;
//! deeper levels rank a shortlist of the poses that see the most. Travel to the first pose
//! is the robot's distance field; between later poses, the travel between their positions
//! ([`PositionTravel`], one table per map). The belief is held still over the plan: the
//! tracker moves it every tick and the robot chooses again within seconds.

use nalgebra::Point2;

use super::travel::PositionTravel;
use super::{Coordinated, Settings};
use crate::sim::Physics;
use crate::sim::arena::Arena;
use crate::sim::views::ViewTable;

/// Poses that see the most, ranked for the levels after the first.
pub const SHORTLIST: usize = 32;
/// Seconds a robot spends at a pose turning and looking before it leaves for the next.
const DWELL_S: f32 = 1.0;

/// The look-ahead's state while it descends: which level first saw each scoring cell.
struct Plan<'a> {
    views: &'a ViewTable,
    mass: &'a [f32],
    centring_weight: f32,
    norm: f32,
    /// `seen_at[c]`: the level (from 1) whose pose first saw cell `c`, 0 if none yet.
    seen_at: Vec<u8>,
}

impl Plan<'_> {
    /// The share of hypotheses pose `k` sees that no earlier pose of the plan saw.
    fn fresh(&self, k: usize) -> f32 {
        let (cells, centring) = self.views.view(k);
        let cw = self.centring_weight;
        let sum: f32 = cells
            .iter()
            .zip(centring)
            .filter(|(c, _)| self.seen_at[**c as usize] == 0)
            .map(|(&c, &f)| self.mass[c as usize] * (1.0 + cw * f))
            .sum();
        sum / self.norm
    }

    /// Marks what pose `k` sees as seen at `level`.
    fn look(&mut self, k: usize, level: u8) {
        for &c in self.views.view(k).0 {
            let s = &mut self.seen_at[c as usize];
            if *s == 0 {
                *s = level;
            }
        }
    }

    /// Undoes [`Plan::look`] at `level`.
    fn unlook(&mut self, k: usize, level: u8) {
        for &c in self.views.view(k).0 {
            let s = &mut self.seen_at[c as usize];
            if *s == level {
                *s = 0;
            }
        }
    }
}

/// A candidate first pose of a plan and the coordinated planner's score of it.
#[derive(Debug, Clone, Copy)]
pub(super) struct Ranked {
    pub pose: usize,
    /// Its worth less travel, crowding and the uncertainty terms, plus the keep bonus: the
    /// coordinated planner's score, to which the plan's rest is added.
    pub score: f32,
}

impl Coordinated {
    /// The `search` planner: the same negotiation, each choice a look-ahead.
    pub fn searching(arena: &Arena, physics: &Physics, settings: Settings, robots: usize) -> Self {
        let mut planner = Coordinated::new(arena, physics, settings, robots);
        planner.travel = PositionTravel::of(arena, &planner.views);
        planner.searching = true;
        planner
    }

    /// Whether this is the `search` planner.
    pub fn is_searching(&self) -> bool {
        self.searching
    }

    /// The plan's value after first steps `firsts`: for each, its score plus `search_weight`
    /// times the best continuation. Returns the index into `firsts` of the best, or `None`
    /// when there is no first step. Ties go to the earlier entry of `firsts`.
    pub(super) fn search_best(&self, physics: &Physics, firsts: &[Ranked]) -> Option<usize> {
        let s = &self.settings;
        let h = s.headings;
        let mut plan = Plan {
            views: &self.views,
            mass: &self.mass,
            centring_weight: s.centring_weight,
            norm: self.norm,
            seen_at: vec![0; self.views.cell_count()],
        };
        // The shortlist for later levels: the poses that see the most, alone.
        let mut shortlist: Vec<usize> = (0..self.seen.len()).collect();
        best_first(&mut shortlist, SHORTLIST, |&a, &b| {
            self.seen[b].total_cmp(&self.seen[a]).then(a.cmp(&b))
        });
        let discount = |t: f32| 0.5f32.powf(t / s.search_half_life);
        let levels = Continue {
            shortlist: &shortlist,
            travel: self.travel.as_deref(),
            positions: &self.views.positions,
            headings: h,
            speed: physics.robot_speed.max(1e-3),
            branching: s.search_branching as usize,
            discount: &discount,
        };
        let mut best: Option<(usize, f32)> = None;
        for (n, first) in firsts.iter().enumerate() {
            plan.look(first.pose, 1);
            let rest = continuation(&mut plan, &levels, first.pose, 0.0, 2, s.search_depth as u8);
            plan.unlook(first.pose, 1);
            let value = first.score + s.search_weight * rest;
            if best.is_none_or(|(_, v)| value > v) {
                best = Some((n, value));
            }
        }
        best.map(|(n, _)| n)
    }
}

/// What the levels after the first share.
struct Continue<'a> {
    shortlist: &'a [usize],
    travel: Option<&'a PositionTravel>,
    positions: &'a [Point2<f32>],
    headings: usize,
    speed: f32,
    branching: usize,
    discount: &'a dyn Fn(f32) -> f32,
}

/// The best discounted worth of the plan's levels `level..=depth`, from pose `from` reached
/// at `at_s` seconds.
fn continuation(
    plan: &mut Plan,
    c: &Continue,
    from: usize,
    at_s: f32,
    level: u8,
    depth: u8,
) -> f32 {
    if level > depth {
        return 0.0;
    }
    let here = from / c.headings;
    let leave_s = at_s + DWELL_S;
    // Each candidate's discounted fresh worth on its own: the ranking of this level.
    let mut ranked: Vec<(usize, f32, f32)> = c
        .shortlist
        .iter()
        .filter(|&&k| k != from)
        .filter_map(|&k| {
            let there = k / c.headings;
            let metres = match c.travel {
                Some(t) => t.metres(here, there),
                None => (c.positions[there] - c.positions[here]).norm(),
            };
            if !metres.is_finite() {
                return None;
            }
            let arrive = leave_s + metres / c.speed;
            let gain = plan.fresh(k) * (c.discount)(arrive);
            (gain > 0.0).then_some((k, gain, arrive))
        })
        .collect();
    best_first(&mut ranked, c.branching, |a, b| {
        b.1.total_cmp(&a.1).then(a.0.cmp(&b.0))
    });
    let mut best = 0.0f32;
    for (k, gain, arrive) in ranked {
        plan.look(k, level);
        let value = gain + continuation(plan, c, k, arrive, level + 1, depth);
        plan.unlook(k, level);
        best = best.max(value);
    }
    best
}

/// The first steps worth ranking: the `branching` best by score alone, plus the robot's
/// current goal so that keeping it is always weighed.
pub(super) fn firsts(
    mut all: Vec<Ranked>,
    branching: usize,
    current: Option<usize>,
) -> Vec<Ranked> {
    let kept = current.and_then(|g| all.iter().find(|r| r.pose == g).copied());
    best_first(&mut all, branching, |a, b| {
        b.score.total_cmp(&a.score).then(a.pose.cmp(&b.pose))
    });
    if let Some(g) = kept
        && !all.iter().any(|r| r.pose == g.pose)
    {
        all.push(g);
    }
    all
}

/// Keeps the `n` first of `items` in the order `order` (a total order: ties broken), sorted.
/// Selecting them first and sorting only those: each choice ranks a few thousand poses to
/// keep a handful, and a whole sort did most of the look-ahead's work.
fn best_first<T>(items: &mut Vec<T>, n: usize, order: impl Fn(&T, &T) -> std::cmp::Ordering) {
    if items.len() > n {
        if n == 0 {
            items.clear();
            return;
        }
        items.select_nth_unstable_by(n - 1, &order);
        items.truncate(n);
    }
    items.sort_by(order);
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::nav::DistanceField;
    use crate::planner::PlannerKind;
    use crate::sim::arena::MapDef;
    use crate::world::{MatchConfig, MatchStatus, World};

    /// Three rooms off a corridor, so that travel between positions is not a straight line.
    fn rooms() -> Arc<Arena> {
        let wall = |x0: f32, y0: f32, x1: f32, y1: f32| {
            vec![
                Point2::new(x0, y0),
                Point2::new(x1, y0),
                Point2::new(x1, y1),
                Point2::new(x0, y1),
            ]
        };
        Arc::new(Arena::new(MapDef {
            name: "rooms".into(),
            width: 15.0,
            height: 8.0,
            obstacles: vec![
                wall(0.0, 3.9, 1.5, 4.1),
                wall(2.7, 3.9, 6.5, 4.1),
                wall(7.7, 3.9, 11.5, 4.1),
                wall(12.7, 3.9, 15.0, 4.1),
                wall(4.9, 4.1, 5.1, 8.0),
                wall(9.9, 4.1, 10.1, 8.0),
            ],
            robot_spawns: vec![[1.0, 1.0, 0.0], [2.0, 1.0, 0.0]],
            opponent_spawns: vec![Point2::new(13.0, 7.0)],
            landmarks: vec![],
        }))
    }

    fn world(planner: PlannerKind, depth: u64, weight: f32, seed: u64) -> World {
        let mut config = MatchConfig {
            robots: 2,
            opponents: 1,
            planner,
            seed,
            ..MatchConfig::default()
        };
        config.tracker.particles_per_role = 300;
        config.coordination.search_depth = depth;
        config.coordination.search_weight = weight;
        World::new(rooms(), config).unwrap()
    }

    #[test]
    fn the_travel_table_holds_the_distance_fields_both_ways() {
        let arena = rooms();
        let views = ViewTable::of(
            &arena,
            crate::planner::coordinated::Settings::default().view_spec(&arena, &Physics::default()),
        );
        let table = PositionTravel::of(&arena, &views).unwrap();
        let p = &views.positions;
        let (a, b) = (0, p.len() - 1);
        let field = DistanceField::from_point(&arena.grid, p[a]).unwrap();
        assert_eq!(
            table.metres(a, b),
            field.dist[arena.grid.cell_of(p[b]).unwrap()]
        );
        // Through the doors, not through the walls; and about the same either way (the
        // start cell is the nearest passable one, so not always exactly).
        assert!(table.metres(a, b) > (p[b] - p[a]).norm());
        assert!((table.metres(a, b) - table.metres(b, a)).abs() < 0.3);
        assert_eq!(table.metres(a, a), 0.0);
    }

    #[test]
    fn a_plan_valued_by_its_first_pose_alone_is_the_coordinated_choice() {
        // One pose deep, or the rest of the plan weighing nothing: the plan's value is the
        // first pose's score, and ties go to the lower pose as the greedy choice's do.
        for (seed, depth, weight) in [(0, 1, 0.3), (1, 3, 0.0), (2, 1, 0.0)] {
            let mut greedy = world(PlannerKind::Coordinated, 3, 0.3, seed);
            let mut search = world(PlannerKind::Search, depth, weight, seed);
            for _ in 0..400 {
                greedy.step();
                search.step();
            }
            assert_eq!(
                greedy.robots.iter().map(|r| r.pose).collect::<Vec<_>>(),
                search.robots.iter().map(|r| r.pose).collect::<Vec<_>>(),
                "seed {seed}"
            );
        }
    }

    #[test]
    fn a_search_team_is_deterministic_and_finds_the_opponent() {
        let run = |seed| {
            let mut w = world(PlannerKind::Search, 3, 0.3, seed);
            while w.tick < 2400 && w.step() {}
            (w.digest(), w.status)
        };
        for seed in 0..3 {
            let (digest, status) = run(seed);
            assert_eq!(run(seed).0, digest, "seed {seed}");
            assert_eq!(
                status,
                MatchStatus::Finished,
                "seed {seed}: not captured in 2 min"
            );
        }
    }
}
