//! The stored form's names for the core's kinds. They are the API's names too, but fixed
//! here on their own: a database outlives a change of the API.

use lasertag_core::bots::BotKind;
use lasertag_core::difficulty::Difficulty;
use lasertag_core::planner::PlannerKind;
use lasertag_core::world::ControlKind;
use serde::{Deserialize, Serialize};

/// How a stored match's clock ran.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StoredClock {
    Realtime,
    Manual,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum StoredControl {
    Bot,
    Api,
    Human,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum StoredBot {
    Wander,
    Evade,
    Idle,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum StoredDifficulty {
    Recruit,
    Veteran,
    Elite,
    Learned,
}

impl StoredDifficulty {
    pub(super) fn of(d: Difficulty) -> StoredDifficulty {
        match d {
            Difficulty::Recruit => StoredDifficulty::Recruit,
            Difficulty::Veteran => StoredDifficulty::Veteran,
            Difficulty::Elite => StoredDifficulty::Elite,
            Difficulty::Learned => StoredDifficulty::Learned,
        }
    }

    pub(super) fn kind(self) -> Difficulty {
        match self {
            StoredDifficulty::Recruit => Difficulty::Recruit,
            StoredDifficulty::Veteran => Difficulty::Veteran,
            StoredDifficulty::Elite => Difficulty::Elite,
            StoredDifficulty::Learned => Difficulty::Learned,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum StoredPlanner {
    Coordinated,
    Search,
    Baseline,
    Idle,
    Api,
}

impl StoredControl {
    pub(super) fn of(kind: ControlKind) -> StoredControl {
        match kind {
            ControlKind::Bot => StoredControl::Bot,
            ControlKind::Api => StoredControl::Api,
            ControlKind::Human => StoredControl::Human,
        }
    }

    pub(super) fn kind(self) -> ControlKind {
        match self {
            StoredControl::Bot => ControlKind::Bot,
            StoredControl::Api => ControlKind::Api,
            StoredControl::Human => ControlKind::Human,
        }
    }
}

impl StoredBot {
    pub(super) fn of(kind: BotKind) -> StoredBot {
        match kind {
            BotKind::Wander => StoredBot::Wander,
            BotKind::Evade => StoredBot::Evade,
            BotKind::Idle => StoredBot::Idle,
        }
    }

    pub(super) fn kind(self) -> BotKind {
        match self {
            StoredBot::Wander => BotKind::Wander,
            StoredBot::Evade => BotKind::Evade,
            StoredBot::Idle => BotKind::Idle,
        }
    }
}

impl StoredPlanner {
    pub(super) fn of(kind: PlannerKind) -> StoredPlanner {
        match kind {
            PlannerKind::Coordinated => StoredPlanner::Coordinated,
            PlannerKind::Search => StoredPlanner::Search,
            PlannerKind::Baseline => StoredPlanner::Baseline,
            PlannerKind::Idle => StoredPlanner::Idle,
            PlannerKind::Api => StoredPlanner::Api,
        }
    }

    pub(super) fn kind(self) -> PlannerKind {
        match self {
            StoredPlanner::Coordinated => PlannerKind::Coordinated,
            StoredPlanner::Search => PlannerKind::Search,
            StoredPlanner::Baseline => PlannerKind::Baseline,
            StoredPlanner::Idle => PlannerKind::Idle,
            StoredPlanner::Api => PlannerKind::Api,
        }
    }
}
