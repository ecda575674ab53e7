//! The robot team's decisions: where each robot goes, how it gets there, when it fires.
//!
//! The team sees the world only through a [`TeamView`] (each robot's own pose estimate, laser
//! scan and anonymous detections) and answers with one [`RobotCommand`] per robot. It never
//! reads ground truth; the world applies the commands on the next tick.
//!
//! - [`baseline`]: the paper's baseline — random reachable destinations, chosen one robot at a
//!   time so teammates spread out, travel time as the only other factor.
//! - [`pursuit`]: shared by every planner — turn to a detected opponent, close in, fire.
//! - [`coordinated`]: the paper's tracker-driven planner — destinations where the team's
//!   belief expects the most opponent hypotheses, negotiated one robot at a time.

pub mod baseline;
pub mod coordinated;
pub mod pursuit;

use nalgebra::Point2;
use rand_chacha::ChaCha8Rng;

use crate::sim::arena::Arena;
use crate::sim::sensors::Detection;
use crate::sim::{Motion, Physics, Pose};
use crate::tracker::{LaserModel, Sighting, Tracker, TrackerEvent};

/// What the team may know about one robot this tick.
#[derive(Debug, Clone, Copy)]
pub struct RobotView<'a> {
    /// The robot's own estimate of its pose (not the truth).
    pub pose: Pose,
    pub frozen: bool,
    /// True when its tag device has cooled down.
    pub can_fire: bool,
    pub scan: &'a [f32],
    pub detections: &'a [Detection],
    /// True when this robot's shot tagged an opponent this tick (the device reports hits).
    pub hit: bool,
}

/// What the team knows this tick.
#[derive(Debug, Clone)]
pub struct TeamView<'a> {
    pub tick: u64,
    pub robots: Vec<RobotView<'a>>,
}

/// One robot's orders for the next tick.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RobotCommand {
    pub motion: Motion,
    pub tag: bool,
    /// Where its planner is sending it (shown in the state), if anywhere.
    pub goal: Option<Pose>,
}

/// The planner a match asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlannerKind {
    Idle,
    Baseline,
    Coordinated,
}

/// The team's brain: the opponent tracker, the chosen planner and its memory.
#[derive(Debug, Clone)]
pub struct Team {
    pub tracker: Tracker,
    pub(crate) brain: Brain,
}

#[derive(Debug, Clone)]
pub(crate) enum Brain {
    Idle,
    Baseline(Box<baseline::Baseline>),
    Coordinated(Box<coordinated::Coordinated>),
}

impl Team {
    /// `rng` feeds the planner; the tracker has its own stream, so that tracker settings do
    /// not change the planner's random choices.
    pub fn new(
        kind: PlannerKind,
        arena: &Arena,
        physics: &Physics,
        coordination: coordinated::Settings,
        robots: usize,
        tracker: Tracker,
        rng: ChaCha8Rng,
    ) -> Team {
        let brain = match kind {
            PlannerKind::Idle => Brain::Idle,
            PlannerKind::Baseline => {
                Brain::Baseline(Box::new(baseline::Baseline::new(arena, robots, rng)))
            }
            PlannerKind::Coordinated => Brain::Coordinated(Box::new(
                coordinated::Coordinated::new(arena, physics, coordination, robots),
            )),
        };
        Team { tracker, brain }
    }

    /// The planner this team runs (every kind asked for is built, so also the one asked for).
    pub fn kind(&self) -> PlannerKind {
        match self.brain {
            Brain::Idle => PlannerKind::Idle,
            Brain::Baseline(_) => PlannerKind::Baseline,
            Brain::Coordinated(_) => PlannerKind::Coordinated,
        }
    }

    /// Starts a full negotiation round on the next tick (searching robots then choose one per
    /// tick), as after a change of
    /// the belief from outside (a test that sets up a belief, a restored match).
    pub fn renegotiate(&mut self) {
        if let Brain::Coordinated(c) = &mut self.brain {
            c.renegotiate();
        }
    }

    /// Updates the tracker with what the robots sensed, then plans. Returns the commands and
    /// what happened to the roles.
    pub fn decide(
        &mut self,
        arena: &Arena,
        physics: &Physics,
        view: &TeamView,
    ) -> (Vec<RobotCommand>, Vec<TrackerEvent>) {
        let events = self.track(arena, physics, view);
        (self.plan(arena, physics, view), events)
    }

    /// The first half of [`Team::decide`]: the tracker's update from what the robots sensed.
    /// (Split so the shell can time the two halves; the pair is exactly `decide`.)
    pub fn track(
        &mut self,
        arena: &Arena,
        physics: &Physics,
        view: &TeamView,
    ) -> Vec<TrackerEvent> {
        let sightings: Vec<Sighting> = view
            .robots
            .iter()
            // A robot frozen before it sensed has an empty scan and nothing to say; one hit
            // after sensing still reports what it saw, and whether its own shot hit.
            .filter(|r| !r.scan.is_empty() || r.hit)
            .map(|r| Sighting {
                pose: r.pose,
                scan: r.scan,
                detections: r.detections,
                tagged: r.hit,
            })
            .collect();
        let laser = LaserModel {
            fov: physics.laser_fov,
            range: physics.laser_range,
        };
        self.tracker.update(arena, laser, &sightings)
    }

    /// The second half of [`Team::decide`]: each robot's command from the updated belief.
    pub fn plan(&mut self, arena: &Arena, physics: &Physics, view: &TeamView) -> Vec<RobotCommand> {
        match &mut self.brain {
            Brain::Idle => vec![RobotCommand::default(); view.robots.len()],
            Brain::Baseline(b) => b.decide(arena, physics, view),
            Brain::Coordinated(c) => c.decide(arena, physics, &self.tracker, view),
        }
    }
}

/// The world point a detection refers to, seen from `pose`.
pub fn detection_point(pose: Pose, d: &Detection) -> Point2<f32> {
    let a = pose.theta + d.bearing;
    pose.pos + nalgebra::Vector2::new(a.cos(), a.sin()) * d.range
}
