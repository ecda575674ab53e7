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

use lasertag_core::sim::still::{STILL_RADIUS_M, StillSpell};
use lasertag_core::world::{RobotOrder, World};
use nalgebra::Point2;

/// Ticks a robot may stand still (within its radius of one point) before it is walked on:
/// 5 s, half the 10 s a robot of a served team should never stand while hunting, so that a
/// robot that stood on a spot it then rocks around is still walked well inside them.
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
    spell: Option<StillSpell>,
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
            // It cannot move: no spell, and a walk starts over once it can.
            *self = Unpark::default();
            return Decision::Policy;
        }
        let at = robot.odometry.pos;
        let spell = self.spell.get_or_insert(StillSpell::new(at, tick));
        let still = spell.update(at, tick);
        if let Some(walk) = self.walk {
            let arrived = (robot.estimate.pos - walk.goal).norm() <= ARRIVED_M;
            // A sighting hands the robot back to the policy once the walk has taken it off
            // the spot: a policy that stood while seeing an opponent would stand again.
            let moved = (at - walk.from).norm() > STILL_RADIUS_M;
            let sees = moved && !robot.scan.detections.is_empty();
            if !(arrived || sees || tick >= walk.until_tick || still >= WALK_STUCK_TICKS) {
                return Decision::Walking;
            }
            self.walk = None;
            *spell = StillSpell::new(at, tick);
            return Decision::Policy;
        }
        if still < UNPARK_AFTER_TICKS {
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
        *spell = StillSpell::new(at, tick);
        Decision::Start(RobotOrder::Waypoints(vec![goal]))
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
