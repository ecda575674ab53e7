//! `GET /api/difficulties`: the robot-team presets a person chooses from (the lobby shows
//! them), each with the settings it sets and how often its robots beat the built-in bots
//! (`lasertag experiment difficulty`; the figures are `docs/results/difficulty_summary.csv`,
//! which a test holds them to), and the fixed rating that follows from them.

use serde::Serialize;
use utoipa::ToSchema;

use super::{DifficultyName, Planner, planner_dto};
use lasertag_core::difficulty::Difficulty;
use lasertag_core::sim::TICK_HZ;

/// One preset.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct DifficultyDto {
    pub name: DifficultyName,
    /// Whether a match gets it unless it asks for another (the lobby's first choice).
    pub default: bool,
    pub robots: usize,
    pub planner: Planner,
    /// The trained policy that drives the robots (`planner` then reads `api`), for a learned
    /// team (GET /api/policies).
    pub policy: Option<&'static str>,
    /// The robots' speed, metres per second.
    pub robot_speed: f64,
    /// Seconds between two tags of one robot.
    pub tag_cooldown_s: f64,
    pub time_limit_s: f64,
    /// Measured against each built-in bot.
    pub measured: Vec<MeasuredDto>,
    /// The preset's fixed rating, which a player's rating is measured against in a rated
    /// match (docs/ratings.md): the `evade` bot stands at 1500.
    pub rating: f64,
}

/// How the preset's robots did against one bot, from the map's spawns.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct MeasuredDto {
    pub map: &'static str,
    /// `wander` or `evade`.
    pub bot: &'static str,
    pub runs: u32,
    /// Share of the matches the robots won (tagged the opponent in time).
    pub robots_win_rate: f64,
    /// Median seconds to the tag, of the matches the robots won.
    pub median_tag_s: f64,
}

/// Every preset, from the easiest.
pub fn all() -> Vec<DifficultyDto> {
    Difficulty::ALL
        .into_iter()
        .map(|d| {
            let p = d.preset();
            DifficultyDto {
                name: DifficultyName::of(d),
                default: d == Difficulty::DEFAULT,
                robots: p.robots,
                planner: planner_dto(p.planner),
                policy: p.policy,
                robot_speed: (p.robot_speed as f64 * 1e6).round() / 1e6,
                tag_cooldown_s: p.tag_cooldown_ticks as f64 / TICK_HZ as f64,
                time_limit_s: p.time_limit_s as f64,
                measured: d
                    .measured()
                    .iter()
                    .map(|m| MeasuredDto {
                        map: "office",
                        bot: m.bot,
                        runs: m.runs,
                        robots_win_rate: m.robots_won as f64 / m.runs as f64,
                        median_tag_s: m.median_tag_s,
                    })
                    .collect(),
                rating: d.rating().rating.round(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The figures served are the committed experiment's, row for row.
    #[test]
    fn the_measured_figures_are_the_committed_results() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let csv = std::fs::read_to_string(root.join("docs/results/difficulty_summary.csv"))
            .expect("docs/results/difficulty_summary.csv");
        let rows: Vec<Vec<&str>> = csv
            .lines()
            .skip(1)
            .map(|l| l.split(',').collect())
            .collect();
        let measured: Vec<_> = Difficulty::ALL
            .into_iter()
            .flat_map(|d| d.measured().map(|m| (d, m)))
            .collect();
        assert_eq!(rows.len(), measured.len());
        for (row, (d, m)) in rows.iter().zip(measured) {
            assert_eq!(row[0], "office");
            assert_eq!(row[1], d.name());
            assert_eq!(row[2], m.bot);
            assert_eq!(row[3].parse::<u32>().ok(), Some(m.runs));
            assert_eq!(row[4].parse::<u32>().ok(), Some(m.robots_won));
            assert_eq!(format!("{:.2}", m.median_tag_s), row[8]);
            assert_eq!(row[9].parse::<u64>().ok(), Some(d.preset().time_limit_s));
        }
    }

    #[test]
    fn one_preset_is_the_default_and_each_has_both_bots() {
        let all = all();
        assert_eq!(all.iter().filter(|d| d.default).count(), 1);
        for d in &all {
            let bots: Vec<_> = d.measured.iter().map(|m| m.bot).collect();
            assert_eq!(bots, ["wander", "evade"], "{d:?}");
        }
    }
}
