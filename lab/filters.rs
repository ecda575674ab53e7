//! The experiment of the paper's Fig. 4: an observer robot stands in the doorway of
//! `hallway` watching the hall while about 20 opponents walk past the door one at a time, at
//! random intervals. With role merging the number of active filters should stay small and
//! constant; without it, it grows by one with every opponent seen.
//!
//! Opponents wait out of sight in the storage area left of the room, walk up the west end,
//! along the whole hall (in the observer's view for x ∈ [7, 23]), and park out of sight in
//! the storage area on the right. Departure and parking orders are chosen so nobody walks
//! through someone else's spot.
//!
//! Every tick it also measures how close the belief is to the truth (GOSPA, see
//! [`crate::tracking`]): fewer filters are only better if they still say where people are.

use crate::error::LabError;
use std::path::Path;
use std::sync::Arc;

use nalgebra::Point2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::part::Params;
use crate::plot::{self, Series};
use crate::study::{MapStamp, Study};
use crate::tracking::{self, Parts, Track};
use lasertag_core::planner::PlannerKind;
use lasertag_core::sim::TICK_HZ;
use lasertag_core::sim::arena::Arena;
use lasertag_core::world::World;
use lasertag_core::world::{ControlKind, MatchConfig, OpponentOrder, Placement};

#[derive(Debug, Clone)]
pub struct FiltersConfig {
    pub runs: usize,
    pub opponents: usize,
    pub seed: u64,
    pub particles_per_role: usize,
    pub kl_cutoff: f32,
}

impl Default for FiltersConfig {
    fn default() -> Self {
        FiltersConfig {
            runs: 25,
            opponents: 20,
            seed: 0,
            particles_per_role: 1000,
            kl_cutoff: lasertag_core::tracker::Settings::default().kl_cutoff,
        }
    }
}

/// The lane south of the hall wall that walkers use in both storage areas.
const LANE_Y: f32 = 5.3;
const HALL_Y: f32 = 7.5;
const WEST_X: f32 = 1.5;
const EAST_X: f32 = 28.5;
/// Once past this x a walker is out of the observer's sight: time to schedule the next one.
const OUT_OF_VIEW_X: f32 = 26.0;
/// Seconds between one walker leaving the view and the next setting off.
const GAP_S: (f32, f32) = (2.0, 12.0);
/// Seconds the run goes on after the last walker has parked.
const TAIL_S: u64 = 60;

/// Free spots on a 0.8 m grid inside `[x0, x1] × [0.6, 4.6]`, clear of obstacles.
fn spots(arena: &Arena, x0: f32, x1: f32) -> Vec<Point2<f32>> {
    let mut out = Vec::new();
    let mut x = x0;
    while x <= x1 + 1e-3 {
        let mut y = 0.6;
        while y <= 4.6 + 1e-3 {
            let p = Point2::new(x, y);
            if arena.disc_is_free(p, 0.45) {
                out.push(p);
            }
            y += 0.8;
        }
        x += 0.8;
    }
    out
}

/// One run: the number of active (untagged) filters, sampled once per simulated second,
/// and the belief's GOSPA, measured every tick.
pub fn one_run(
    arena: Arc<Arena>,
    cfg: &FiltersConfig,
    merge: bool,
    run: usize,
) -> Result<(Vec<u32>, Track), LabError> {
    let n = cfg.opponents;
    // Starts: top rows leave first (nobody walks up through a waiting spot).
    let mut starts = spots(&arena, 0.6, 8.2);
    starts.sort_by(|a, b| b.y.total_cmp(&a.y).then(b.x.total_cmp(&a.x)));
    // Parking: columns nearest the lane first, each filled bottom-up.
    let mut parks = spots(&arena, 21.8, 29.4);
    parks.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    if starts.len() < n || parks.len() < n {
        return Err(LabError::Scenario(format!(
            "map {:?} has room for {} waiting and {} parked opponents, {n} needed: this experiment needs the shipped hallway map",
            arena.def.name,
            starts.len(),
            parks.len()
        )));
    }
    starts.truncate(n);
    let config = MatchConfig {
        robots: 1,
        opponents: n,
        opponent_control: ControlKind::Api,
        planner: PlannerKind::Idle,
        seed: cfg.seed + run as u64,
        time_limit_ticks: u64::MAX,
        placement: Placement::Given {
            robots: vec![[15.0, 5.9, std::f32::consts::FRAC_PI_2]],
            opponents: starts.iter().map(|p| [p.x, p.y]).collect(),
        },
        tracker: lasertag_core::tracker::Settings {
            merge,
            particles_per_role: cfg.particles_per_role,
            kl_cutoff: cfg.kl_cutoff,
            ..lasertag_core::tracker::Settings::default()
        },
        ..MatchConfig::default()
    };
    let mut world = World::new(arena, config)?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed.wrapping_mul(1_000_003) + run as u64);
    let mut next = 0usize; // next walker to send
    let mut depart_at = 20u64; // tick
    let mut walking: Option<usize> = None;
    let mut done_at: Option<u64> = None;
    let mut samples = Vec::new();
    let mut track = Track::default();
    loop {
        if walking.is_none() && next < n && world.tick >= depart_at {
            let (s, p) = (starts[next], parks[next]);
            let route = [
                (s.x, LANE_Y),
                (WEST_X, LANE_Y),
                (WEST_X, HALL_Y),
                (EAST_X, HALL_Y),
                (EAST_X, LANE_Y),
                (p.x, LANE_Y),
                (p.x, p.y),
            ];
            world.order_opponent(
                next,
                OpponentOrder::Waypoints(route.iter().map(|&(x, y)| Point2::new(x, y)).collect()),
            )?;
            walking = Some(next);
            next += 1;
        }
        if let Some(k) = walking
            && world.opponents[k].pose.pos.x > OUT_OF_VIEW_X
            && world.opponents[k].pose.pos.y < HALL_Y + 1.0
        {
            walking = None;
            let gap = rng.random_range(GAP_S.0..GAP_S.1);
            depart_at = world.tick + (gap * TICK_HZ as f32) as u64;
            if next == n {
                // The last walker still has to park: about 15 m more.
                done_at = Some(world.tick + (15 + TAIL_S) * TICK_HZ as u64);
            }
        }
        if world.tick.is_multiple_of(TICK_HZ as u64) {
            samples.push(
                world.team.trackers[0]
                    .roles
                    .iter()
                    .filter(|r| !r.tagged)
                    .count() as u32,
            );
        }
        track.push(&world);
        if done_at.is_some_and(|t| world.tick >= t) || world.tick > 3_600 * TICK_HZ as u64 {
            break;
        }
        world.step();
    }
    Ok((samples, track.finish()))
}

/// Mean over runs of each second's count; shorter runs hold their last value.
fn mean_curve(runs: &[Vec<u32>]) -> Vec<f64> {
    let len = runs.iter().map(Vec::len).max().unwrap_or(0);
    (0..len)
        .map(|t| {
            let sum: u32 = runs
                .iter()
                .map(|r| r.get(t).or(r.last()).copied().unwrap_or(0))
                .sum();
            sum as f64 / runs.len().max(1) as f64
        })
        .collect()
}

/// What the experiment found, for the command to print.
#[derive(Debug, Clone)]
pub struct FiltersResult {
    pub with_merge_max_mean: f64,
    pub with_merge_final_mean: f64,
    pub without_merge_final_mean: f64,
    pub without_merge_max_mean: f64,
    pub seconds: usize,
    /// GOSPA and its parts, each run's mean over its ticks averaged over runs, and the
    /// half-width of the 95% confidence interval of that mean GOSPA.
    pub with_merge_gospa: Parts,
    pub without_merge_gospa: Parts,
    pub with_merge_gospa_ci95: f64,
    pub without_merge_gospa_ci95: f64,
}

/// The study: run `j` is with merging for `j < runs`, without it otherwise, with seed
/// `seed + j % runs`, on `hallway`.
#[derive(Debug, Clone)]
pub struct Filters {
    pub cfg: FiltersConfig,
    pub map: MapStamp,
}

/// What one run measured: the active filters each second, and the GOSPA track.
pub type Run = (Vec<u32>, Track);

impl Filters {
    /// Run `j` of the study on `arena` (hallway).
    pub fn run_one(&self, arena: &Arc<Arena>, j: usize) -> Result<Run, LabError> {
        let runs = self.cfg.runs;
        one_run(arena.clone(), &self.cfg, j < runs, j % runs)
    }
}

impl Study for Filters {
    const NAME: &'static str = "filters";
    const LABEL: &'static str = "filters (merge, no merge)";
    type Run = Run;
    type Report = FiltersResult;

    fn params(&self) -> Params {
        let c = &self.cfg;
        let mut p = Params::default();
        p.set("runs", c.runs);
        p.set("opponents", c.opponents);
        p.set("seed", c.seed);
        p.set("particles_per_role", c.particles_per_role);
        p.set("kl_cutoff", c.kl_cutoff);
        MapStamp::to_params(std::slice::from_ref(&self.map), &mut p);
        p
    }

    fn from_params(p: &Params) -> Result<Filters, String> {
        let [map] = <[MapStamp; 1]>::try_from(MapStamp::from_params(p)?)
            .map_err(|maps| format!("{} maps where the experiment runs on one", maps.len()))?;
        Ok(Filters {
            cfg: FiltersConfig {
                runs: p.parse("runs")?,
                opponents: p.parse("opponents")?,
                seed: p.parse("seed")?,
                particles_per_role: p.parse("particles_per_role")?,
                kl_cutoff: p.parse("kl_cutoff")?,
            },
            map,
        })
    }

    fn runs(&self) -> usize {
        2 * self.cfg.runs
    }

    /// Writes `filters.csv`, `filters.svg`, `filters_gospa.csv`, `filters_gospa_runs.csv`
    /// and `filters_gospa.svg` into `out`.
    fn write(&self, runs: Vec<Run>, out: &Path) -> Result<FiltersResult, LabError> {
        write(&self.cfg, runs, out)
    }
}

fn write(cfg: &FiltersConfig, runs: Vec<Run>, out: &Path) -> Result<FiltersResult, LabError> {
    let (counts, tracks): (Vec<Vec<u32>>, Vec<Track>) = runs.into_iter().unzip();
    let (merged, unmerged) = counts.split_at(cfg.runs);
    let with = mean_curve(merged);
    let without = mean_curve(unmerged);
    let len = with.len().max(without.len());
    let at = |c: &[f64], t: usize| c.get(t).or(c.last()).copied().unwrap_or(0.0);
    let mut csv = String::from("time_s,mean_filters_with_merging,mean_filters_without_merging\n");
    for t in 0..len {
        csv.push_str(&format!("{t},{:.3},{:.3}\n", at(&with, t), at(&without, t)));
    }
    let csv_path = out.join("filters.csv");
    crate::error::write(&csv_path, csv)?;
    let curve = |c: &[f64]| (0..len).map(|t| (t as f64, at(c, t))).collect::<Vec<_>>();
    plot::lines(
        &out.join("filters.svg"),
        &format!(
            "Active filters, {} opponents passing a watched door ({} runs each)",
            cfg.opponents, cfg.runs
        ),
        "time (s)",
        "mean number of active filters",
        &[
            Series {
                name: "with merging",
                points: curve(&with),
            },
            Series {
                name: "without merging",
                points: curve(&without),
            },
        ],
    )?;
    let (tracked_with, tracked_without) = tracks.split_at(cfg.runs);
    write_gospa(out, cfg, tracked_with, tracked_without)?;
    let ci = |runs: &[Track]| {
        let means: Vec<f64> = runs.iter().map(|t| t.mean.gospa).collect();
        crate::capture::mean_ci(&means).1
    };
    Ok(FiltersResult {
        with_merge_gospa_ci95: ci(tracked_with),
        without_merge_gospa_ci95: ci(tracked_without),
        with_merge_gospa: Parts::mean(tracked_with.iter().map(|t| t.mean)),
        without_merge_gospa: Parts::mean(tracked_without.iter().map(|t| t.mean)),
        with_merge_max_mean: with.iter().copied().fold(0.0, f64::max),
        with_merge_final_mean: at(&with, len.saturating_sub(1)),
        without_merge_final_mean: at(&without, len.saturating_sub(1)),
        without_merge_max_mean: without.iter().copied().fold(0.0, f64::max),
        seconds: len,
    })
}

/// `filters_gospa.csv` (each second's GOSPA and parts, mean over runs, with and without
/// merging; a finished run holds its last second, as the filter counts do),
/// `filters_gospa_runs.csv` (each run's mean) and `filters_gospa.svg`.
fn write_gospa(
    out: &Path,
    cfg: &FiltersConfig,
    with: &[Track],
    without: &[Track],
) -> Result<(), LabError> {
    let mut runs_csv = format!("merging,seed,{}\n", tracking::csv_header("mean_"));
    for (merging, runs) in [(true, with), (false, without)] {
        for (i, t) in runs.iter().enumerate() {
            let seed = cfg.seed + i as u64;
            runs_csv.push_str(&format!("{merging},{seed},{}\n", t.mean.csv()));
        }
    }
    crate::error::write(&out.join("filters_gospa_runs.csv"), runs_csv)?;
    let curve = |runs: &[Track]| {
        let runs: Vec<&Track> = runs.iter().collect();
        tracking::mean_by_second(&runs, true)
    };
    let (with, without) = (curve(with), curve(without));
    let len = with.len().max(without.len());
    let at =
        |c: &[(Parts, usize)], t: usize| c.get(t).or(c.last()).map_or_else(Parts::default, |p| p.0);
    let mut csv = format!(
        "time_s,{},{}\n",
        tracking::csv_header("with_merging_"),
        tracking::csv_header("without_merging_")
    );
    for t in 0..len {
        csv.push_str(&format!(
            "{t},{},{}\n",
            at(&with, t).csv(),
            at(&without, t).csv()
        ));
    }
    crate::error::write(&out.join("filters_gospa.csv"), csv)?;
    let points = |c: &[(Parts, usize)]| (0..len).map(|t| (t as f64, at(c, t).gospa)).collect();
    plot::lines(
        &out.join("filters_gospa.svg"),
        &format!(
            "Belief against truth, {} opponents passing a watched door ({} runs each)",
            cfg.opponents, cfg.runs
        ),
        "time (s)",
        "mean GOSPA (m; c = 2 m, p = 2)",
        &[
            Series {
                name: "with merging",
                points: points(&with),
            },
            Series {
                name: "without merging",
                points: points(&without),
            },
        ],
    )
}
