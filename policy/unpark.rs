//! A served team's guard against parking: a robot that has stood still for
//! [`UNPARK_AFTER_TICKS`] while an opponent is untagged is walked, for a while, to where its
//! team's belief puts the most weight, and then handed back to the policy.
//!
//! Why: a policy is a deterministic function of what a robot sees, and where it sees the same
//! thing tick after tick (an empty room, a belief that no longer moves) it can give the same
//! "stand" action for the rest of the match. A person who hides and waits then beats the team
//! by waiting. The walk is the belief's own answer to "where is the opponent likely to be",
//! the question the robot stopped asking, and it ends once the robot, off its spot, sees an
//! opponent: chasing is the policy's.
//!
//! What the guard reads is what the robot knows: its odometry (which moves when its wheels
//! move, so standing and turning on the spot read as still, as they look to a person), its
//! own detections, its pose estimate and the belief it holds. A walk is a `Waypoints` order,
//! recorded like any order, so replays and resumed matches never need the guard. A resumed
//! match's guard starts afresh: a robot may then stand one more [`UNPARK_AFTER_TICKS`].

use std::collections::VecDeque;

use lasertag_core::sim::still::STILL_RADIUS_M;
use lasertag_core::world::{RobotOrder, World};
use nalgebra::Point2;

/// Ticks a robot may stand still before it is walked on: 5 s, half the 10 s a robot of a
/// served team should never stand while hunting.
pub const UNPARK_AFTER_TICKS: u64 = 100;
/// The longest a walk lasts before the policy drives again: 10 s.
const WALK_TICKS: u64 = 200;
/// A walk that stands still this long gave out (its way blocked by a teammate, say): 2 s.
const WALK_STUCK_TICKS: u64 = 40;
/// A walk ends this close to its goal (m).
const ARRIVED_M: f32 = 0.5;
/// A walk's goal is at least this far from the robot (m), when the belief has weight there.
const MIN_GOAL_M: f32 = 2.0;
/// The radius (m) over which a candidate goal's belief weight is summed.
const GOAL_NEIGHBOURHOOD_M: f32 = 1.5;
/// Particles tried as goals: enough to find the belief's heavy places, few enough that
/// summing each one's neighbourhood stays a few hundred thousand operations a walk.
const GOAL_CANDIDATES: usize = 64;

/// One robot's guard.
#[derive(Debug, Clone, Default)]
pub struct Unpark {
    /// Where its odometry was on its decision ticks over the last [`UNPARK_AFTER_TICKS`].
    trail: VecDeque<(u64, Point2<f32>)>,
    walk: Option<Walk>,
}

#[derive(Debug, Clone, Copy)]
struct Walk {
    goal: Point2<f32>,
    until_tick: u64,
    /// Where the robot's odometry stood when the walk began.
    from: Point2<f32>,
}

/// What the guard decides for a robot on a decision tick.
#[derive(Debug, Clone, PartialEq)]
pub enum Decision {
    /// The policy drives.
    Policy,
    /// A walk goes on: no new order.
    Walking,
    /// Start a walk with this order.
    Start(RobotOrder),
}

impl Unpark {
    /// The decision for robot `i` of `world` on this tick.
    pub fn decide(&mut self, world: &World, i: usize) -> Decision {
        let tick = world.tick;
        let robot = &world.robots[i];
        if world.robot_frozen(i) {
            // It cannot move: its standing does not count, and a walk starts over.
            *self = Unpark::default();
            return Decision::Policy;
        }
        let at = robot.odometry.pos;
        self.note(tick, at);
        if let Some(walk) = self.walk {
            let arrived = (robot.estimate.pos - walk.goal).norm() <= ARRIVED_M;
            // A sighting hands the robot back to the policy once the walk has taken it off
            // the spot: a policy that stood while seeing an opponent would stand again.
            let moved = (at - walk.from).norm() > STILL_RADIUS_M;
            let sees = moved && !robot.scan.detections.is_empty();
            let stuck = self.stood(tick, WALK_STUCK_TICKS);
            if !(arrived || sees || tick >= walk.until_tick || stuck) {
                return Decision::Walking;
            }
            self.walk = None;
            self.trail.clear();
            return Decision::Policy;
        }
        if !self.stood(tick, UNPARK_AFTER_TICKS) {
            return Decision::Policy;
        }
        let Some(goal) = walk_goal(world, i) else {
            return Decision::Policy;
        };
        self.walk = Some(Walk {
            goal,
            until_tick: tick + WALK_TICKS,
            from: at,
        });
        self.trail.clear();
        Decision::Start(RobotOrder::Waypoints(vec![goal]))
    }

    /// The robot was at `at` on tick `tick`.
    fn note(&mut self, tick: u64, at: Point2<f32>) {
        self.trail.push_back((tick, at));
        // Kept: the last point at or before the window's start, and every one after it.
        while self
            .trail
            .get(1)
            .is_some_and(|(t, _)| t + UNPARK_AFTER_TICKS <= tick)
        {
            self.trail.pop_front();
        }
    }

    /// Whether the robot has stood for the last `ticks`: the trail reaches that far back and
    /// every point of it since is within twice [`STILL_RADIUS_M`] of where it is now. A
    /// robot that stayed within the radius of any one point for `ticks` stood so (any two
    /// of its points are within twice the radius), whatever point a measurement of its
    /// spell took as the centre: the guard cannot be later than the measurement.
    fn stood(&self, tick: u64, ticks: u64) -> bool {
        let (Some(&(first, _)), Some(&(_, now))) = (self.trail.front(), self.trail.back()) else {
            return false;
        };
        first + ticks <= tick
            && self
                .trail
                .iter()
                .filter(|(t, _)| t + ticks >= tick)
                .all(|(_, p)| (p - now).norm() <= 2.0 * STILL_RADIUS_M)
    }
}

/// Where robot `i` walks: the particle of its belief's untagged roles with the most belief
/// weight within [`GOAL_NEIGHBOURHOOD_M`], of those at least [`MIN_GOAL_M`] away; else the
/// farthest particle; else (no belief at all) the farthest opponent spawn. Only a goal the
/// navigation grid has a free cell near.
fn walk_goal(world: &World, i: usize) -> Option<Point2<f32>> {
    let from = world.robots[i].estimate.pos;
    let grid = &world.arena.grid;
    // A waypoint order takes a point within half a metre of where a robot fits.
    let rings = (0.5 / grid.cell).ceil() as usize;
    let reachable = |p: &Point2<f32>| grid.nearest_passable(*p, rings).is_some();
    // Each untagged role's cloud, its weights scaled by the opponents it stands for.
    let mut cloud: Vec<(Point2<f32>, f32)> = Vec::new();
    if let Some(tracker) = world.team.belief_of(i, world.robots.len()) {
        for role in tracker.roles.iter().filter(|r| !r.tagged) {
            let count = role.count as f32;
            cloud.extend(
                role.particles()
                    .iter()
                    .zip(role.weights())
                    .map(|(p, w)| (*p, w * count)),
            );
        }
    }
    let stride = cloud.len().div_ceil(GOAL_CANDIDATES).max(1);
    let near = GOAL_NEIGHBOURHOOD_M * GOAL_NEIGHBOURHOOD_M;
    let best = cloud
        .iter()
        .step_by(stride)
        .filter(|(p, _)| (p - from).norm() >= MIN_GOAL_M && reachable(p))
        .map(|(c, _)| {
            let weight: f32 = cloud
                .iter()
                .filter(|(p, _)| (p - c).norm_squared() <= near)
                .map(|(_, w)| w)
                .sum();
            (*c, weight)
        })
        // The first of equals: the same goal on every machine.
        .fold(
            None,
            |best: Option<(Point2<f32>, f32)>, (c, w)| match best {
                Some((_, bw)) if bw >= w => best,
                _ => Some((c, w)),
            },
        );
    if let Some((goal, _)) = best {
        return Some(goal);
    }
    let farthest = |points: &mut dyn Iterator<Item = Point2<f32>>| {
        points
            .filter(|p| (p - from).norm() > ARRIVED_M && reachable(p))
            .fold(None, |best: Option<Point2<f32>>, p| match best {
                Some(b) if (b - from).norm() >= (p - from).norm() => best,
                _ => Some(p),
            })
    };
    farthest(&mut cloud.iter().map(|(p, _)| *p))
        .or_else(|| farthest(&mut world.arena.def.opponent_spawns.iter().copied()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use lasertag_core::sim::still::LongestStill;

    #[test]
    fn a_robot_is_judged_standing_within_the_time_any_measured_spell_takes() {
        // It drives in from the left, then rocks between x = 1.0 and 1.24 every decision,
        // deciding every 3 ticks: a measured spell may centre anywhere on that stretch.
        let (mut guard, mut measured) = (Unpark::default(), LongestStill::default());
        let mut judged = None;
        for tick in (0..400).step_by(3) {
            let x = if tick < 30 {
                tick as f32 / 30.0
            } else {
                1.0 + 0.24 * ((tick / 3) % 2) as f32
            };
            let at = Point2::new(x, 2.0);
            guard.note(tick, at);
            measured.push(0, at, tick);
            if guard.stood(tick, UNPARK_AFTER_TICKS) {
                judged = Some(tick);
                break;
            }
        }
        let judged = judged.expect("judged standing");
        assert!(
            measured.longest_ticks() <= UNPARK_AFTER_TICKS + 3,
            "judged at tick {judged}, when the measured spell was {} ticks",
            measured.longest_ticks()
        );
        // It came within twice the radius of x = 1.0, where it rocks from, at tick 15: the
        // window of the last 100 ticks may begin up to a decision before.
        assert!(
            judged + 3 >= 15 + UNPARK_AFTER_TICKS,
            "judged while driving: {judged}"
        );
    }
}
