//! The experiment of the paper's Fig. 5: how soon two robots tag one opponent, with the
//! tracker-driven `coordinated` planner and its look-ahead variant `search`
//! (docs/search-planner.md) against the random `baseline`, from random starts.
//!
//! For each map and opponent bot, runs `runs` seeded matches per planner (run `i` uses the
//! same seed, so the same starts, for every planner), and writes every capture time to a CSV,
//! a summary with median, mean and its 95% confidence interval, a Mann–Whitney U test of
//! the difference, and one SVG per setting: the fraction of runs that have tagged the
//! opponent by each time.
//!
//! Every tick until the tag it also measures how close the team's belief is to the truth
//! (GOSPA, [`crate::tracking`]): `capture_gospa.csv` per run, the means in the summary, and
//! the mean over the runs still going at each second (`capture_gospa_time.csv`, one SVG per
//! map and bot). It notes when a robot first saw an opponent, which splits a capture into
//! finding and chasing; with `oracle_belief` every tracker is handed the truth each tick,
//! which bounds what a better search of the belief could gain.
//!
//! It also measures how long robots stand still while an opponent is untagged (the longest
//! spell of any robot, [`lasertag_core::sim::still`]): a team that parks is one a person
//! beats by waiting, so `--bots idle` (an opponent that hides and never moves) is among the
//! bots a study can run.
//!
//! `--planners` adds teams to the three: a shipped trained policy (`policy:<name>`), whose
//! orders go in before each tick ([`crate::policy`]), in every table, file and plot.

mod bots;
mod oracle;
pub mod planner;
mod statistics;

use crate::error::LabError;
use std::path::Path;
use std::sync::Arc;

use crate::part::Params;
use crate::plot::{self, Series};
use crate::record::{Fields, Line, Record};
use crate::study::{MapStamp, Study, group_from_params, group_to_params};
use crate::tracking::{self, Parts, Track};
pub(crate) use bots::bot_name;
use bots::bots_name;
pub use bots::{DEFAULT_BOTS, parse_bots};
use lasertag_core::bots::BotKind;
use lasertag_core::sim::TICK_HZ;
use lasertag_core::sim::arena::Arena;
use lasertag_core::sim::still::LongestStill;
use lasertag_core::world::{MatchConfig, Placement};
use lasertag_core::world::{MatchStatus, Side, World};
pub use planner::Planner;
pub use statistics::{mann_whitney_p, wilcoxon_signed_rank_p};
pub(crate) use statistics::{mean_ci, median, parked, stats};

#[derive(Debug, Clone)]
pub struct CaptureConfig {
    pub runs: usize,
    /// Opponents per match (1, as in the paper, unless asked); a run ends when all are tagged.
    pub opponents: usize,
    pub seed: u64,
    pub time_limit_s: u64,
    /// Weights of the coordinated planner (the defaults unless tuning).
    pub coordination: lasertag_core::planner::coordinated::Settings,
    /// Robots localise themselves (the default); false leaves them their odometry.
    pub localisation: bool,
    /// The team radio (perfect unless asked: `--radio-latency`, `--radio-loss`).
    pub radio: lasertag_core::radio::Settings,
    /// Every tick, each tracker's clouds are put on the true opponents (`--oracle-belief`).
    pub oracle_belief: bool,
    /// The teams compared, in order (`--planners`; `baseline` and `coordinated` among them).
    pub planners: Vec<Planner>,
    /// The opponent bots, in order (`--bots`).
    pub bots: Vec<BotKind>,
}

/// One setting of the experiment.
#[derive(Debug, Clone)]
struct Setting {
    map: usize,
    bot: BotKind,
    planner: Planner,
}

/// When, in seconds from the start, a run's robots first saw an opponent and when they had
/// tagged every opponent (`None`: not within the time limit). Capture time is finding plus
/// chasing: the first sighting splits them, and says how much of it a planner that
/// searches better can shorten at all.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    pub tagged: Option<f64>,
    pub first_seen: Option<f64>,
    /// The longest any robot stood still (within its own radius of one point) while an
    /// opponent was untagged and the robot could move, in seconds.
    pub longest_still_s: f64,
}

impl Record for Outcome {
    fn write(&self, out: &mut Line) {
        self.tagged.write(out);
        self.first_seen.write(out);
        self.longest_still_s.write(out);
    }
    fn read(input: &mut Fields) -> Result<Outcome, String> {
        Ok(Outcome {
            tagged: Record::read(input)?,
            first_seen: Record::read(input)?,
            longest_still_s: Record::read(input)?,
        })
    }
}

/// What a run's line holds before its GOSPA track, as the parameter `run_fields` names it:
/// a part whose runs hold less cannot be read.
const RUN_FIELDS: &str = "tagged,first_seen,longest_still";

/// The run's [`Outcome`] and the belief's GOSPA at every tick while the match ran.
fn one_run(
    arena: Arc<Arena>,
    s: &Setting,
    seed: u64,
    cfg: &CaptureConfig,
) -> Result<Run, LabError> {
    let limit_s = cfg.time_limit_s;
    let mut config = MatchConfig {
        robots: 2,
        opponents: cfg.opponents,
        opponent_bot: s.bot,
        placement: Placement::Random,
        seed,
        time_limit_ticks: limit_s * TICK_HZ as u64,
        coordination: cfg.coordination.clone(),
        localisation: cfg.localisation,
        radio: cfg.radio.clone(),
        ..MatchConfig::default()
    };
    s.planner.apply(&mut config);
    let mut world = World::new(arena, config)?;
    let mut team = crate::policy::for_world(&world)?;
    let mut track = Track::default();
    let mut first_seen = None;
    let mut still = LongestStill::default();
    while world.status == MatchStatus::Running {
        if cfg.oracle_belief {
            oracle::reveal_opponents(&mut world);
        }
        // A policy decides from the belief as it is now (the oracle's, with one).
        crate::policy::step(team.as_mut(), &mut world);
        // A detection by any robot's own laser (anonymous: which opponent does not matter).
        if first_seen.is_none() && world.robots.iter().any(|r| !r.scan.seen.is_empty()) {
            first_seen = Some(world.time_s());
        }
        // Not the tick that ends the match: with the opponent tagged there is nothing to
        // track, and its zero would flatter every run by a tick.
        if world.status == MatchStatus::Running {
            track.push(&world);
            for (i, r) in world.robots.iter().enumerate() {
                if world.robot_frozen(i) {
                    still.pause(i);
                } else {
                    still.push(i, r.pose.pos, world.tick);
                }
            }
        }
    }
    let tagged = (world.winner == Some(Side::Robots)).then(|| world.time_s());
    let outcome = Outcome {
        tagged,
        first_seen,
        longest_still_s: still.longest_ticks() as f64 / TICK_HZ as f64,
    };
    Ok((outcome, track.finish()))
}

/// The median time to the first sighting (a run that saw nothing counts as the `limit`) and
/// the median time from it to the tag, over the runs that tagged (`NaN` when none did).
fn find_and_chase(outcomes: &[Outcome], limit: f64) -> (f64, f64) {
    let mut found: Vec<f64> = outcomes
        .iter()
        .map(|o| o.first_seen.unwrap_or(limit))
        .collect();
    let mut chases: Vec<f64> = outcomes
        .iter()
        .filter_map(|o| Some(o.tagged? - o.first_seen?))
        .collect();
    (median(&mut found), median(&mut chases))
}

/// Runs still going at a second below which a curve of their mean stops: a mean over a
/// handful of long runs says more about those runs than about the planner.
const CURVE_MIN_RUNS: f64 = 0.1;

/// Each second's mean GOSPA over the runs still going, while at least [`CURVE_MIN_RUNS`] of
/// the runs (and at least one) are.
fn gospa_curve(tracks: &[Track]) -> Vec<(Parts, usize)> {
    let runs: Vec<&Track> = tracks.iter().collect();
    let least = ((tracks.len() as f64 * CURVE_MIN_RUNS).ceil() as usize).max(1);
    tracking::mean_by_second(&runs, false)
        .into_iter()
        .take_while(|(_, n)| *n >= least)
        .collect()
}

/// The study: the configuration and the maps it runs on, in order. Run `j` is setting
/// `j / runs` (map, then bot, then planner) with seed `seed + j % runs`.
#[derive(Debug, Clone)]
pub struct Capture {
    pub cfg: CaptureConfig,
    pub maps: Vec<MapStamp>,
}

/// What one run measured: when it saw and tagged the opponents, and the GOSPA track until
/// then.
pub type Run = (Outcome, Track);

impl Capture {
    fn settings(&self) -> Vec<Setting> {
        let mut settings = Vec::new();
        for map in 0..self.maps.len() {
            for &bot in &self.cfg.bots {
                for planner in &self.cfg.planners {
                    settings.push(Setting {
                        map,
                        bot,
                        planner: planner.clone(),
                    });
                }
            }
        }
        settings
    }

    /// Run `j` of the study; `arenas` are the study's maps, in its order.
    pub fn run_one(&self, arenas: &[Arc<Arena>], j: usize) -> Result<Run, LabError> {
        let cfg = &self.cfg;
        let settings = self.settings();
        let s = settings
            .get(j / cfg.runs)
            .ok_or_else(|| LabError::Scenario(format!("no run {j} in the study")))?;
        let arena = arenas.get(s.map).ok_or_else(|| {
            LabError::Scenario(format!("run {j} is on map {}, which is not loaded", s.map))
        })?;
        one_run(arena.clone(), s, cfg.seed + (j % cfg.runs) as u64, cfg)
    }
}

impl Study for Capture {
    const NAME: &'static str = "capture";
    const LABEL: &'static str = "capture runs";
    type Run = Run;
    /// The summary table.
    type Report = String;

    fn params(&self) -> Params {
        let c = &self.cfg;
        let mut p = Params::default();
        p.set("runs", c.runs);
        p.set("opponents", c.opponents);
        p.set("seed", c.seed);
        p.set("time_limit_s", c.time_limit_s);
        p.set("localisation", c.localisation);
        p.set("oracle_belief", c.oracle_belief);
        group_to_params(&c.coordination, "coordination", &mut p);
        group_to_params(&c.radio, "radio", &mut p);
        MapStamp::to_params(&self.maps, &mut p);
        p.set("planners", planner::list_name(&c.planners));
        p.set("bots", bots_name(&c.bots));
        p.set("run_fields", RUN_FIELDS);
        let policies = c.planners.iter().filter_map(|p| match p {
            Planner::Policy(name) => Some(name.as_str()),
            Planner::BuiltIn(_) => None,
        });
        crate::policy::to_params(policies, &mut p);
        p
    }

    fn from_params(p: &Params) -> Result<Capture, String> {
        if p.get("run_fields").ok() != Some(RUN_FIELDS) {
            return Err(format!(
                "its runs do not record {RUN_FIELDS}: the part was written by an earlier build; run its shard again"
            ));
        }
        Ok(Capture {
            cfg: CaptureConfig {
                runs: p.parse("runs")?,
                opponents: p.parse("opponents")?,
                seed: p.parse("seed")?,
                time_limit_s: p.parse("time_limit_s")?,
                localisation: p.parse("localisation")?,
                oracle_belief: p.parse("oracle_belief")?,
                coordination: group_from_params(p, "coordination")?,
                radio: group_from_params(p, "radio")?,
                // Parts written before the list was a parameter compared the default three.
                planners: Planner::parse_list(p.get("planners").unwrap_or(planner::DEFAULT))
                    .map_err(|e| format!("parameter `planners`: {e}"))?,
                // Parts written before the list was a parameter ran the paper's two.
                bots: parse_bots(p.get("bots").unwrap_or(DEFAULT_BOTS))
                    .map_err(|e| format!("parameter `bots`: {e}"))?,
            },
            maps: MapStamp::from_params(p)?,
        })
    }

    fn runs(&self) -> usize {
        self.settings().len() * self.cfg.runs
    }

    /// Writes the files into `out`; returns the summary table as text.
    fn write(&self, runs: Vec<Run>, out: &Path) -> Result<String, LabError> {
        write(self, runs, out)
    }
}

fn write(study: &Capture, runs: Vec<Run>, out: &Path) -> Result<String, LabError> {
    let cfg = &study.cfg;
    let settings = study.settings();
    let (bots, planners) = (&cfg.bots, &cfg.planners);
    let names: Vec<String> = planners.iter().map(Planner::name).collect();
    let (outcomes, tracks): (Vec<Outcome>, Vec<Track>) = runs.into_iter().unzip();
    let results: Vec<Option<f64>> = outcomes.iter().map(|o| o.tagged).collect();
    let limit = cfg.time_limit_s as f64;
    let mut csv =
        String::from("map,bot,planner,seed,captured,time_s,first_seen_s,longest_still_s\n");
    let mut summary = format!(
        "map,bot,planner,runs,captured,median_s,mean_s,mean_ci95_low_s,mean_ci95_high_s,median_ratio_vs_baseline,mann_whitney_p,{},mean_gospa_ci95_m,median_ratio_vs_coordinated,mann_whitney_p_vs_coordinated,median_first_seen_s,median_chase_s,wilcoxon_p_vs_coordinated,wilcoxon_p_vs_baseline,median_longest_still_s,max_longest_still_s,runs_still_over_10s\n",
        tracking::csv_header("mean_")
    );
    let mut table = format!(
        "{:<10} {:<7} {:<14} {:>8} {:>8} {:>8} {:>16} {:>6} {:>9} {:>7} {:>7}\n",
        "map",
        "bot",
        "planner",
        "captured",
        "median",
        "mean",
        "95% CI of mean",
        "ratio",
        "p",
        "GOSPA",
        "still"
    );
    let mut gospa_csv = format!("map,bot,planner,seed,{}\n", tracking::csv_header("mean_"));
    let mut gospa_time = format!(
        "map,bot,planner,time_s,runs_going,{}\n",
        tracking::csv_header("mean_")
    );
    for (k, s) in settings.iter().enumerate() {
        let seconds = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.2}"));
        for (i, o) in outcomes[k * cfg.runs..(k + 1) * cfg.runs]
            .iter()
            .enumerate()
        {
            csv.push_str(&format!(
                "{},{},{},{},{},{},{},{:.2}\n",
                study.maps[s.map].name,
                bot_name(s.bot),
                s.planner.name(),
                cfg.seed + i as u64,
                o.tagged.is_some(),
                seconds(o.tagged),
                seconds(o.first_seen),
                o.longest_still_s
            ));
        }
        for (i, t) in tracks[k * cfg.runs..(k + 1) * cfg.runs].iter().enumerate() {
            gospa_csv.push_str(&format!(
                "{},{},{},{},{}\n",
                study.maps[s.map].name,
                bot_name(s.bot),
                s.planner.name(),
                cfg.seed + i as u64,
                t.mean.csv()
            ));
        }
    }
    for (map, MapStamp { name: map_name, .. }) in study.maps.iter().enumerate() {
        for &bot in bots {
            let idx = |p: &Planner| {
                settings
                    .iter()
                    .position(|s| s.map == map && s.bot == bot && s.planner == *p)
                    .unwrap_or(0)
            };
            let times_of = |p: &Planner| {
                let k = idx(p);
                results[k * cfg.runs..(k + 1) * cfg.runs].to_vec()
            };
            let outcomes_of = |p: &Planner| {
                let k = idx(p);
                outcomes[k * cfg.runs..(k + 1) * cfg.runs].to_vec()
            };
            let tracks_of = |p: &Planner| {
                let k = idx(p);
                &tracks[k * cfg.runs..(k + 1) * cfg.runs]
            };
            let base = times_of(&Planner::BASELINE);
            let (base_median, ..) = stats(&base, limit);
            // The look-ahead is measured against the greedy choice it refines.
            let greedy = times_of(&Planner::COORDINATED);
            let (greedy_median, ..) = stats(&greedy, limit);
            let as_values =
                |t: &[Option<f64>]| t.iter().map(|v| v.unwrap_or(limit)).collect::<Vec<_>>();
            let mut series = Vec::new();
            let mut gospa_series = Vec::new();
            for (p, name) in planners.iter().zip(&names) {
                let run_means: Vec<f64> = tracks_of(p).iter().map(|t| t.mean.gospa).collect();
                let (_, gospa_ci) = mean_ci(&run_means);
                let gospa = Parts::mean(tracks_of(p).iter().map(|t| t.mean));
                let times = times_of(p);
                let (median, mean, lo, hi) = stats(&times, limit);
                let captured = times.iter().filter(|t| t.is_some()).count();
                let ratio = median / base_median;
                let pv = mann_whitney_p(&as_values(&times), &as_values(&base));
                let greedy_ratio = median / greedy_median;
                let greedy_pv = mann_whitney_p(&as_values(&times), &as_values(&greedy));
                // Run i of every planner has the same seed and starts: paired.
                let paired_pv = wilcoxon_signed_rank_p(&as_values(&times), &as_values(&greedy));
                let paired_base_pv = wilcoxon_signed_rank_p(&as_values(&times), &as_values(&base));
                let (first_seen, chase) = find_and_chase(&outcomes_of(p), limit);
                let spells: Vec<f64> = outcomes_of(p).iter().map(|o| o.longest_still_s).collect();
                let (still_median, still_max, still_over) = parked(&spells);
                summary.push_str(&format!(
                    "{},{},{},{},{captured},{median:.2},{mean:.2},{lo:.2},{hi:.2},{ratio:.3},{pv:.3e},{},{gospa_ci:.4},{greedy_ratio:.3},{greedy_pv:.3e},{first_seen:.2},{chase:.2},{paired_pv:.3e},{paired_base_pv:.3e},{still_median:.2},{still_max:.2},{still_over}\n",
                    map_name,
                    bot_name(bot),
                    name,
                    cfg.runs,
                    gospa.csv()
                ));
                table.push_str(&format!(
                    "{:<10} {:<7} {:<14} {:>4}/{:<3} {:>7.1}s {:>7.1}s {:>16} {:>6.2} {:>9.2e} {:>6.2}m {:>6.1}s\n",
                    map_name,
                    bot_name(bot),
                    name,
                    captured,
                    cfg.runs,
                    median,
                    mean,
                    format!("[{lo:.1}, {hi:.1}] s"),
                    ratio,
                    pv,
                    gospa.gospa,
                    still_max
                ));
                let curve = gospa_curve(tracks_of(p));
                for (t, (parts, n)) in curve.iter().enumerate() {
                    gospa_time.push_str(&format!(
                        "{},{},{},{t},{n},{}\n",
                        map_name,
                        bot_name(bot),
                        name,
                        parts.csv()
                    ));
                }
                let points = curve
                    .iter()
                    .enumerate()
                    .map(|(t, (parts, _))| (t as f64, parts.gospa))
                    .collect();
                gospa_series.push((name.as_str(), points));
                // Fraction of runs that have tagged the opponent by each second.
                let mut done: Vec<f64> = times.iter().flatten().copied().collect();
                done.sort_by(f64::total_cmp);
                let points = (0..=cfg.time_limit_s)
                    .map(|t| {
                        let n = done.partition_point(|v| *v <= t as f64);
                        (t as f64, n as f64 / cfg.runs as f64)
                    })
                    .collect();
                series.push((name.as_str(), points));
            }
            let series: Vec<Series> = series
                .into_iter()
                .map(|(name, points)| Series { name, points })
                .collect();
            plot::lines(
                &out.join(format!("capture_{}_{}.svg", map_name, bot_name(bot))),
                &format!(
                    "Opponents tagged by time: {} vs {} bot ({} runs)",
                    map_name,
                    bot_name(bot),
                    cfg.runs
                ),
                "time (s)",
                &if cfg.opponents == 1 {
                    "fraction of runs with the opponent tagged".to_string()
                } else {
                    format!(
                        "fraction of runs with all {} opponents tagged",
                        cfg.opponents
                    )
                },
                &series,
            )?;
            let gospa_series: Vec<Series> = gospa_series
                .into_iter()
                .map(|(name, points)| Series { name, points })
                .collect();
            plot::lines(
                &out.join(format!("capture_gospa_{}_{}.svg", map_name, bot_name(bot))),
                &format!(
                    "Belief against truth while hunting: {} vs {} bot ({} runs)",
                    map_name,
                    bot_name(bot),
                    cfg.runs
                ),
                "time (s)",
                "mean GOSPA of runs still going (m; c = 2 m, p = 2)",
                &gospa_series,
            )?;
        }
    }
    let write = |name: &str, text: &str| {
        let p = out.join(name);
        crate::error::write(&p, text)
    };
    write("capture.csv", &csv)?;
    write("capture_summary.csv", &summary)?;
    write("capture_gospa.csv", &gospa_csv)?;
    write("capture_gospa_time.csv", &gospa_time)?;
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finding_counts_unseen_runs_at_the_limit_and_chasing_only_tagged_ones() {
        let o = |tagged, first_seen| Outcome {
            tagged,
            first_seen,
            longest_still_s: 0.0,
        };
        let runs = [
            o(Some(12.0), Some(2.0)),
            o(Some(9.0), Some(8.0)),
            o(None, Some(4.0)), // seen, never tagged: finding counts, chasing does not
            o(None, None),      // never seen: found at the limit
        ];
        let (first_seen, chase) = find_and_chase(&runs, 300.0);
        assert_eq!(first_seen, 6.0, "median of 2, 4, 8, 300");
        assert_eq!(chase, 5.5, "median of 10 and 1");
        assert!(find_and_chase(&runs[3..], 300.0).1.is_nan());
    }

    #[test]
    fn a_part_whose_runs_record_less_is_refused_by_why() {
        let study = Capture {
            cfg: CaptureConfig {
                runs: 1,
                opponents: 1,
                seed: 0,
                time_limit_s: 5,
                coordination: Default::default(),
                localisation: true,
                radio: Default::default(),
                oracle_belief: false,
                planners: Planner::parse_list(planner::DEFAULT).expect("the default"),
                bots: parse_bots(DEFAULT_BOTS).expect("the default"),
            },
            maps: Vec::new(),
        };
        let p = study.params();
        assert!(Capture::from_params(&p).is_ok());
        // A part of the build before: no `run_fields`.
        let mut earlier = Params::default();
        for (k, v) in p.iter().filter(|(k, _)| *k != "run_fields") {
            earlier.set(k, v);
        }
        let err = Capture::from_params(&earlier).expect_err("refused");
        assert!(err.contains("earlier build"), "{err}");
    }

    #[test]
    fn an_outcome_reads_back_as_written() {
        for o in [
            Outcome {
                tagged: Some(7.25),
                first_seen: Some(1.5),
                longest_still_s: 3.45,
            },
            Outcome {
                tagged: None,
                first_seen: None,
                longest_still_s: 0.0,
            },
        ] {
            assert_eq!(crate::record::from_line(&crate::record::to_line(&o)), Ok(o));
        }
    }
}
