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
//! last heard otherwise ([`Mate`]). With an imperfect radio a robot also scores with its own
//! tracker, and nobody moves a teammate: a robot stuck behind one with a higher index asks
//! it over the radio to step aside, and that robot does so itself when it hears.
//!
//! Long file: negotiation, scoring and goal keeping share one private robot state, and
//! its unit tests reach into it; scoring and passages are the next seams to split out.

use std::sync::Arc;

use nalgebra::Point2;

use crate::nav::{self, DistanceField, PathFollower, steer, turn_to};
use crate::planner::pursuit::{engage_looking_ahead, nearest_sighting, pursuit_goal};
use crate::planner::{Knowledge, RobotCommand, RobotView, TeamView};
use crate::radio::Status;
use crate::sim::arena::Arena;
use crate::sim::views::{ViewSpec, ViewTable};
use crate::sim::{AGENT_RADIUS, Motion, Physics, Pose, wrap_angle};
use crate::tracker::{Confidence, Tracker};

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
}

/// What a robot knows of a teammate when it plans (see [`Knowledge`]).
#[derive(Debug, Clone, Copy)]
struct Mate {
    index: usize,
    pos: Point2<f32>,
    frozen: bool,
    pursuing: bool,
    /// Where it is going.
    goal: Option<Point2<f32>>,
    /// It still follows a path.
    moving: bool,
    making_way: bool,
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
    /// Per candidate position of `views`: whether a landmark is recognisable from there.
    sees_landmark: Vec<bool>,
    /// Per clearance-grid cell: whether it lies in a narrow passage.
    narrow: Vec<bool>,
}

/// One robot's best choice in a round.
#[derive(Debug, Clone, Copy)]
struct Choice {
    pose: usize,
    value: f32,
    worth: f32,
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
        Coordinated {
            settings,
            views,
            robots: vec![RobotState::default(); robots],
            next_round: 0,
            mass: vec![0.0; cells],
            seen: vec![0.0; poses],
            sees_landmark,
            narrow,
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
        let claim = if s.seeing {
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

    /// Teammates as robot `i` knows them, in index order: read directly with shared memory,
    /// as last heard otherwise (a teammate never heard from is unknown and left out).
    fn mates(&self, know: &Knowledge, view: &TeamView, i: usize) -> Vec<Mate> {
        (0..view.robots.len())
            .filter(|&j| j != i)
            .filter_map(|j| {
                if know.shared_memory() {
                    let r = &self.robots[j];
                    Some(Mate {
                        index: j,
                        pos: view.robots[j].pose.pos,
                        frozen: view.robots[j].frozen,
                        pursuing: r.seeing,
                        goal: self.goal_pose(j).map(|g| g.pos),
                        moving: !r.path.finished(),
                        making_way: r.making_way.is_some(),
                    })
                } else {
                    know.heard(i, j).map(|m| Mate {
                        index: j,
                        pos: m.pose.pos,
                        frozen: m.frozen,
                        pursuing: m.status.pursuing,
                        goal: m.status.goal.map(|g| g.pos),
                        moving: !m.status.route.is_empty(),
                        making_way: m.status.making_way,
                    })
                }
            })
            .collect()
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

    /// Stage 1: expected opponents per scoring cell. Returns their total.
    fn bin_mass(&mut self, tracker: &Tracker) -> f32 {
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

    fn drop_worthless(&mut self, searching: &[usize], total: f32) {
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
    fn nearest_pose(&self, pose: Pose) -> Option<usize> {
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
    fn choose(
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
                if self.robots[j].seeing {
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
        let field = self.field_for(arena, view, know, i);
        let uncertainty = self.uncertainty(view.robots[i].spread);
        let best = field.as_ref().and_then(|f| {
            self.best_for(arena, physics, i, f, &taken, uncertainty)
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
            if let Some(f) = DistanceField::from_point_avoiding(&arena.grid, from, &others) {
                return Some(f);
            }
        }
        DistanceField::from_point(&arena.grid, from)
    }

    /// Per-pose worth under the current (claimed) mass.
    fn score_poses(&mut self, total: f32) {
        for k in 0..self.views.len() {
            self.seen[k] = self.worth_of(k, total);
        }
    }

    /// How uncertain a robot with localisation `spread` counts as: 0 up to
    /// `uncertainty_spread`, rising to 1 at twice that.
    fn uncertainty(&self, spread: f32) -> f32 {
        let t = self.settings.uncertainty_spread;
        if spread > t {
            ((spread - t) / t).min(1.0)
        } else {
            0.0
        }
    }

    /// Robot `i`'s best pose given the scored worths. An `uncertainty` above 0 adds
    /// Fabiani & Latombe's trade: destinations that see a landmark gain, paths through
    /// narrow passages lose.
    fn best_for(
        &self,
        arena: &Arena,
        physics: &Physics,
        i: usize,
        field: &DistanceField,
        chosen: &[Point2<f32>],
        uncertainty: f32,
    ) -> Option<Choice> {
        let s = &self.settings;
        let h = s.headings;
        let current = self.robots[i].goal.map(|g| g.pose);
        // Only for an uncertain robot: a certain one skips the pass (and the terms vanish
        // exactly, so its choices are the plain planner's).
        let narrow =
            (uncertainty > 0.0 && s.narrow_weight > 0.0).then(|| field.narrow_metres(&self.narrow));
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
                let narrow_m = narrow.as_ref().map_or(0.0, |n| n[cell]);
                cost += uncertainty * (s.narrow_weight * narrow_m - landmark);
            }
            for k in p_idx * h..(p_idx + 1) * h {
                let keep = if current == Some(k) {
                    s.keep_bonus
                } else {
                    0.0
                };
                let value = self.seen[k] - cost + keep;
                if best.is_none_or(|b| value > b.value) {
                    best = Some(Choice {
                        pose: k,
                        value,
                        worth: self.seen[k],
                    });
                }
            }
        }
        best
    }

    /// Robot `i` has not moved for a while although its path goes on. Blocked by a moving
    /// teammate (two robots meeting in a doorway or a narrow corridor), the one with the
    /// higher index steps off the other's path and waits for it to pass: a fixed order, so
    /// the two never both give way or both insist. Blocked by anything else (a frozen or
    /// parked teammate, a tight corner), it re-plans around its teammates.
    ///
    /// Over an imperfect radio a robot moves only itself: with the higher index it steps
    /// aside; with the lower it asks the blocker to (in its next message) and waits, and
    /// re-plans around the team if it is still stuck at the next check after asking.
    fn unstick(&mut self, arena: &Arena, view: &TeamView, know: &Knowledge, i: usize, tick: u64) {
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
    fn make_way(
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bots::BotKind;
    use crate::planner::{Brain, PlannerKind};
    use crate::sim::arena::MapDef;
    use crate::world::World;
    use crate::world::{MatchConfig, Placement};

    /// Two 6 m × 6 m rooms joined by a corridor 4 m long and 0.9 m wide: too narrow for two
    /// robots to pass each other. The opponent is walled into a pocket in a corner, out of
    /// sight, so that nothing distracts the robots.
    fn corridor() -> Arc<Arena> {
        Arc::new(Arena::new(MapDef {
            name: "corridor".into(),
            width: 16.0,
            height: 6.0,
            obstacles: vec![
                vec![
                    Point2::new(6.0, 0.0),
                    Point2::new(10.0, 0.0),
                    Point2::new(10.0, 2.55),
                    Point2::new(6.0, 2.55),
                ],
                vec![
                    Point2::new(6.0, 3.45),
                    Point2::new(10.0, 3.45),
                    Point2::new(10.0, 6.0),
                    Point2::new(6.0, 6.0),
                ],
                vec![
                    Point2::new(0.0, 4.5),
                    Point2::new(2.0, 4.5),
                    Point2::new(2.0, 4.6),
                    Point2::new(0.0, 4.6),
                ],
                vec![
                    Point2::new(1.9, 4.6),
                    Point2::new(2.0, 4.6),
                    Point2::new(2.0, 6.0),
                    Point2::new(1.9, 6.0),
                ],
            ],
            robot_spawns: vec![[2.0, 3.0, 0.0]],
            opponent_spawns: vec![Point2::new(0.9, 5.3)],
            landmarks: vec![],
        }))
    }

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
        let best = c.best_for(arena, &physics, 0, &field, &[], u).unwrap();
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
}
