//! The tracker-driven planner of the paper's section 4.3: robots go where they expect to see
//! the most opponent hypotheses, chosen one robot at a time so that teammates look at
//! different places.
//!
//! Each negotiation round runs these stages over plain data:
//!
//! 1. **Mass**: the tracker's particles of untagged roles, each weighted by its role's count,
//!    are binned on the scoring grid of the arena's [`ViewTable`]: `mass[c]` is the expected
//!    number of opponents in cell `c`.
//! 2. **Claims**: what robots that are not choosing will observe — a pursuer's current view,
//!    a teammate's kept destination — counts for less (`claim_keep` of its mass).
//! 3. **Choice**: for every choosing robot, every candidate pose `k` is worth
//!    `seen(k) / total − travel_weight · seconds to get there − crowding_weight · crowding`,
//!    where `seen(k)` sums the mass of the cells `k` sees, weighted up to `1 + centring_weight`
//!    for cells straight ahead. Robots choose one per tick, the one that chose longest ago
//!    first; each choice is claimed before the next. This is what splits a team across branching
//!    corridors: a branch that one robot will search is worth little to the next.
//!
//! Rounds happen every `round_ticks` (each searching robot then chooses on its turn), and a
//! robot also chooses on its own, at most every `MIN_CHOICE_TICKS`, when it reached its goal, when
//! its goal became worthless (the tracker's negative information emptied it on the way), when
//! it is stuck, or while it follows an opponent it just lost sight of.
//!
//! A robot that detects an opponent leaves the negotiation and pursues it ([`pursuit`]); the
//! others keep searching, with the pursuer's view claimed.
//!
//! What a robot reads of its teammates (their poses, goals, claims, routes, whether they
//! pursue or make way) goes through [`Knowledge`]: read directly with a perfect radio, as
//! last heard otherwise (`mates`). With an imperfect radio a robot also scores with its own
//! tracker, and nobody moves a teammate: a robot stuck behind one with a higher index asks
//! it over the radio to step aside, and that robot does so itself when it hears.
//!
//! The scoring stages live in `scoring` (with how far a choosing robot's travel field need
//! grow in `reach`); robots getting past each other in doorways and narrow corridors in
//! `passages`.

mod mates;
mod passages;
mod reach;
mod scoring;
pub mod search;
pub mod travel;

use std::sync::Arc;

use nalgebra::Point2;

use crate::nav::{self, PathFollower, steer, turn_to};
use crate::planner::pursuit::{engage_looking_ahead, nearest_sighting, pursuit_goal};
use crate::planner::view::{Knowledge, RobotCommand, RobotView, TeamView};
use crate::radio::Status;
use crate::sim::arena::Arena;
use crate::sim::views::{ViewSpec, ViewTable};
use crate::sim::{Motion, Physics, Pose};
use crate::tracker::Tracker;

crate::settings! {
    /// Weights and rhythms of the `coordinated` planner (the match's `coordination` object;
    /// docs/planner.md says what each does). The defaults are tuned with `lasertag
    /// experiment capture`.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Settings as "coordination" {
        /// Extra worth of a hypothesis straight ahead over one at the edge of the view.
        pub centring_weight: f32 = 0.5, range(0.0, 10.0);
        /// Worth lost per second of travel, in shares of all hypotheses.
        pub travel_weight: f32 = 0.01, range(0.0, 1.0);
        /// Worth lost for a destination on top of a teammate's, falling to 0 at
        /// `crowding_radius`.
        pub crowding_weight: f32 = 0.05, range(0.0, 10.0);
        /// Metres over which the crowding penalty falls to 0.
        pub crowding_radius: f32 = 3.0, above(0.0, 50.0);
        /// Share of a hypothesis that still counts once a teammate is going to observe it.
        pub claim_keep: f32 = 0.2, range(0.0, 1.0);
        /// Extra worth of the goal a robot already has, so that it does not switch for a
        /// marginal gain (each switch wastes the trip so far).
        pub keep_bonus: f32 = 0.0, range(0.0, 1.0);
        /// How much more a hypothesis of a suspicious role (see `tracker::Confidence`) counts
        /// than one of a valid or invalid role: robots go and check what the team is unsure
        /// of. Above 0: at 0 a team whose roles are all suspicious would see nothing.
        pub suspicious_weight: f32 = 2.0, above(0.0, 100.0);
        /// Ticks between full negotiation rounds.
        pub round_ticks: u64 = 60, range(1, 12_000);
        /// A goal whose view now holds less than this share of what it held when chosen is
        /// dropped for a new one.
        pub worthless_share: f32 = 0.3, range(0.0, 1.0);
        /// ... or less than this share of all hypotheses.
        pub worthless_floor: f32 = 0.01, range(0.0, 1.0);
        /// Uncertainty-aware motion (Fabiani & Latombe): a robot whose localisation spread
        /// is above this (m) counts as uncertain, fully so at twice that. Below it the two
        /// terms below vanish and the choice is the plain one. Above 0: at 0 every robot,
        /// even a perfectly localised one, would count as uncertain.
        pub uncertainty_spread: f32 = 0.15, above(0.0, 10.0);
        /// Worth added, times the uncertainty, to a destination that sees a landmark (within
        /// the landmark range, in line of sight): there the robot localises itself again.
        pub landmark_weight: f32 = 0.1, range(0.0, 1.0);
        /// Worth lost, times the uncertainty, per metre of the path through narrow passages
        /// (under twice `NARROW_HALF_WIDTH` wide), where a robot unsure of its pose scrapes
        /// walls.
        pub narrow_weight: f32 = 0.02, range(0.0, 1.0);
        /// Pursuit look-ahead (seconds, 0 = off): while it sees an opponent, an uncertain
        /// robot weighs a few motions held this long by the chance of still seeing it.
        pub lookahead: f32 = 0.5, range(0.0, MAX_LOOKAHEAD);
        /// Whether a teammate driven from outside (a person, an API client) claims what
        /// lies ahead of it, so that the planned robots search elsewhere; off, they plan as
        /// if it were not there (`lasertag experiment teammate` measures the difference).
        pub outside_claims: bool = true;
        /// The `search` planner only: view poses a robot's plan looks ahead (1: the next
        /// pose alone, the coordinated planner's choice).
        pub search_depth: u64 = 3, range(1, 6);
        /// The `search` planner only: continuations followed at each level of the plan.
        pub search_branching: u64 = 4, range(1, 12);
        /// The `search` planner only: how much the best continuation after a pose counts
        /// beside the pose's own worth (0: not at all, the coordinated planner's choice).
        pub search_weight: f32 = 0.3, range(0.0, 10.0);
        /// The `search` planner only: seconds after the arrival at the plan's first pose
        /// after which what a later pose sees counts half.
        pub search_half_life: f32 = 10.0, above(0.0, 600.0);
    }
    internal {
        /// Spacing of candidate positions (metres) and headings per position.
        pub candidate_spacing: f32 = 1.0;
        pub headings: usize = 8;
        /// Side of the scoring grid's cells (metres).
        pub score_cell: f32 = 0.5;
    }
}

/// Longest pursuit look-ahead (seconds): beyond it a held motion says little about the next
/// decision, which comes every tick anyway.
pub const MAX_LOOKAHEAD: f32 = 2.0;

/// A narrow passage is under twice this wide (metres): a robot disc (0.5 m) has under a
/// quarter metre either side, less than an uncertain robot's error.
pub const NARROW_HALF_WIDTH: f32 = 0.5;
/// How far around a cell [`nav::narrow_cells`] looks for room (metres).
const NARROW_REACH: f32 = 0.2;

/// Most candidate positions a map gets: a 500 m × 500 m map would otherwise need gigabytes
/// of views, so big maps get a coarser candidate grid (and scoring grid) instead.
const MAX_POSITIONS: f32 = 1500.0;

impl Settings {
    /// The view table this planner needs on `arena`, coarsened for big maps.
    pub fn view_spec(&self, arena: &Arena, physics: &Physics) -> ViewSpec {
        let spacing = self
            .candidate_spacing
            .max((arena.width() * arena.height() / MAX_POSITIONS).sqrt());
        ViewSpec {
            spacing,
            headings: self.headings,
            cell: self.score_cell.max(spacing / 4.0),
            fov: physics.laser_fov,
            range: physics.laser_range,
        }
    }
}

/// How long after losing sight of an opponent a robot keeps re-planning towards where the
/// belief says it went, and how often.
const CHASE_TICKS: u64 = 100;
const CHASE_REPLAN_TICKS: u64 = 10;
/// How often goals are checked for having become worthless.
const WORTH_CHECK_TICKS: u64 = 10;
/// A robot that moved less than this in `STUCK_TICKS` re-plans around its teammates.
const STUCK_DISTANCE: f32 = 0.2;
const STUCK_TICKS: u64 = 40;
/// Shortest time between two choices of one robot outside full rounds.
const MIN_CHOICE_TICKS: u64 = 10;
/// How far ahead of a teammate driven from outside its claim lies (m): where it will be in
/// about a second and a half at a robot's speed, looking the way it looks.
const OUTSIDE_LEAD_M: f32 = 1.5;

/// Where a teammate driven from outside is heading: `OUTSIDE_LEAD_M` ahead of its pose, the
/// way it faces. Nobody knows its driver's plan; its heading is the best guess, and a
/// person who turns makes the next choice of the others follow.
fn ahead(pose: Pose) -> Pose {
    let (s, c) = pose.theta.sin_cos();
    Pose {
        pos: pose.pos + nalgebra::Vector2::new(c, s) * OUTSIDE_LEAD_M,
        theta: pose.theta,
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Goal {
    /// Candidate pose index in the view table.
    pose: usize,
    /// Share of all hypotheses its view held when it was chosen, after teammates' claims
    /// (so at most what it holds unclaimed: the worthless check compares against that).
    worth: f32,
}

#[derive(Debug, Clone, Default)]
struct RobotState {
    goal: Option<Goal>,
    path: PathFollower,
    replan: bool,
    /// Plan around teammates next time (set when stuck).
    avoid_team: bool,
    seeing: bool,
    lost_at: Option<u64>,
    progress: Option<(Point2<f32>, u64)>,
    /// Making way for teammate `.0` until tick `.1`: off its path, waiting for it to pass.
    making_way: Option<(usize, u64)>,
    /// When it last chose a destination.
    chosen_at: u64,
    /// A full round asked it to choose again; it will, on its turn.
    due: bool,
    /// Radio only: the teammate it asks to step aside in its next message.
    yield_request: Option<usize>,
    /// Radio only: whom it last asked to step aside, and when.
    asked: Option<(usize, u64)>,
    /// Driven from outside (as of the last decision): it chooses for itself, first; what
    /// lies ahead of it is its claim.
    outside: bool,
}

#[derive(Debug, Clone)]
pub struct Coordinated {
    settings: Settings,
    views: Arc<ViewTable>,
    robots: Vec<RobotState>,
    next_round: u64,
    /// Scratch: expected opponents per scoring cell, and per-pose worth.
    mass: Vec<f32>,
    seen: Vec<f32>,
    /// What `seen` was divided by when last scored: `(1 + centring_weight) × total mass`.
    norm: f32,
    /// Per candidate position of `views`: whether a landmark is recognisable from there.
    sees_landmark: Vec<bool>,
    /// Per clearance-grid cell: whether it lies in a narrow passage.
    narrow: Vec<bool>,
    /// Per clearance-grid cell: the candidate position of `views` on it, or
    /// none (shared: copies of a match's world keep one).
    cell_positions: Arc<[u32]>,
    /// The `search` planner: each choice looks ahead over several poses (see `search`).
    searching: bool,
    /// Travel between the view table's positions, for the look-ahead (`None`: not
    /// searching, or a map with too many positions).
    travel: Option<Arc<travel::PositionTravel>>,
}

impl Coordinated {
    pub fn new(arena: &Arena, physics: &Physics, settings: Settings, robots: usize) -> Self {
        let views = ViewTable::of(arena, settings.view_spec(arena, physics));
        let (cells, poses) = (views.cell_count(), views.len());
        // Landmarks are recognised all round, so a position sees one whatever its heading.
        let sees_landmark =
            views
                .positions
                .iter()
                .map(|&p| {
                    arena.def.landmarks.iter().any(|&m| {
                        (m - p).norm() <= physics.landmark_range && arena.line_of_sight(p, m)
                    })
                })
                .collect();
        let narrow = nav::narrow_cells(&arena.grid, NARROW_HALF_WIDTH, NARROW_REACH);
        let cell_positions = Coordinated::cell_positions(&arena.grid, &views.positions);
        Coordinated {
            settings,
            views,
            robots: vec![RobotState::default(); robots],
            next_round: 0,
            mass: vec![0.0; cells],
            seen: vec![0.0; poses],
            norm: 1.0,
            sees_landmark,
            narrow,
            cell_positions,
            searching: false,
            travel: None,
        }
    }

    /// A full negotiation round on the next tick.
    pub fn renegotiate(&mut self) {
        self.next_round = 0;
    }

    /// The pose a robot is heading for, as shown in the state.
    fn goal_pose(&self, i: usize) -> Option<Pose> {
        self.robots[i].goal.map(|g| {
            let (pos, theta) = self.views.pose(g.pose);
            Pose { pos, theta }
        })
    }

    /// Robot `i`'s plans as it announces them over the radio. Takes its pending request
    /// to a teammate to step aside: it is asked once per stuck check.
    pub fn status(&mut self, i: usize, pose: Pose) -> Status {
        let s = &self.robots[i];
        let claim = if s.outside && self.settings.outside_claims {
            self.nearest_pose(ahead(pose))
        } else if s.seeing {
            self.nearest_pose(pose)
        } else {
            s.goal.map(|g| g.pose)
        };
        let route = if s.path.finished() {
            Vec::new()
        } else {
            let mut r = vec![pose.pos];
            r.extend(s.path.waypoints.iter().skip(s.path.next).copied());
            r
        };
        let status = Status {
            goal: self.goal_pose(i),
            claim,
            pursuing: s.seeing,
            route,
            making_way: s.making_way.is_some(),
            yield_request: s.yield_request,
        };
        self.robots[i].yield_request = None;
        status
    }

    /// The centralised team's decisions, from the shared `tracker` (a perfect radio).
    pub fn decide(
        &mut self,
        arena: &Arena,
        physics: &Physics,
        tracker: &Tracker,
        view: &TeamView,
    ) -> Vec<RobotCommand> {
        self.decide_with(arena, physics, &Knowledge::shared(tracker), view)
    }

    /// This tick's commands, each robot deciding from what it knows (see [`Knowledge`]).
    pub fn decide_with(
        &mut self,
        arena: &Arena,
        physics: &Physics,
        know: &Knowledge,
        view: &TeamView,
    ) -> Vec<RobotCommand> {
        let tick = view.tick;
        let n = view.robots.len();
        let mut commands: Vec<Option<RobotCommand>> = vec![None; n];
        let mut stuck = Vec::new();
        // Who pursues, who is out of the game, who needs a new destination.
        for (i, robot) in view.robots.iter().enumerate() {
            let state = &mut self.robots[i];
            state.outside = robot.outside;
            if robot.outside {
                // Its own driver chooses where it goes: nothing to negotiate, and its
                // teammates plan around it (`choose` claims what it is heading for).
                *state = RobotState {
                    outside: true,
                    chosen_at: state.chosen_at,
                    ..RobotState::default()
                };
                commands[i] = Some(RobotCommand::default());
                continue;
            }
            if robot.frozen {
                state.seeing = false;
                state.progress = None; // standing still while frozen is not being stuck
                commands[i] = Some(RobotCommand {
                    goal: None,
                    ..RobotCommand::default()
                });
                continue;
            }
            if let Some((target, range, bearing)) = nearest_sighting(robot) {
                state.seeing = true;
                state.lost_at = None;
                state.progress = None; // turning to a target in place is not being stuck
                // Only an uncertain robot looks ahead: always on, the look-ahead's detours
                // to keep a target in view cost more tags than they saved (capture medians
                // against `evade` rose by half; see docs/planner.md).
                let horizon = if self.uncertainty(robot.spread) > 0.0 {
                    self.settings.lookahead
                } else {
                    0.0
                };
                let (motion, tag) =
                    engage_looking_ahead(arena, robot, physics, horizon, (target, range, bearing));
                commands[i] = Some(RobotCommand {
                    motion,
                    tag,
                    goal: Some(pursuit_goal(robot.pose, target)),
                });
                continue;
            }
            if state.seeing {
                // Lost it: go where the belief says it went, re-planning often for a while.
                state.seeing = false;
                state.lost_at = Some(tick);
                state.replan = true;
            }
            if let Some(lost) = state.lost_at {
                if tick >= lost + CHASE_TICKS {
                    state.lost_at = None;
                } else if (tick - lost).is_multiple_of(CHASE_REPLAN_TICKS) {
                    state.replan = true;
                }
            }
            if state.goal.is_none() {
                state.replan = true;
            }
            // A teammate stuck behind this robot asked it to step aside (radio only: with
            // shared memory the stuck robot moves it directly).
            if state.making_way.is_none()
                && let Some(&keeper) = know.yield_requests(i).first()
            {
                self.make_way(arena, view, know, i, keeper, tick);
            }
            let state = &mut self.robots[i];
            if let Some((keeper, until)) = state.making_way {
                let keeper_pos = if know.shared_memory() {
                    Some(view.robots[keeper].pose.pos)
                } else {
                    know.heard(i, keeper).map(|m| m.pose.pos)
                };
                let passed = state.path.finished()
                    && keeper_pos.is_none_or(|k| (k - robot.pose.pos).norm() > 2.5);
                if tick >= until || passed {
                    state.making_way = None;
                    state.replan = true;
                }
                continue;
            }
            match state.progress {
                Some((p, t)) if tick >= t + STUCK_TICKS => {
                    if (robot.pose.pos - p).norm() < STUCK_DISTANCE && !state.path.finished() {
                        stuck.push(i);
                    }
                    state.progress = Some((robot.pose.pos, tick));
                }
                None => state.progress = Some((robot.pose.pos, tick)),
                _ => {}
            }
        }
        for i in stuck {
            self.unstick(arena, view, know, i, tick);
        }
        let searching: Vec<usize> = (0..n).filter(|&i| commands[i].is_none()).collect();
        if tick >= self.next_round {
            self.next_round = tick + self.settings.round_ticks;
            for &i in &searching {
                self.robots[i].due = true;
            }
        }
        let check = tick.is_multiple_of(WORTH_CHECK_TICKS);
        // One robot chooses per tick (the one that chose longest ago): a round of n robots is
        // spread over n ticks, 50 ms apart, so that no tick pays for n travel fields at once.
        // Outside rounds a robot chooses at most every MIN_CHOICE_TICKS: one whose best
        // choice is where it stands would otherwise plan every tick.
        let pick = |robots: &[RobotState]| {
            searching
                .iter()
                .copied()
                .filter(|&i| robots[i].making_way.is_none())
                .filter(|&i| {
                    let r = &robots[i];
                    r.due || r.replan && tick >= r.chosen_at + MIN_CHOICE_TICKS
                })
                .min_by_key(|&i| (robots[i].chosen_at, i))
        };
        let mut chooser = pick(&self.robots);
        // Binning is cheap but not free: only when a goal is checked or chosen.
        if know.shared_memory() {
            if check || chooser.is_some() {
                let total = self.bin_mass(know.tracker(0));
                if total > 0.0 && check {
                    self.drop_worthless(&searching, total);
                    chooser = pick(&self.robots);
                }
                if let Some(i) = chooser
                    && total > 0.0
                {
                    self.choose(arena, physics, view, know, i, total);
                }
            }
        } else {
            // Each robot judges its goal and chooses by its own tracker.
            if check {
                for &i in &searching {
                    let total = self.bin_mass(know.tracker(i));
                    if total > 0.0 {
                        self.drop_worthless(&[i], total);
                    }
                }
                chooser = pick(&self.robots);
            }
            if let Some(i) = chooser {
                let total = self.bin_mass(know.tracker(i));
                if total > 0.0 {
                    self.choose(arena, physics, view, know, i, total);
                }
            }
        }
        for &i in &searching {
            commands[i] = Some(self.drive(physics, i, &view.robots[i]));
        }
        commands
            .into_iter()
            .map(|c| c.unwrap_or_default())
            .collect()
    }

    /// Follow the path to the goal, then turn to its heading.
    fn drive(&mut self, physics: &Physics, i: usize, robot: &RobotView) -> RobotCommand {
        let goal = self.goal_pose(i);
        let state = &mut self.robots[i];
        let motion = match state.path.target(robot.pose.pos) {
            Some(wp) => steer(robot.pose, wp, physics.robot_turn_rate),
            None if state.making_way.is_some() => Motion::Stop,
            None => match goal {
                Some(g) => {
                    let m = turn_to(robot.pose, g.theta, physics.robot_turn_rate);
                    if m == Motion::Stop {
                        state.replan = true; // arrived and looked: choose again on its turn
                    }
                    m
                }
                None => Motion::Stop,
            },
        };
        RobotCommand {
            motion,
            tag: false,
            goal,
        }
    }
}

crate::checkpoint::plain_struct!(Goal { pose, worth });
crate::checkpoint::plain_struct!(RobotState {
    goal,
    path,
    replan,
    avoid_team,
    seeing,
    lost_at,
    progress,
    making_way,
    chosen_at,
    due,
    yield_request,
    asked,
    outside,
});
// `mass`, `seen` and `norm` are scratch, but saved: a checkpoint that left them out would
// hold only if no tick ever read them before writing them, which nothing checks.
crate::checkpoint::restore_struct!(Coordinated {
    plain: [robots, next_round, mass, seen, norm],
    nested: [],
    derived: [
        settings,
        views,
        sees_landmark,
        narrow,
        cell_positions,
        searching,
        travel,
    ],
});

#[cfg(test)]
mod test_maps;
