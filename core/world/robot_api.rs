//! Robots driven from outside (every robot with `PlannerKind::Api`, or those
//! `MatchConfig::outside_robots` names beside planned teammates): the orders a
//! researcher's own robot brain (or a person's keys) gives, and what each robot knows to
//! decide them.
//!
//! The team plans nothing for such robots; at the start of each tick each one's command
//! comes from its last order: velocities that hold until the next order, or a route the
//! built-in path follower drives (planned on the navigation grid around walls, steered from
//! the robot's own pose estimate, never the truth). A tag fires once, on the next tick.
//!
//! An observation carries only what the robot itself has: its scan, detections and
//! landmark sightings, its odometry and pose estimate, its device's readiness and what the
//! radio delivered of its teammates. The referee's truth stays out.

use super::*;
use crate::nav::{PathFollower, ReachCache, path_within, steer};
use crate::tracker::features::BeliefFeatures;

/// Waypoints one order may carry: each is a path search over the navigation grid.
pub const MAX_ROBOT_WAYPOINTS: usize = 16;

/// An order for an API-driven robot.
#[derive(Debug, Clone, PartialEq)]
pub enum RobotOrder {
    /// Fractions of top speed and turn rate in [-1, 1], held until the next order; `tag`
    /// fires the device once, on the next tick (if it is ready then).
    Drive {
        forward: f32,
        turn: f32,
        tag: bool,
    },
    /// Drive through these points in order, around walls, and stop at the last.
    Waypoints(Vec<Point2<f32>>),
    Stop,
}

/// What an API-driven robot is doing.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ApiDrive {
    motion: Motion,
    route: Option<PathFollower>,
    fire: bool,
    /// With `fire`, for a person's keys: the tick whose opponents their screen showed.
    aim_tick: Option<u64>,
}

/// Why an order for a robot was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RobotOrderError {
    #[error("no robot {0} in this match")]
    UnknownRobot(String),
    #[error("this robot is not driven from outside (its planner is not \"api\")")]
    NotApiDriven,
    #[error("{field}: {value} must be a number in -1..=1")]
    OutOfRange { field: &'static str, value: f32 },
    #[error("waypoints: {0} points, at most {MAX_ROBOT_WAYPOINTS}")]
    TooManyWaypoints(usize),
    #[error(
        "waypoints[{index}]: finding the way there would take more than this server's budget of {budget} units of path search per request (each waypoint searches the map's grid: give fewer or nearer waypoints)"
    )]
    OverBudget { index: usize, budget: u64 },
    #[error("waypoints[{index}]: [{x}, {y}] {why}")]
    BadWaypoint {
        index: usize,
        x: f32,
        y: f32,
        why: &'static str,
    },
}

/// What robot `robot` has heard of a teammate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Teammate {
    pub robot: usize,
    /// The teammate's own estimate of its pose, as it was sent.
    pub pose: Pose,
    /// Ticks since it was sent (0 with a perfect radio).
    pub age_ticks: u64,
    /// Where it announced it is going, if its planner gives it a goal (robots driven by
    /// actions announce none).
    pub goal: Option<Point2<f32>>,
}

/// Everything one robot knows this tick (never ground truth).
#[derive(Debug, Clone, PartialEq)]
pub struct RobotObservation<'a> {
    pub tick: u64,
    /// Laser ranges (m), one per beam across the field of view; empty while frozen.
    pub scan: &'a [f32],
    pub detections: &'a [Detection],
    pub landmarks: &'a [LandmarkSighting],
    pub odometry: Pose,
    pub estimate: Pose,
    pub spread: f32,
    pub frozen: bool,
    /// The device would fire on the next tick.
    pub tag_ready: bool,
    pub teammates: Vec<Teammate>,
    /// The team belief as this robot holds it, seen from its own estimate.
    pub belief: BeliefFeatures,
}

impl World {
    /// Whether every robot takes orders from outside.
    pub fn robots_api_driven(&self) -> bool {
        self.team.kind() == PlannerKind::Api
    }

    /// Whether robot `index` takes orders from outside.
    pub fn robot_outside(&self, index: usize) -> bool {
        self.robots_api_driven()
            || self.config.outside_robots.get(index) == Some(&true)
            || self.robots.get(index).is_some_and(|r| r.seated)
    }

    /// Whether robot `index` is a seat for a person on the robot team
    /// (`MatchConfig::pursuer_slots`), taken or not.
    pub fn robot_seat(&self, index: usize) -> bool {
        index < self.robots.len()
            && index + self.config.pursuer_slots.min(self.robots.len()) >= self.robots.len()
    }

    /// Whether any robot takes orders from outside.
    pub fn any_robot_outside(&self) -> bool {
        (0..self.robots.len()).any(|i| self.robot_outside(i))
    }

    /// Gives robot `index` an order; it applies from the next tick. Every part of the order
    /// is checked before any of it takes effect.
    pub fn order_robot(&mut self, index: usize, order: RobotOrder) -> Result<(), RobotOrderError> {
        if index >= self.robots.len() {
            return Err(RobotOrderError::UnknownRobot(
                AgentId::Robot(index).to_string(),
            ));
        }
        if !self.robot_outside(index) {
            return Err(RobotOrderError::NotApiDriven);
        }
        let drive = match order {
            RobotOrder::Drive { forward, turn, tag } => {
                for (field, value) in [("forward", forward), ("turn", turn)] {
                    if !(value.is_finite() && (-1.0..=1.0).contains(&value)) {
                        return Err(RobotOrderError::OutOfRange { field, value });
                    }
                }
                ApiDrive {
                    motion: if forward == 0.0 && turn == 0.0 {
                        Motion::Stop
                    } else {
                        Motion::Drive { forward, turn }
                    },
                    route: None,
                    fire: tag,
                    aim_tick: None,
                }
            }
            RobotOrder::Waypoints(points) => ApiDrive {
                route: Some(PathFollower::new(self.plan_route(index, &points)?)),
                ..ApiDrive::default()
            },
            RobotOrder::Stop => ApiDrive::default(),
        };
        self.robots[index].api = drive;
        Ok(())
    }

    /// A person's keys for robot `index`, one of the team's pursuer slots: its drive order,
    /// and with the trigger pulled the tick their screen showed (their shot is judged
    /// against the opponents where they were then, as an opponent's person's is against the
    /// robots).
    pub fn robot_keys(&mut self, index: usize, input: HumanInput) -> Result<(), InputError> {
        if !self.robot_seat(index) {
            return Err(InputError::NoRobotSeat(index));
        }
        self.order_robot(
            index,
            RobotOrder::Drive {
                forward: input.forward,
                turn: input.turn,
                tag: input.tag,
            },
        )?;
        self.robots[index].api.aim_tick = input.seen_tick.filter(|_| input.tag);
        Ok(())
    }

    /// Bounds the path search of the orders applied from now on: together they may take
    /// `units` of work (see `nav::path_within`) until the next call; an order past it is
    /// refused ([`RobotOrderError::OverBudget`]) and changes nothing. The path an accepted
    /// order gets does not depend on the budget, so a replay needs none. Unbounded until
    /// set.
    pub fn set_route_budget(&mut self, units: u64) {
        self.route_budget = units;
        self.route_work = units;
    }

    /// A path through `points` from where robot `index` believes it is, around walls.
    fn plan_route(
        &mut self,
        index: usize,
        points: &[Point2<f32>],
    ) -> Result<Vec<Point2<f32>>, RobotOrderError> {
        if points.len() > MAX_ROBOT_WAYPOINTS {
            return Err(RobotOrderError::TooManyWaypoints(points.len()));
        }
        let grid = &self.arena.grid;
        let (w, h) = (self.arena.width(), self.arena.height());
        let mut from = self.robots[index].estimate.pos;
        let mut path = vec![from];
        for (k, p) in points.iter().enumerate() {
            let bad = |why| RobotOrderError::BadWaypoint {
                index: k,
                x: p.x,
                y: p.y,
                why,
            };
            let inside = (0.0..=w).contains(&p.x) && (0.0..=h).contains(&p.y);
            if !inside {
                return Err(bad("lies outside the arena"));
            }
            // A point in a wall, or where no robot fits, stands for the nearest place that
            // does (within half a metre).
            let rings = (0.5 / grid.cell).ceil() as usize;
            let goal = grid
                .nearest_passable(*p, rings)
                .ok_or_else(|| bad("is not within 0.5 m of free space"))?;
            let leg = path_within(grid, from, goal, &mut self.route_work)
                .map_err(|_| RobotOrderError::OverBudget {
                    index: k,
                    budget: self.route_budget,
                })?
                .ok_or_else(|| bad("cannot be reached from the point before it"))?;
            path.extend(leg.into_iter().skip(1));
            if grid.cell_of(*p).is_some_and(|c| c == goal) {
                path.push(*p);
            }
            from = *path.last().unwrap_or(&from);
        }
        Ok(path)
    }

    /// Stage 1 for API-driven robots: each robot's command from its order.
    pub(super) fn drive_api_robots(&mut self) {
        let turn_rate = self.config.physics.robot_turn_rate;
        let outside: Vec<bool> = (0..self.robots.len())
            .map(|i| self.robot_outside(i))
            .collect();
        for (r, _) in self.robots.iter_mut().zip(outside).filter(|(_, o)| *o) {
            let api = &mut r.api;
            let motion = match &mut api.route {
                Some(route) => route
                    .target(r.estimate.pos)
                    .map_or(Motion::Stop, |t| steer(r.estimate, t, turn_rate)),
                None => api.motion,
            };
            let goal = api.route.as_ref().and_then(|route| {
                route
                    .waypoints
                    .last()
                    .filter(|_| !route.finished())
                    .map(|p| Pose {
                        pos: *p,
                        theta: r.estimate.theta,
                    })
            });
            let fire = std::mem::take(&mut api.fire);
            r.aim_tick = std::mem::take(&mut api.aim_tick).filter(|_| fire);
            r.command = RobotCommand {
                motion,
                tag: fire,
                goal,
            };
        }
    }

    /// What robot `index` knows now, or `None` for a robot the match does not have.
    pub fn observation(&self, index: usize) -> Option<RobotObservation<'_>> {
        self.observation_with(index, &mut ReachCache::default())
    }

    /// [`World::observation`] with the robot's own [`ReachCache`] for its belief features:
    /// the same observation, cheaper when asked every tick.
    pub fn observation_with(
        &self,
        index: usize,
        reach: &mut ReachCache,
    ) -> Option<RobotObservation<'_>> {
        let r = self.robots.get(index)?;
        let frozen = self.robot_frozen(index);
        let estimates: Vec<Pose> = self.robots.iter().map(|r| r.estimate).collect();
        let teammates = (0..self.robots.len())
            .filter(|j| *j != index)
            .filter_map(|j| {
                let (pose, sent) = self.team.teammate_report(index, j, &estimates, self.tick)?;
                let goal = self
                    .team
                    .teammate_goal(index, j, self.robots[j].command.goal)
                    .map(|g| g.pos);
                Some(Teammate {
                    robot: j,
                    pose,
                    age_ticks: self.tick.saturating_sub(sent),
                    goal,
                })
            })
            .collect();
        Some(RobotObservation {
            tick: self.tick,
            scan: &r.scan.ranges,
            detections: &r.scan.detections,
            landmarks: &r.landmarks,
            odometry: r.odometry,
            estimate: r.estimate,
            spread: r.spread,
            frozen,
            tag_ready: !frozen && self.tick + 1 >= r.cooldown_until,
            teammates,
            belief: self
                .team
                .belief_of(index, self.robots.len())
                .map(|t| {
                    BeliefFeatures::of_with(
                        &t.roles,
                        r.estimate,
                        self.config.opponents,
                        &self.arena.grid,
                        reach,
                    )
                })
                .unwrap_or_default(),
        })
    }
}

crate::checkpoint::plain_struct!(ApiDrive {
    motion,
    route,
    fire,
    aim_tick
});
