//! The paper's baseline planner (section 4.3): every few seconds the robots, one at a time,
//! pick a random reachable destination `(x, y, heading)` on a coarse grid, discouraged from
//! points near those their teammates already picked and from long trips; they drive there
//! along a shortest path and chase whatever they detect. It keeps no memory of opponents.

use nalgebra::Point2;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use crate::nav::{DistanceField, PathFollower, steer, turn_to};
use crate::planner::pursuit::{around_the_corner, engage, nearest_sighting, pursuit_goal};
use crate::planner::view::{Knowledge, RobotCommand, TeamView};
use crate::radio::Status;
use crate::sim::arena::Arena;
use crate::sim::views::candidate_points;
use crate::sim::{Motion, Physics, Pose};

/// Ticks between negotiation rounds (8 s).
pub const ROUND_TICKS: u64 = 160;
/// Spacing of the candidate destination grid (metres) and its number of headings.
pub const CANDIDATE_SPACING: f32 = 1.0;
pub const HEADINGS: usize = 8;
/// Value lost per second of travel (the random part of a value is in [0, 1)).
const TRAVEL_WEIGHT: f32 = 1.0 / 60.0;
/// Value lost for a destination on top of a teammate's, falling to 0 at `NEAR_RADIUS`.
const NEAR_WEIGHT: f32 = 1.0;
const NEAR_RADIUS: f32 = 4.0;
/// How long a robot keeps heading for where it last saw an opponent.
const CHASE_MEMORY_TICKS: u64 = 100;
/// A robot that moved less than this in `STUCK_TICKS` picks a new destination.
const STUCK_DISTANCE: f32 = 0.2;
const STUCK_TICKS: u64 = 60;

#[derive(Debug, Clone, Default)]
struct RobotState {
    goal: Option<Pose>,
    path: PathFollower,
    needs_goal: bool,
    chase: Option<(Point2<f32>, u64)>,
    progress: Option<(Point2<f32>, u64)>,
}

#[derive(Debug, Clone)]
pub struct Baseline {
    candidates: Vec<Point2<f32>>,
    robots: Vec<RobotState>,
    rng: ChaCha8Rng,
    next_round: u64,
}

impl Baseline {
    pub fn new(arena: &Arena, robots: usize, rng: ChaCha8Rng) -> Baseline {
        Baseline {
            candidates: candidate_points(arena, CANDIDATE_SPACING),
            robots: vec![RobotState::default(); robots],
            rng,
            next_round: 0,
        }
    }

    /// Robot `i`'s plans as it announces them over the radio: only its goal matters here.
    pub fn status(&self, i: usize) -> Status {
        Status {
            goal: self.robots[i].goal,
            ..Status::default()
        }
    }

    /// This tick's commands. Teammates' goals (the only thing a robot reads of them) come
    /// from `know`: read directly with a perfect radio, as last heard otherwise.
    pub fn decide(
        &mut self,
        arena: &Arena,
        physics: &Physics,
        know: &Knowledge,
        view: &TeamView,
    ) -> Vec<RobotCommand> {
        let tick = view.tick;
        if tick >= self.next_round {
            self.next_round = tick + ROUND_TICKS;
            self.robots.iter_mut().for_each(|r| r.needs_goal = true);
        }
        let mut commands = Vec::with_capacity(view.robots.len());
        for (i, robot) in view.robots.iter().enumerate() {
            if robot.frozen {
                commands.push(RobotCommand {
                    goal: self.robots[i].goal,
                    ..RobotCommand::default()
                });
                continue;
            }
            if let Some((target, range, bearing)) = nearest_sighting(robot) {
                let state = &mut self.robots[i];
                state.chase = Some((target, tick));
                state.needs_goal = true;
                let (motion, tag) = engage(arena, robot, physics, target, range, bearing);
                commands.push(RobotCommand {
                    motion,
                    tag,
                    goal: Some(pursuit_goal(robot.pose, target)),
                });
                continue;
            }
            let state = &mut self.robots[i];
            if let Some((target, seen)) = state.chase {
                if tick < seen + CHASE_MEMORY_TICKS && (target - robot.pose.pos).norm() > 0.5 {
                    // Round the corner `engage` was heading for, if a wall hides the target:
                    // straight at it, the robot would turn back and forth between the two.
                    let via = around_the_corner(arena, robot.pose.pos, target).unwrap_or(target);
                    commands.push(RobotCommand {
                        motion: steer(robot.pose, via, physics.robot_turn_rate),
                        tag: false,
                        goal: Some(pursuit_goal(robot.pose, target)),
                    });
                    continue;
                }
                state.chase = None;
            }
            match state.progress {
                Some((p, t)) if tick >= t + STUCK_TICKS => {
                    if (robot.pose.pos - p).norm() < STUCK_DISTANCE && !state.path.finished() {
                        state.needs_goal = true;
                    }
                    state.progress = Some((robot.pose.pos, tick));
                }
                None => state.progress = Some((robot.pose.pos, tick)),
                _ => {}
            }
            if state.needs_goal || state.goal.is_none() {
                self.choose_goal(arena, physics, know, i, robot.pose);
            }
            let state = &mut self.robots[i];
            let motion = match state.path.target(robot.pose.pos) {
                Some(wp) => steer(robot.pose, wp, physics.robot_turn_rate),
                None => match state.goal {
                    Some(goal) => {
                        let m = turn_to(robot.pose, goal.theta, physics.robot_turn_rate);
                        if m == Motion::Stop {
                            state.needs_goal = true; // arrived and looked: pick the next one
                        }
                        m
                    }
                    None => Motion::Stop,
                },
            };
            commands.push(RobotCommand {
                motion,
                tag: false,
                goal: state.goal,
            });
        }
        commands
    }

    /// Robot `i` picks its next destination, taking its teammates' current ones into account
    /// (as it knows them: see [`Knowledge`]).
    fn choose_goal(
        &mut self,
        arena: &Arena,
        physics: &Physics,
        know: &Knowledge,
        i: usize,
        from: Pose,
    ) {
        let taken: Vec<Point2<f32>> = if know.shared_memory() {
            self.robots
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .filter_map(|(_, r)| r.goal.map(|g| g.pos))
                .collect()
        } else {
            (0..self.robots.len())
                .filter(|&j| j != i)
                .filter_map(|j| know.heard(i, j).and_then(|m| m.status.goal))
                .map(|g| g.pos)
                .collect()
        };
        let state = &mut self.robots[i];
        state.needs_goal = false;
        state.progress = None;
        let Some(field) = DistanceField::from_point(&arena.grid, from.pos) else {
            state.goal = None;
            state.path = PathFollower::default();
            return;
        };
        let mut best: Option<(f32, Point2<f32>, usize)> = None;
        for p in &self.candidates {
            let Some(cell) = arena.grid.cell_of(*p) else {
                continue;
            };
            if !field.reachable(cell) {
                continue;
            }
            let travel_s = field.dist[cell] / physics.robot_speed;
            let crowding: f32 = taken
                .iter()
                .map(|t| (1.0 - (t - p).norm() / NEAR_RADIUS).max(0.0))
                .sum();
            let value =
                self.rng.random::<f32>() - TRAVEL_WEIGHT * travel_s - NEAR_WEIGHT * crowding;
            if best.is_none_or(|(v, _, _)| value > v) {
                best = Some((value, *p, cell));
            }
        }
        let state = &mut self.robots[i];
        match best.and_then(|(_, p, cell)| Some((p, field.path_to(&arena.grid, from.pos, cell)?))) {
            Some((p, path)) => {
                let heading = self.rng.random_range(0..HEADINGS) as f32 * std::f32::consts::TAU
                    / HEADINGS as f32;
                state.goal = Some(Pose {
                    pos: p,
                    theta: crate::sim::wrap_angle(heading),
                });
                state.path = PathFollower::new(path);
            }
            None => {
                state.goal = None;
                state.path = PathFollower::default();
            }
        }
    }
}

crate::checkpoint::plain_struct!(RobotState {
    goal,
    path,
    needs_goal,
    chase,
    progress,
});
crate::checkpoint::restore_struct!(Baseline {
    plain: [robots, rng, next_round],
    nested: [],
    derived: [candidates],
});
