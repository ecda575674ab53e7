//! The robot-team presets' names on the wire (the core's `Difficulty` stays free of serde).

use lasertag_core::difficulty::Difficulty;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// A robot-team preset (docs/difficulty.md): a set of the other settings, measured against
/// the built-in bots.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum DifficultyName {
    /// One robot at 0.8 m/s searching at random, 2 s between tags, 2 minutes.
    Recruit,
    /// Two robots at 0.8 m/s searching at random, 2 s between tags, 2 minutes.
    Veteran,
    /// Two coordinated robots tracking the opponents, at full speed, 2 minutes.
    Elite,
    /// Two robots driven by the shipped trained policy (`policy:learned`), from what each
    /// knows, the team belief included; at full speed, 2 minutes.
    Learned,
}

impl DifficultyName {
    pub fn kind(self) -> Difficulty {
        match self {
            DifficultyName::Recruit => Difficulty::Recruit,
            DifficultyName::Veteran => Difficulty::Veteran,
            DifficultyName::Elite => Difficulty::Elite,
            DifficultyName::Learned => Difficulty::Learned,
        }
    }

    pub fn of(d: Difficulty) -> DifficultyName {
        match d {
            Difficulty::Recruit => DifficultyName::Recruit,
            Difficulty::Veteran => DifficultyName::Veteran,
            Difficulty::Elite => DifficultyName::Elite,
            Difficulty::Learned => DifficultyName::Learned,
        }
    }
}
