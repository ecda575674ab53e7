//! The `experiment` commands: their flags (clap), checks and printed tables. The `lasertag`
//! binary mounts [`Experiment`] as `lasertag experiment …` and hands over a map loader, so
//! this crate never reads JSON. Every experiment takes `--shard INDEX/COUNT`
//! ([`ShardArgs`], declared once); `merge` joins the parts and prints what the unsharded
//! command prints.
//!
//! Long file: every experiment's flags are declared here, once, each beside the checks that
//! turn it into its study's configuration; split, a flag and its check would live apart.

use crate::error::{LabError, MergeError};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use clap::Subcommand;
use lasertag_core::settings::{FieldType, Group, Value};
use lasertag_core::sim::arena::Arena;

use crate::capture::Capture;
use crate::difficulty::DifficultyStudy;
use crate::execute::{self, Outcome};
use crate::filters::Filters;
use crate::localisation::Localisation;
use crate::merge;
use crate::reacquire::Reacquire;
use crate::report::{Report, print};
use crate::shard::ShardArgs;
use crate::study::{MapStamp, Study};
use crate::teammate::TeammateStudy;
use crate::uncertainty::Uncertainty;

/// Reads every map of a directory into arenas (the binary's map loader).
pub type LoadMaps = fn(&Path) -> Result<Vec<Arc<Arena>>, LabError>;

#[derive(Debug, Subcommand)]
pub enum Experiment {
    /// Fig. 4: active filters with and without role merging on `hallway`.
    Filters {
        /// Runs per variant (with and without merging).
        #[arg(long, default_value_t = 25)]
        runs: usize,
        /// Opponents passing the door in each run.
        #[arg(long, default_value_t = 20)]
        opponents: usize,
        /// Particles per role.
        #[arg(long, default_value_t = 1000)]
        particles: usize,
        /// Symmetric KL divergence under which two roles merge.
        #[arg(long, default_value_t = 0.7)]
        kl_cutoff: f32,
        /// Seed of the first run (run i uses seed + i).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Directory of map files.
        #[arg(long, default_value = "maps")]
        maps: PathBuf,
        /// Where to write filters.csv and filters.svg.
        #[arg(long, default_value = "out/filters")]
        out: PathBuf,
        #[command(flatten)]
        shard: ShardArgs,
    },
    /// Fig. 5: capture time of `coordinated` and `search` vs `baseline` on `office` and
    /// `warehouse`; `--planners` adds a shipped trained policy (`policy:learned`).
    Capture {
        /// Runs per map, opponent bot and planner.
        #[arg(long, default_value_t = 100)]
        runs: usize,
        /// Seed of the first run (run i uses seed + i, the same for both planners).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Time limit of each run in seconds (runs that reach it count as not captured).
        #[arg(long, default_value_t = 300)]
        time_limit: u64,
        /// Opponents per match (1..=16); a run is a capture when all of them are tagged.
        #[arg(long, default_value_t = 1)]
        opponents: usize,
        /// Maps to run on.
        #[arg(long, value_delimiter = ',', default_value = "office,warehouse")]
        on: Vec<String>,
        /// Directory of map files.
        #[arg(long, default_value = "maps")]
        maps: PathBuf,
        /// Where to write the CSV files and plots.
        #[arg(long, default_value = "out/capture")]
        out: PathBuf,
        #[command(flatten)]
        shard: ShardArgs,
        /// Override a weight of the coordinated planner, e.g. `--set travel_weight=0.02`
        /// (repeatable; the names and ranges of the API's `coordination` object, listed in
        /// docs/settings.md).
        #[arg(long = "set", value_name = "NAME=VALUE")]
        set: Vec<String>,
        /// Whether robots localise themselves (false: odometry alone, which drifts).
        #[arg(long, default_value_t = true, action = clap::ArgAction::Set)]
        localisation: bool,
        /// Team radio latency in ticks (0..=100); with a latency or loss each robot keeps
        /// its own tracker.
        #[arg(long, default_value_t = 0)]
        radio_latency: u32,
        /// Probability that a robot misses one teammate message (0..=1).
        #[arg(long, default_value_t = 0.0)]
        radio_loss: f32,
        /// Hand the team's tracker the truth every tick (every cloud on its opponent): what
        /// the planners achieve with a perfect belief, the floor of what better searching
        /// can reach.
        #[arg(long, default_value_t = false, action = clap::ArgAction::Set)]
        oracle_belief: bool,
        /// The teams compared, comma-separated: `coordinated`, `search`, `baseline` and
        /// `policy:<name>`, a shipped trained policy (`policy:learned`) whose orders go in
        /// before each tick every 2 ticks, as a served match gives them. `baseline` and
        /// `coordinated` must be among them (the summary compares with both).
        #[arg(long, default_value = crate::capture::planner::DEFAULT)]
        planners: String,
        /// The opponent bots, comma-separated: `wander`, `evade`, and `idle` (one that
        /// never moves, as a person hiding: the study's parked time says whether a team
        /// waits it out).
        #[arg(long, default_value = crate::capture::DEFAULT_BOTS)]
        bots: String,
    },
    /// How hard each difficulty preset is: its robots' win rate and median time to the tag
    /// against the `wander` and `evade` bots, from the spawns, for the preset's match length
    /// (the `learned` preset's robots driven by its shipped policy, as a served match's).
    Difficulty {
        /// Runs per map, preset and bot.
        #[arg(long, default_value_t = 200)]
        runs: usize,
        /// Seed of the first run (run i uses seed + i, the same for every preset).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Maps to run on.
        #[arg(long, value_delimiter = ',', default_value = "office")]
        on: Vec<String>,
        /// Directory of map files.
        #[arg(long, default_value = "maps")]
        maps: PathBuf,
        /// Where to write the CSV files and plots.
        #[arg(long, default_value = "out/difficulty")]
        out: PathBuf,
        #[command(flatten)]
        shard: ShardArgs,
    },
    /// A person on the robot team: how soon one planned robot and a scripted person-like
    /// pursuer tag the opponent, with and without the coordinated planner accounting for
    /// the person, against two coordinated and two baseline robots, from random starts.
    Teammate {
        /// Runs per map, bot and team (the same seeds for every team).
        #[arg(long, default_value_t = 100)]
        runs: usize,
        /// Seed of the first run (run i uses seed + i).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Seconds before a run counts as not captured.
        #[arg(long, default_value_t = 300)]
        time_limit: u64,
        /// Maps to run on.
        #[arg(long, value_delimiter = ',', default_value = "office,warehouse")]
        on: Vec<String>,
        /// Directory of map files.
        #[arg(long, default_value = "maps")]
        maps: PathBuf,
        /// Where to write the CSV files and plots.
        #[arg(long, default_value = "out/teammate")]
        out: PathBuf,
        #[command(flatten)]
        shard: ShardArgs,
    },
    /// Coltin et al.'s Table I: time for a robot to see an opponent again that a
    /// teammate sees, with and without shared hypotheses and the tracker's prediction.
    Reacquire {
        /// Runs per condition (the same seeds and routes in every condition).
        #[arg(long, default_value_t = 50)]
        runs: usize,
        /// Seed of the first run (run i uses seed + i).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Longest search counted, seconds (runs that reach it count at it).
        #[arg(long, default_value_t = 60)]
        limit: u64,
        /// Radio latency in ticks (no loss).
        #[arg(long, default_value_t = 2)]
        latency: u32,
        /// Directory of map files (the experiment runs on `office`).
        #[arg(long, default_value = "maps")]
        maps: PathBuf,
        /// Where to write the CSV files and the plot.
        #[arg(long, default_value = "out/reacquire")]
        out: PathBuf,
        #[command(flatten)]
        shard: ShardArgs,
    },
    /// The robots' localisation error over time on every map: with landmarks,
    /// without them, and odometry alone.
    Localisation {
        /// Runs per map and variant (with and without landmarks).
        #[arg(long, default_value_t = 3)]
        runs: usize,
        /// Seed of the first run (run i uses seed + i).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Length of each run in seconds.
        #[arg(long, default_value_t = 600)]
        seconds: u64,
        #[arg(long, default_value_t = 2)]
        robots: usize,
        #[arg(long, default_value_t = 2)]
        opponents: usize,
        /// Directory of map files (every map in it is run).
        #[arg(long, default_value = "maps")]
        maps: PathBuf,
        /// Where to write the CSV files and plots.
        #[arg(long, default_value = "out/localisation")]
        out: PathBuf,
        #[command(flatten)]
        shard: ShardArgs,
    },
    /// Uncertainty-aware motion on and off, for robots that localise from
    /// landmarks and odometry alone (Fabiani & Latombe's setting).
    Uncertainty {
        /// Runs per map, opponent bot and variant (the same seeds in both variants).
        #[arg(long, default_value_t = 100)]
        runs: usize,
        /// Seed of the first run (run i uses seed + i).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Time limit of each run in seconds (runs that reach it count as not captured).
        #[arg(long, default_value_t = 300)]
        time_limit: u64,
        /// Laser beams the localiser uses (0: landmarks and odometry alone).
        #[arg(long, default_value_t = 0)]
        beams: usize,
        /// Odometry noise as a multiple of the default (5% of distance, 2°/m, 2% of turns).
        #[arg(long, default_value_t = 4.0)]
        odometry_scale: f32,
        /// Length of each hunt (tagging off) in seconds.
        #[arg(long, default_value_t = 120)]
        hunt_s: u64,
        /// Maps to run on.
        #[arg(long, value_delimiter = ',', default_value = "office,warehouse")]
        on: Vec<String>,
        /// Directory of map files.
        #[arg(long, default_value = "maps")]
        maps: PathBuf,
        /// Where to write the CSV files and plots.
        #[arg(long, default_value = "out/uncertainty")]
        out: PathBuf,
        #[command(flatten)]
        shard: ShardArgs,
    },
    /// Join the parts of a study run in shards (`--shard INDEX/COUNT`) into the CSV files
    /// and plots one unsharded run writes, byte for byte.
    Merge {
        /// Part files, or directories of them (every `*.part` file in each), such as
        /// `out/capture/parts`.
        #[arg(required = true, value_name = "PARTS")]
        parts: Vec<PathBuf>,
        /// Where to write the CSV files and plots.
        #[arg(long)]
        out: PathBuf,
    },
}

/// The maps named in `on`, loaded from the directory `maps`.
fn chosen_maps(
    load: LoadMaps,
    maps: &Path,
    on: &[String],
) -> Result<Vec<(String, Arc<Arena>)>, LabError> {
    let store = load(maps)?;
    on.iter()
        .map(|name| {
            store
                .iter()
                .find(|a| a.def.name == *name)
                .map(|a| (name.clone(), a.clone()))
                .ok_or_else(|| LabError::NoMap {
                    name: name.clone(),
                    dir: maps.to_owned(),
                })
        })
        .collect()
}

/// The one map `name` from the directory `maps`.
fn one_map(load: LoadMaps, maps: &Path, name: &str) -> Result<Arc<Arena>, LabError> {
    load(maps)?
        .into_iter()
        .find(|a| a.def.name == name)
        .ok_or_else(|| LabError::NoMap {
            name: name.to_owned(),
            dir: maps.to_owned(),
        })
}

/// Runs one experiment command, printing its table; `load` reads a directory of maps.
pub fn run(e: Experiment, load: LoadMaps) -> Result<(), LabError> {
    match e {
        Experiment::Capture {
            runs,
            seed,
            time_limit,
            opponents,
            on,
            maps,
            out,
            set,
            localisation,
            radio_latency,
            radio_loss,
            oracle_belief,
            planners,
            bots,
            shard: ShardArgs { shard },
        } => {
            if runs == 0 || time_limit == 0 {
                return Err(LabError::Arguments(
                    "--runs and --time-limit must be at least 1".into(),
                ));
            }
            if !(1..=16).contains(&opponents) {
                return Err(LabError::Arguments(format!(
                    "--opponents {opponents}: must be in 1..=16"
                )));
            }
            let planners = crate::capture::Planner::parse_list(&planners)
                .map_err(|e| LabError::Arguments(format!("--planners {e}")))?;
            let bots = crate::capture::parse_bots(&bots)
                .map_err(|e| LabError::Arguments(format!("--bots {e}")))?;
            let chosen = chosen_maps(load, &maps, &on)?;
            let mut coordination = lasertag_core::planner::coordinated::Settings::default();
            for kv in &set {
                let (k, v) = kv.split_once('=').ok_or_else(|| {
                    LabError::Arguments(format!("--set {kv}: expected NAME=VALUE"))
                })?;
                coordination
                    .set_text(k, v)
                    .map_err(|error| LabError::Setting {
                        flag: "--set",
                        error,
                    })?;
            }
            let mut radio = lasertag_core::radio::Settings::default();
            radio
                .set("latency_ticks", Value::Integer(radio_latency.into()))
                .map_err(|e| LabError::Arguments(format!("--radio-latency: {}", e.message)))?;
            radio
                .set("loss", radio_loss.to_value())
                .map_err(|e| LabError::Arguments(format!("--radio-loss: {}", e.message)))?;
            let arenas: Vec<Arc<Arena>> = chosen.into_iter().map(|(_, a)| a).collect();
            let study = Capture {
                cfg: crate::capture::CaptureConfig {
                    runs,
                    opponents,
                    seed,
                    time_limit_s: time_limit,
                    coordination,
                    localisation,
                    radio,
                    oracle_belief,
                    planners,
                    bots,
                },
                maps: MapStamp::all(&arenas),
            };
            let done = execute::execute(&study, shard, &out, |j| study.run_one(&arenas, j))?;
            finish(done, Report::Capture, &out)
        }
        Experiment::Difficulty {
            runs,
            seed,
            on,
            maps,
            out,
            shard: ShardArgs { shard },
        } => {
            if runs == 0 {
                return Err(LabError::Arguments("--runs must be at least 1".into()));
            }
            let arenas: Vec<Arc<Arena>> = chosen_maps(load, &maps, &on)?
                .into_iter()
                .map(|(_, a)| a)
                .collect();
            let study = DifficultyStudy {
                runs,
                seed,
                maps: MapStamp::all(&arenas),
            };
            let done = execute::execute(&study, shard, &out, |j| study.run_one(&arenas, j))?;
            finish(done, Report::Difficulty, &out)
        }
        Experiment::Teammate {
            runs,
            seed,
            time_limit,
            on,
            maps,
            out,
            shard: ShardArgs { shard },
        } => {
            if runs == 0 || time_limit == 0 {
                return Err(LabError::Arguments(
                    "--runs and --time-limit must be at least 1".into(),
                ));
            }
            let arenas: Vec<Arc<Arena>> = chosen_maps(load, &maps, &on)?
                .into_iter()
                .map(|(_, a)| a)
                .collect();
            let study = TeammateStudy {
                runs,
                seed,
                time_limit_s: time_limit,
                maps: MapStamp::all(&arenas),
            };
            let done = execute::execute(&study, shard, &out, |j| study.run_one(&arenas, j))?;
            finish(done, Report::Teammate, &out)
        }
        Experiment::Reacquire {
            runs,
            seed,
            limit,
            latency,
            maps,
            out,
            shard: ShardArgs { shard },
        } => {
            if runs == 0 || limit == 0 {
                return Err(LabError::Arguments(
                    "--runs and --limit must be at least 1".into(),
                ));
            }
            if latency > lasertag_core::radio::MAX_LATENCY_TICKS {
                return Err(LabError::Arguments(format!(
                    "--latency {latency} must be in 0..={}",
                    lasertag_core::radio::MAX_LATENCY_TICKS
                )));
            }
            let arena = one_map(load, &maps, "office")?;
            let study = Reacquire {
                cfg: crate::reacquire::ReacquireConfig {
                    runs,
                    seed,
                    limit_s: limit,
                    latency_ticks: latency,
                },
                map: MapStamp::of(&arena.def),
            };
            let done = execute::execute(&study, shard, &out, |j| study.run_one(&arena, j))?;
            finish(done, Report::Reacquire, &out)
        }
        Experiment::Localisation {
            runs,
            seed,
            seconds,
            robots,
            opponents,
            maps,
            out,
            shard: ShardArgs { shard },
        } => {
            if runs == 0 || seconds == 0 || robots == 0 {
                return Err(LabError::Arguments(
                    "--runs, --seconds and --robots must be at least 1".into(),
                ));
            }
            let mut arenas = load(&maps)?;
            arenas.sort_by(|a, b| a.def.name.cmp(&b.def.name));
            let study = Localisation {
                cfg: crate::localisation::LocalisationConfig {
                    runs,
                    seed,
                    seconds,
                    robots,
                    opponents,
                },
                maps: MapStamp::all(&arenas),
            };
            let variants = crate::localisation::variants(&arenas);
            let done = execute::execute(&study, shard, &out, |j| study.run_one(&variants, j))?;
            finish(done, Report::Localisation, &out)
        }
        Experiment::Uncertainty {
            runs,
            seed,
            time_limit,
            beams,
            odometry_scale,
            hunt_s,
            on,
            maps,
            out,
            shard: ShardArgs { shard },
        } => {
            if runs == 0 || time_limit == 0 || hunt_s == 0 {
                return Err(LabError::Arguments(
                    "--runs, --time-limit and --hunt-s must be at least 1".into(),
                ));
            }
            if beams > 181 {
                return Err(LabError::Arguments(format!(
                    "--beams {beams}: must be in 0..=181 (the laser has 181)"
                )));
            }
            // The noise scaled past the API's ranges (heading 45°/m, fractions 1) is nonsense.
            if !(0.0..=20.0).contains(&odometry_scale) {
                return Err(LabError::Arguments(format!(
                    "--odometry-scale {odometry_scale}: must be in [0, 20]"
                )));
            }
            let chosen = chosen_maps(load, &maps, &on)?;
            let arenas: Vec<Arc<Arena>> = chosen.into_iter().map(|(_, a)| a).collect();
            let study = Uncertainty {
                cfg: crate::uncertainty::UncertaintyConfig {
                    runs,
                    seed,
                    time_limit_s: time_limit,
                    beams,
                    odometry_scale,
                    hunt_s,
                },
                maps: MapStamp::all(&arenas),
            };
            let done = execute::execute(&study, shard, &out, |j| study.run_one(&arenas, j))?;
            finish(done, Report::Uncertainty, &out)
        }
        Experiment::Filters {
            runs,
            opponents,
            particles,
            kl_cutoff,
            seed,
            maps,
            out,
            shard: ShardArgs { shard },
        } => {
            if runs == 0
                || opponents == 0
                || particles < 10
                || !(kl_cutoff > 0.0 && kl_cutoff.is_finite())
            {
                return Err(LabError::Arguments("--runs and --opponents must be at least 1, --particles at least 10, --kl-cutoff positive".into()));
            }
            let arena = one_map(load, &maps, "hallway")?;
            let study = Filters {
                cfg: crate::filters::FiltersConfig {
                    runs,
                    opponents,
                    seed,
                    particles_per_role: particles,
                    kl_cutoff,
                },
                map: MapStamp::of(&arena.def),
            };
            let done = execute::execute(&study, shard, &out, |j| study.run_one(&arena, j))?;
            finish(done, Report::Filters, &out)
        }
        Experiment::Merge { parts, out } => {
            let parts = merge::read_parts(&parts)?;
            let experiment = merge::check(&parts)?;
            let report = match experiment {
                Capture::NAME => Report::Capture(merge::join::<Capture>(&parts, &out)?),
                DifficultyStudy::NAME => {
                    Report::Difficulty(merge::join::<DifficultyStudy>(&parts, &out)?)
                }
                TeammateStudy::NAME => {
                    Report::Teammate(merge::join::<TeammateStudy>(&parts, &out)?)
                }
                Reacquire::NAME => Report::Reacquire(merge::join::<Reacquire>(&parts, &out)?),
                Localisation::NAME => {
                    Report::Localisation(merge::join::<Localisation>(&parts, &out)?)
                }
                Uncertainty::NAME => Report::Uncertainty(merge::join::<Uncertainty>(&parts, &out)?),
                Filters::NAME => Report::Filters(merge::join::<Filters>(&parts, &out)?),
                name => {
                    return Err(MergeError::Unknown {
                        path: parts.first().map(|p| p.path.clone()).unwrap_or_default(),
                        name: name.to_string(),
                    }
                    .into());
                }
            };
            print(&report, &out);
            println!("merged {} parts", parts.len());
            Ok(())
        }
    }
}

/// Prints what a command did: the study's tables, or which part a shard wrote.
fn finish<R>(
    done: Outcome<R>,
    report: impl FnOnce(R) -> Report,
    out: &Path,
) -> Result<(), LabError> {
    match done {
        Outcome::Files(r) => print(&report(r), out),
        Outcome::Part(w) => println!(
            "shard {} ran {} of the study's {} runs and wrote {}\n\
             once every shard has run: lasertag experiment merge {} --out {}",
            w.shard,
            w.runs,
            w.study_runs,
            w.path.display(),
            out.join("parts").display(),
            out.display()
        ),
    }
    Ok(())
}
