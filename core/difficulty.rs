//! The robot team's difficulty presets, which a person chooses in the lobby (and the API as
//! `difficulty`): each is a set of existing settings — team size, planner, robot speed, tag
//! cool-down, match length — measured against the built-in bots by `lasertag
//! experiment difficulty` (docs/difficulty.md). A preset changes only the robot team and the
//! clock; the opponents' rules are the game's.

use crate::planner::PlannerKind;
use crate::sim::{Physics, TICK_HZ};
use crate::world::MatchConfig;

/// A difficulty preset, from the easiest.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Difficulty {
    /// One slow robot searching at random, slow to fire again: a newcomer's first matches.
    Recruit,
    /// Two slow robots searching at random, each on its own.
    Veteran,
    /// Two robots at full speed that track what they cannot see and coordinate where to look
    /// over a perfect radio: the paper's team, as the showcase plays.
    Elite,
}

/// What a preset sets (every other setting keeps its default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Preset {
    pub robots: usize,
    pub planner: PlannerKind,
    /// Metres per second (the game's default is 1).
    pub robot_speed: f32,
    /// Ticks between two tags of one robot (the game's default is one second).
    pub tag_cooldown_ticks: u64,
    /// The match's length.
    pub time_limit_s: u64,
}

impl Difficulty {
    pub const ALL: [Difficulty; 3] = [Difficulty::Recruit, Difficulty::Veteran, Difficulty::Elite];

    /// The preset a person gets unless they choose: one a newcomer can win.
    pub const DEFAULT: Difficulty = Difficulty::Recruit;

    /// The name the API and the lobby use.
    pub fn name(self) -> &'static str {
        match self {
            Difficulty::Recruit => "recruit",
            Difficulty::Veteran => "veteran",
            Difficulty::Elite => "elite",
        }
    }

    pub fn parse(name: &str) -> Option<Difficulty> {
        Difficulty::ALL.into_iter().find(|d| d.name() == name)
    }

    pub fn preset(self) -> Preset {
        let second = TICK_HZ as u64;
        match self {
            Difficulty::Recruit => Preset {
                robots: 1,
                planner: PlannerKind::Baseline,
                robot_speed: 0.8,
                tag_cooldown_ticks: 2 * second,
                time_limit_s: 120,
            },
            Difficulty::Veteran => Preset {
                robots: 2,
                planner: PlannerKind::Baseline,
                robot_speed: 0.8,
                tag_cooldown_ticks: 2 * second,
                time_limit_s: 120,
            },
            Difficulty::Elite => Preset {
                robots: 2,
                planner: PlannerKind::Coordinated,
                robot_speed: 1.0,
                tag_cooldown_ticks: second,
                time_limit_s: 120,
            },
        }
    }

    /// `config` with the preset's settings.
    pub fn apply(self, config: &mut MatchConfig) {
        let p = self.preset();
        config.robots = p.robots;
        config.planner = p.planner;
        config.physics = self.physics(config.physics.clone());
        config.time_limit_ticks = p.time_limit_s * TICK_HZ as u64;
    }

    /// `physics` with the preset's robot speed and tag cool-down: the part of a preset no
    /// other setting of a match carries.
    pub fn physics(self, physics: Physics) -> Physics {
        let p = self.preset();
        Physics {
            robot_speed: p.robot_speed,
            tag_cooldown_ticks: p.tag_cooldown_ticks,
            ..physics
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_presets_grow_harder() {
        for d in Difficulty::ALL {
            assert_eq!(Difficulty::parse(d.name()), Some(d));
        }
        assert_eq!(Difficulty::parse("Elite"), None);
        let [r, v, e] = Difficulty::ALL.map(Difficulty::preset);
        assert!(r.robots <= v.robots && v.robots <= e.robots);
        assert_eq!(e.planner, PlannerKind::Coordinated);
        assert!(r.robot_speed <= v.robot_speed && v.robot_speed <= e.robot_speed);
        assert!(r.tag_cooldown_ticks >= e.tag_cooldown_ticks);
    }

    #[test]
    fn a_preset_sets_only_the_team_and_the_clock() {
        let mut config = MatchConfig::default();
        Difficulty::Recruit.apply(&mut config);
        assert_eq!(config.robots, 1);
        assert_eq!(config.planner, PlannerKind::Baseline);
        assert_eq!(config.physics.robot_speed, 0.8);
        assert_eq!(config.physics.tag_cooldown_ticks, 2 * TICK_HZ as u64);
        assert_eq!(config.time_limit_ticks, 120 * TICK_HZ as u64);
        let default = MatchConfig::default();
        assert_eq!(
            config.physics.opponent_speed,
            default.physics.opponent_speed
        );
        assert_eq!(config.opponents, default.opponents);
        assert_eq!(config.tracker, default.tracker);
    }
}
