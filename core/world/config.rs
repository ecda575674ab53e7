//! What a match is set up with: who controls the opponents, where agents start, and
//! every setting of the tick pipeline.

use super::*;

/// Who controls every opponent slot of a match.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControlKind {
    Bot,
    Api,
    Human,
}

/// Where agents start.
#[derive(Debug, Clone, PartialEq)]
pub enum Placement {
    /// The map's spawns, in order, wrapping (displaced to the nearest free spot when taken).
    Spawns,
    /// Random free points of the arena, all mutually reachable (for experiments).
    Random,
    /// Explicit starts: robots `(x, y, heading)` and opponents `(x, y)`; empty lists fall back to spawns.
    Given {
        robots: Vec<[f32; 3]>,
        opponents: Vec<[f32; 2]>,
    },
}

/// Everything that defines a match besides the map.
#[derive(Debug, Clone)]
pub struct MatchConfig {
    pub robots: usize,
    pub opponents: usize,
    pub opponent_control: ControlKind,
    pub opponent_bot: BotKind,
    pub planner: PlannerKind,
    /// The trained policy (`policy:<name>`) the shell drives the team by: its robots are
    /// driven from outside (`planner` is [`PlannerKind::Api`]) and the shell gives them the
    /// policy's orders as inputs every few ticks, so the match's record holds every action
    /// and a replay never needs the model. The core only carries the name.
    pub policy: Option<String>,
    /// Robots driven from outside (by an API client or a person) while the team's planner
    /// drives the rest: `outside_robots[i]` for robot `i`, none when shorter. With
    /// `planner` [`PlannerKind::Api`] every robot is driven from outside whatever this says.
    pub outside_robots: Vec<bool>,
    /// The last this many robots are seats for people on the robot team (pursuers): while a
    /// person holds one it is driven from outside, by their keys; while it is free the
    /// team's planner drives it.
    pub pursuer_slots: usize,
    pub seed: u64,
    pub time_limit_ticks: u64,
    pub placement: Placement,
    pub physics: Physics,
    pub tracker: crate::tracker::Settings,
    /// Weights of the `coordinated` planner.
    pub coordination: crate::planner::coordinated::Settings,
    /// Robots localise themselves (MCL from odometry, laser and landmarks); when off, each
    /// robot's estimate is its odometry alone (dead reckoning, which drifts). Either way no
    /// decision reads the true pose.
    pub localisation: bool,
    pub localiser: crate::localise::Settings,
    /// The team radio: perfect (the default) keeps one shared tracker; a latency or loss
    /// gives every robot its own (see `crate::radio`).
    pub radio: crate::radio::Settings,
}

impl Default for MatchConfig {
    fn default() -> Self {
        MatchConfig {
            robots: 2,
            opponents: 1,
            opponent_control: ControlKind::Bot,
            opponent_bot: BotKind::Wander,
            planner: PlannerKind::Coordinated,
            policy: None,
            outside_robots: Vec::new(),
            pursuer_slots: 0,
            seed: 0,
            time_limit_ticks: 300 * TICK_HZ as u64,
            placement: Placement::Spawns,
            physics: Physics::default(),
            tracker: crate::tracker::Settings::default(),
            coordination: crate::planner::coordinated::Settings::default(),
            localisation: true,
            localiser: crate::localise::Settings::default(),
            radio: crate::radio::Settings::default(),
        }
    }
}
