//! Getting robots past each other in doorways and narrow corridors: a robot stuck behind a
//! moving teammate steps off its path and waits for it to pass, or asks it to step aside;
//! stuck behind anything else, it re-plans around its teammates.

use nalgebra::Point2;

use super::{Coordinated, STUCK_TICKS};
use crate::nav::{DistanceField, PathFollower};
use crate::planner::view::{Knowledge, TeamView};
use crate::sim::AGENT_RADIUS;
use crate::sim::arena::Arena;

/// Longest a robot waits off a teammate's path before it goes on with its own plans.
const MAKE_WAY_TICKS: u64 = 160;

/// Distance from `p` to the segment `a`–`b`.
fn segment_distance(p: Point2<f32>, a: Point2<f32>, b: Point2<f32>) -> f32 {
    let ab = b - a;
    let len2 = ab.norm_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + ab * t)).norm()
}

impl Coordinated {
    /// Robot `i` has not moved for a while although its path goes on. Blocked by a moving
    /// teammate (two robots meeting in a doorway or a narrow corridor), the one with the
    /// higher index steps off the other's path and waits for it to pass: a fixed order, so
    /// the two never both give way or both insist. Blocked by anything else (a frozen or
    /// parked teammate, a tight corner), it re-plans around its teammates.
    ///
    /// Over an imperfect radio a robot moves only itself: with the higher index it steps
    /// aside; with the lower it asks the blocker to (in its next message) and waits, and
    /// re-plans around the team if it is still stuck at the next check after asking.
    pub(super) fn unstick(
        &mut self,
        arena: &Arena,
        view: &TeamView,
        know: &Knowledge,
        i: usize,
        tick: u64,
    ) {
        let pos = view.robots[i].pose.pos;
        let blocker = self
            .mates(know, view, i)
            .into_iter()
            .filter(|m| (m.pos - pos).norm() < 1.2)
            .filter(|m| !m.frozen && m.moving)
            .filter(|m| !m.pursuing) // a pursuer follows its target, not its path
            .filter(|m| !m.making_way)
            .min_by(|a, b| (a.pos - pos).norm().total_cmp(&(b.pos - pos).norm()))
            .map(|m| m.index);
        if let Some(j) = blocker {
            if know.shared_memory() || i > j {
                let (yielder, keeper) = (i.max(j), i.min(j));
                if self.make_way(arena, view, know, yielder, keeper, tick) {
                    return;
                }
            } else {
                let asked_already = self.robots[i]
                    .asked
                    .is_some_and(|(k, at)| k == j && tick < at + 2 * STUCK_TICKS);
                if !asked_already {
                    let state = &mut self.robots[i];
                    state.yield_request = Some(j);
                    state.asked = Some((j, tick));
                    state.progress = None;
                    return;
                }
            }
        }
        self.robots[i].replan = true;
        self.robots[i].avoid_team = true;
    }

    /// Sends `yielder` to the nearest point off `keeper`'s remaining path. False when there
    /// is none within reach.
    pub(super) fn make_way(
        &mut self,
        arena: &Arena,
        view: &TeamView,
        know: &Knowledge,
        yielder: usize,
        keeper: usize,
        tick: u64,
    ) -> bool {
        const CLEAR: f32 = 0.9; // centre distance at which two discs pass with room to spare
        const REACH: f32 = 8.0;
        let grid = &arena.grid;
        let from = view.robots[yielder].pose.pos;
        // The keeper's position and remaining route, as the yielder knows them.
        let (keeper_pos, route) = if know.shared_memory() {
            let keeper_pos = view.robots[keeper].pose.pos;
            let k = &self.robots[keeper].path;
            let mut route = vec![keeper_pos];
            route.extend(k.waypoints.iter().skip(k.next).copied());
            (keeper_pos, route)
        } else {
            let Some(m) = know.heard(yielder, keeper) else {
                return false;
            };
            let route = if m.status.route.is_empty() {
                vec![m.pose.pos]
            } else {
                m.status.route.clone()
            };
            (m.pose.pos, route)
        };
        // The keeper's body is a wall for the way out, but no wider than the gap between the
        // two: pressed together (pushed sideways in a corridor, centres 0.5 m apart) a full
        // two-radius disc also closed the cells beside the yielder and boxed it in.
        let gap = (from - keeper_pos).norm() - grid.cell;
        let keeper_disc = (keeper_pos, gap.clamp(grid.cell, 2.0 * AGENT_RADIUS));
        let Some(field) = DistanceField::from_point_avoiding(grid, from, &[keeper_disc]) else {
            return false;
        };
        let off_route = |p: Point2<f32>| {
            route
                .windows(2)
                .all(|w| segment_distance(p, w[0], w[1]) >= CLEAR)
                && (p - keeper_pos).norm() >= CLEAR
        };
        let spot = (0..grid.len())
            .filter(|&c| field.dist[c] <= REACH)
            .filter(|&c| off_route(grid.centre(c)))
            .min_by(|&a, &b| field.dist[a].total_cmp(&field.dist[b]));
        let Some(path) = spot.and_then(|c| field.path_to(grid, from, c)) else {
            return false;
        };
        let state = &mut self.robots[yielder];
        state.path = PathFollower::new(path);
        state.making_way = Some((keeper, tick + MAKE_WAY_TICKS));
        state.replan = false;
        state.progress = None;
        if know.shared_memory() {
            // Over a radio the keeper reset its own when it asked.
            self.robots[keeper].progress = None;
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bots::BotKind;
    use crate::planner::coordinated::test_maps::corridor;
    use crate::planner::coordinated::{Goal, Settings};
    use crate::planner::{Brain, PlannerKind};
    use crate::sim::Pose;
    use crate::world::World;
    use crate::world::{MatchConfig, Placement};

    fn coordinated(world: &mut World) -> &mut Coordinated {
        match &mut world.team.brain {
            Brain::Coordinated(c) => c,
            _ => panic!("a coordinated team"),
        }
    }

    /// Sends robot `i` to the candidate pose nearest `to`, as a negotiation would.
    fn send(world: &mut World, i: usize, to: Point2<f32>) {
        let arena = world.arena.clone();
        let from = world.robots[i].pose.pos;
        let c = coordinated(world);
        let k = c
            .nearest_pose(Pose {
                pos: to,
                theta: 0.0,
            })
            .unwrap();
        let (pos, _) = c.views.pose(k);
        let field = DistanceField::from_point(&arena.grid, from).unwrap();
        let path = field
            .path_to(&arena.grid, from, arena.grid.cell_of(pos).unwrap())
            .unwrap();
        let state = &mut c.robots[i];
        state.goal = Some(Goal {
            pose: k,
            worth: 1.0,
        });
        state.path = PathFollower::new(path);
        state.replan = false;
    }

    #[test]
    fn two_robots_meeting_head_on_in_a_narrow_corridor_both_get_through() {
        let config = MatchConfig {
            robots: 2,
            opponents: 1,
            opponent_bot: BotKind::Idle,
            planner: PlannerKind::Coordinated,
            placement: Placement::Given {
                robots: vec![[2.0, 3.0, 0.0], [14.0, 3.0, std::f32::consts::PI]],
                opponents: vec![[0.9, 5.3]],
            },
            // Goals stay as the test sets them: no rounds, never worthless.
            coordination: Settings {
                round_ticks: u64::MAX / 2,
                worthless_floor: 0.0,
                worthless_share: 0.0,
                ..Settings::default()
            },
            ..MatchConfig::default()
        };
        let mut world = World::new(corridor(), config).unwrap();
        coordinated(&mut world).next_round = u64::MAX / 2;
        send(&mut world, 0, Point2::new(14.5, 3.5));
        send(&mut world, 1, Point2::new(1.5, 2.5));
        let (mut a_through, mut b_through) = (None, None);
        for _ in 0..(60 * 20) {
            world.step();
            if a_through.is_none() && world.robots[0].pose.pos.x > 10.3 {
                a_through = Some(world.tick);
            }
            if b_through.is_none() && world.robots[1].pose.pos.x < 5.7 {
                b_through = Some(world.tick);
            }
        }
        assert!(
            a_through.is_some() && b_through.is_some(),
            "robot 0 through at {a_through:?}, robot 1 at {b_through:?}; poses {:?}",
            world.robots.iter().map(|r| r.pose).collect::<Vec<_>>()
        );
    }
}
