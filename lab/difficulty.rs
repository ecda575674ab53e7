//! How hard each difficulty preset is (`lasertag_core::difficulty`): the preset's robots
//! against one built-in bot (`wander`, a newcomer walking about; `evade`, one who runs from
//! robots it sees), from the map's spawns as a person starts, for the preset's match length.
//!
//! For each map, preset and bot it runs `runs` seeded matches and writes every outcome, a
//! summary (the robots' win rate with its 95% Wilson interval, the median time to the tag
//! when they win) and one plot per map and bot: the share of matches the robots have won by
//! each time. The lobby shows the office figures next to the choice (docs/difficulty.md).
//! The `learned` preset's robots are driven by its shipped trained policy ([`crate::policy`]),
//! as a served match drives them.

use std::path::Path;
use std::sync::Arc;

use crate::capture::{bot_name, median};
use crate::error::LabError;
use crate::part::Params;
use crate::plot::{self, Series};
use crate::study::{MapStamp, Study};
use lasertag_core::bots::BotKind;
use lasertag_core::difficulty::Difficulty;
use lasertag_core::sim::arena::Arena;
use lasertag_core::world::{MatchConfig, MatchStatus, Side, World};

const BOTS: [BotKind; 2] = [BotKind::Wander, BotKind::Evade];

/// One setting of the study.
#[derive(Debug, Clone, Copy)]
struct Setting {
    map: usize,
    difficulty: Difficulty,
    bot: BotKind,
}

/// The study: `runs` matches per map, preset and bot. Run `j` is setting `j / runs` (map,
/// then preset, then bot) with seed `seed + j % runs`.
#[derive(Debug, Clone)]
pub struct DifficultyStudy {
    pub runs: usize,
    pub seed: u64,
    pub maps: Vec<MapStamp>,
}

/// Points of a plotted curve.
type Curve = Vec<(f64, f64)>;

/// Seconds until the robots tagged the opponent; `None` when it held out to the end.
pub type Run = Option<f64>;

impl DifficultyStudy {
    fn settings(&self) -> Vec<Setting> {
        let mut settings = Vec::new();
        for map in 0..self.maps.len() {
            for difficulty in Difficulty::ALL {
                for bot in BOTS {
                    settings.push(Setting {
                        map,
                        difficulty,
                        bot,
                    });
                }
            }
        }
        settings
    }

    /// Run `j` of the study; `arenas` are the study's maps, in its order.
    pub fn run_one(&self, arenas: &[Arc<Arena>], j: usize) -> Result<Run, LabError> {
        let s = self.settings()[j / self.runs];
        let arena = arenas.get(s.map).ok_or_else(|| {
            LabError::Scenario(format!("run {j} is on map {}, which is not loaded", s.map))
        })?;
        let mut config = MatchConfig {
            opponents: 1,
            opponent_bot: s.bot,
            seed: self.seed + (j % self.runs) as u64,
            ..MatchConfig::default()
        };
        s.difficulty.apply(&mut config);
        let mut world = World::new(arena.clone(), config)?;
        // The learned preset's robots are driven by its shipped policy.
        let mut team = crate::policy::for_world(&world)?;
        while world.status == MatchStatus::Running {
            crate::policy::step(team.as_mut(), &mut world);
        }
        Ok((world.winner == Some(Side::Robots)).then(|| world.time_s()))
    }
}

/// The robots' share of wins and its 95% Wilson score interval.
pub fn win_rate(wins: usize, runs: usize) -> (f64, f64, f64) {
    if runs == 0 {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let (n, p, z) = (runs as f64, wins as f64 / runs as f64, 1.96f64);
    let centre = (p + z * z / (2.0 * n)) / (1.0 + z * z / n);
    let half = z / (1.0 + z * z / n) * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt();
    (p, (centre - half).max(0.0), (centre + half).min(1.0))
}

impl Study for DifficultyStudy {
    const NAME: &'static str = "difficulty";
    const LABEL: &'static str = "difficulty runs";
    type Run = Run;
    /// The summary table.
    type Report = String;

    fn params(&self) -> Params {
        let mut p = Params::default();
        p.set("runs", self.runs);
        p.set("seed", self.seed);
        MapStamp::to_params(&self.maps, &mut p);
        let policies = Difficulty::ALL.iter().filter_map(|d| d.preset().policy);
        crate::policy::to_params(policies, &mut p);
        p
    }

    fn from_params(p: &Params) -> Result<DifficultyStudy, String> {
        Ok(DifficultyStudy {
            runs: p.parse("runs")?,
            seed: p.parse("seed")?,
            maps: MapStamp::from_params(p)?,
        })
    }

    fn runs(&self) -> usize {
        self.settings().len() * self.runs
    }

    fn write(&self, runs: Vec<Run>, out: &Path) -> Result<String, LabError> {
        let settings = self.settings();
        let mut csv = String::from("map,difficulty,bot,seed,robots_won,time_s\n");
        let mut summary = String::from(
            "map,difficulty,bot,runs,robots_won,win_rate,win_rate_ci95_low,win_rate_ci95_high,median_tag_s,time_limit_s\n",
        );
        let mut table = format!(
            "{:<10} {:<8} {:<7} {:>10} {:>9} {:>16} {:>11}\n",
            "map", "preset", "bot", "robots won", "win rate", "95% CI", "median tag"
        );
        // Each setting's curve: map, bot, preset, (second, share won by then).
        let mut curves: Vec<(usize, BotKind, &str, Curve)> = Vec::new();
        for (k, s) in settings.iter().enumerate() {
            let map = &self.maps[s.map].name;
            let times = &runs[k * self.runs..(k + 1) * self.runs];
            for (i, t) in times.iter().enumerate() {
                csv.push_str(&format!(
                    "{map},{},{},{},{},{}\n",
                    s.difficulty.name(),
                    bot_name(s.bot),
                    self.seed + i as u64,
                    t.is_some(),
                    t.map_or(String::new(), |v| format!("{v:.2}"))
                ));
            }
            let mut won: Vec<f64> = times.iter().flatten().copied().collect();
            let (rate, lo, hi) = win_rate(won.len(), self.runs);
            let med = median(&mut won);
            let limit = s.difficulty.preset().time_limit_s;
            summary.push_str(&format!(
                "{map},{},{},{},{},{rate:.3},{lo:.3},{hi:.3},{med:.2},{limit}\n",
                s.difficulty.name(),
                bot_name(s.bot),
                self.runs,
                won.len(),
            ));
            table.push_str(&format!(
                "{map:<10} {:<8} {:<7} {:>6}/{:<3} {:>8.0}% {:>16} {:>10.1}s\n",
                s.difficulty.name(),
                bot_name(s.bot),
                won.len(),
                self.runs,
                100.0 * rate,
                format!("[{:.0}, {:.0}]%", 100.0 * lo, 100.0 * hi),
                med
            ));
            // `won` is sorted: the share won by each second.
            let points = (0..=limit)
                .map(|t| {
                    let n = won.partition_point(|v| *v <= t as f64);
                    (t as f64, n as f64 / self.runs as f64)
                })
                .collect();
            curves.push((s.map, s.bot, s.difficulty.name(), points));
        }
        for (m, stamp) in self.maps.iter().enumerate() {
            for bot in BOTS {
                let series: Vec<Series> = curves
                    .iter()
                    .filter(|(map, b, ..)| *map == m && *b == bot)
                    .map(|(_, _, name, points)| Series {
                        name,
                        points: points.clone(),
                    })
                    .collect();
                plot::lines(
                    &out.join(format!("difficulty_{}_{}.svg", stamp.name, bot_name(bot))),
                    &format!(
                        "Robots' wins by time, each preset: {} vs {} bot ({} runs)",
                        stamp.name,
                        bot_name(bot),
                        self.runs
                    ),
                    "time (s)",
                    "share of matches the robots have won",
                    &series,
                )?;
            }
        }
        crate::error::write(&out.join("difficulty.csv"), &csv)?;
        crate::error::write(&out.join("difficulty_summary.csv"), &summary)?;
        Ok(table)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wilson_interval_holds_the_rate_and_stays_in_bounds() {
        let (p, lo, hi) = win_rate(0, 100);
        assert_eq!((p, lo), (0.0, 0.0));
        assert!(hi > 0.0 && hi < 0.05, "{hi}");
        let (p, lo, hi) = win_rate(50, 100);
        assert!((p - 0.5).abs() < 1e-12 && lo < 0.5 && hi > 0.5);
        assert!((hi - lo - 0.19).abs() < 0.01, "{lo} {hi}");
        let (p, lo, hi) = win_rate(100, 100);
        assert_eq!(p, 1.0);
        assert!(lo > 0.95 && (hi - 1.0).abs() < 1e-12, "{lo} {hi}");
    }
}
