//! The robot team's difficulty presets, which a person chooses in the lobby (and the API as
//! `difficulty`): each is a set of existing settings — team size, planner, robot speed, tag
//! cool-down, match length — measured against the built-in bots by `lasertag
//! experiment difficulty` (docs/difficulty.md). A preset changes only the robot team and the
//! clock; the opponents' rules are the game's.

use crate::planner::PlannerKind;
use crate::sim::{Physics, TICK_HZ};
use crate::world::MatchConfig;

/// A difficulty preset: the hand-made teams from the easiest, then the learned one (its
/// place among them is its measured rating).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Difficulty {
    /// One slow robot searching at random, slow to fire again: a newcomer's first matches.
    Recruit,
    /// Two slow robots searching at random, each on its own.
    Veteran,
    /// Two robots at full speed that track what they cannot see and coordinate where to look
    /// over a perfect radio: the paper's team, as the showcase plays.
    Elite,
    /// Two robots at full speed driven by the shipped trained policy (`policy:learned`,
    /// `policy/shipped/learned.md`) from what each knows, the team belief included.
    Learned,
}

/// What a preset sets (every other setting keeps its default).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Preset {
    pub robots: usize,
    pub planner: PlannerKind,
    /// The shipped policy that drives the robots, for a learned team.
    pub policy: Option<&'static str>,
    /// Metres per second (the game's default is 1).
    pub robot_speed: f32,
    /// Ticks between two tags of one robot (the game's default is one second).
    pub tag_cooldown_ticks: u64,
    /// The match's length.
    pub time_limit_s: u64,
}

/// One row of a preset's measurement: how its robots did against one built-in bot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured {
    /// `wander` or `evade`.
    pub bot: &'static str,
    pub runs: u32,
    /// Matches the robots won (tagged the bot in time).
    pub robots_won: u32,
    /// Median seconds to the tag, of the matches the robots won.
    pub median_tag_s: f64,
}

/// A preset's rating, which matches never change (see [`Difficulty::rating`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixedRating {
    pub rating: f64,
    pub deviation: f64,
}

impl Difficulty {
    pub const ALL: [Difficulty; 4] = [
        Difficulty::Recruit,
        Difficulty::Veteran,
        Difficulty::Elite,
        Difficulty::Learned,
    ];

    /// The preset a person gets unless they choose: one a newcomer can win.
    pub const DEFAULT: Difficulty = Difficulty::Recruit;

    /// The name the API and the lobby use.
    pub fn name(self) -> &'static str {
        match self {
            Difficulty::Recruit => "recruit",
            Difficulty::Veteran => "veteran",
            Difficulty::Elite => "elite",
            Difficulty::Learned => "learned",
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
                policy: None,
                robot_speed: 0.8,
                tag_cooldown_ticks: 2 * second,
                time_limit_s: 120,
            },
            Difficulty::Veteran => Preset {
                robots: 2,
                planner: PlannerKind::Baseline,
                policy: None,
                robot_speed: 0.8,
                tag_cooldown_ticks: 2 * second,
                time_limit_s: 120,
            },
            Difficulty::Elite => Preset {
                robots: 2,
                planner: PlannerKind::Coordinated,
                policy: None,
                robot_speed: 1.0,
                tag_cooldown_ticks: second,
                time_limit_s: 120,
            },
            Difficulty::Learned => Preset {
                robots: 2,
                planner: PlannerKind::Api,
                policy: Some("learned"),
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
        config.policy = p.policy.map(str::to_string);
        config.physics = self.physics(config.physics.clone());
        config.time_limit_ticks = p.time_limit_s * TICK_HZ as u64;
    }

    /// The maps the presets' ratings were measured on ([`Difficulty::measured`]): a match
    /// on another map measures nothing against them, and is not rated.
    pub const MEASURED_ON: &'static [&'static str] = &["office"];

    /// How the preset's robots did against each built-in bot on `office`
    /// (`lasertag experiment difficulty --runs 200`, seeds 0..200; the committed figures are
    /// `docs/results/difficulty_summary.csv`, which a test of the server holds these to).
    pub fn measured(self) -> [Measured; 2] {
        let m = |bot, runs, robots_won, median_tag_s| Measured {
            bot,
            runs,
            robots_won,
            median_tag_s,
        };
        match self {
            Difficulty::Recruit => [m("wander", 200, 186, 32.03), m("evade", 200, 82, 65.53)],
            Difficulty::Veteran => [m("wander", 200, 198, 23.83), m("evade", 200, 113, 72.75)],
            Difficulty::Elite => [m("wander", 200, 200, 13.25), m("evade", 200, 199, 26.90)],
            Difficulty::Learned => [m("wander", 200, 200, 13.35), m("evade", 200, 199, 13.45)],
        }
    }

    /// The preset's fixed rating on the Glicko scale, where the `evade` bot (a bot that runs
    /// from the robots, the nearest to a person) stands at 1500: the rating whose expected
    /// score against 1500 is the robots' measured win rate against that bot, and as its
    /// deviation the standard error of that estimate on the same scale. The win rate is
    /// taken as (wins + ½) / (runs + 1), so that a preset that never lost still gets a finite
    /// rating.
    pub fn rating(self) -> FixedRating {
        let evade = self.measured()[1];
        let n = evade.runs as f64;
        let p = (evade.robots_won as f64 + 0.5) / (n + 1.0);
        // 400 / ln 10: the Elo and Glicko scale's points per unit of log-odds.
        let scale = 400.0 / std::f64::consts::LN_10;
        FixedRating {
            rating: 1500.0 + scale * (p / (1.0 - p)).ln(),
            deviation: scale / (n * p * (1.0 - p)).sqrt(),
        }
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
        let [r, v, e, l] = Difficulty::ALL.map(Difficulty::preset);
        assert_eq!((l.planner, l.policy), (PlannerKind::Api, Some("learned")));
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

    #[test]
    fn ratings_follow_the_measured_win_rates() {
        let [r, v, e, _] = Difficulty::ALL.map(Difficulty::rating);
        // Recruit's robots win 41% against the evade bot: below 1500; veteran's 56.5%: above.
        assert!(r.rating < 1500.0 && v.rating > 1500.0 && e.rating > v.rating + 500.0);
        assert!((r.rating - 1437.0).abs() < 2.0, "{r:?}");
        // A rating 400 points up means 10:1 odds: elite's 199 of 200 (smoothed) is ~2350.
        assert!((2300.0..2400.0).contains(&e.rating), "{e:?}");
        // Fewer losses measured, a wider interval.
        assert!(r.deviation < e.deviation && r.deviation > 20.0);
    }
}
