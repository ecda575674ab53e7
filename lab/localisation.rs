//! How well the robots localise themselves — mean position error over time on every
//! map in three variants: the full filter with the map's landmarks, the filter without
//! landmarks (laser and odometry), and odometry alone (dead reckoning: the drift a robot that
//! does not localise suffers).
//!
//! Each run is a full match with localisation on. Tagging is disabled (`tag_range` 0) so that
//! every run lasts the whole duration: the robots still hunt, which is what moves them.

use crate::error::LabError;
use std::path::Path;
use std::sync::Arc;

use crate::part::Params;
use crate::plot::{self, Series};
use crate::study::{MapStamp, Study};
use lasertag_core::sim::TICK_HZ;
use lasertag_core::sim::arena::{Arena, MapDef};
use lasertag_core::world::MatchConfig;
use lasertag_core::world::World;

#[derive(Debug, Clone)]
pub struct LocalisationConfig {
    pub runs: usize,
    pub seed: u64,
    pub seconds: u64,
    pub robots: usize,
    pub opponents: usize,
}

/// What a robot localises from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    /// Odometry, laser and the map's landmarks (the default).
    Landmarks,
    /// Odometry and laser on the same map with its landmarks removed.
    LaserOnly,
    /// No filter: the estimate is the robot's odometry.
    OdometryOnly,
}

impl Variant {
    pub const ALL: [Variant; 3] = [
        Variant::Landmarks,
        Variant::LaserOnly,
        Variant::OdometryOnly,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Variant::Landmarks => "landmarks",
            Variant::LaserOnly => "laser_only",
            Variant::OdometryOnly => "odometry_only",
        }
    }

    fn label(self) -> &'static str {
        match self {
            Variant::Landmarks => "MCL with landmarks",
            Variant::LaserOnly => "MCL without landmarks",
            Variant::OdometryOnly => "odometry alone",
        }
    }
}

/// Per map and variant: the mean error curve (per second) and summary figures.
#[derive(Debug, Clone)]
pub struct Curve {
    pub map: String,
    pub variant: Variant,
    pub mean_per_second: Vec<f64>,
    pub mean: f64,
    /// The largest error of any robot at any tick of any run.
    pub worst: f64,
}

/// One run: per second, the mean over robots and that second's ticks of the position error;
/// and the worst error seen.
pub fn one_run(
    arena: Arc<Arena>,
    cfg: &LocalisationConfig,
    localisation: bool,
    seed: u64,
) -> Result<(Vec<f64>, f64), LabError> {
    let mut config = MatchConfig {
        robots: cfg.robots,
        opponents: cfg.opponents,
        seed,
        time_limit_ticks: cfg.seconds * TICK_HZ as u64,
        localisation,
        ..MatchConfig::default()
    };
    config.physics.tag_range = 0.0;
    let mut world = World::new(arena, config)?;
    let mut per_second = Vec::with_capacity(cfg.seconds as usize);
    let (mut sum, mut n, mut worst) = (0.0f64, 0usize, 0.0f64);
    for t in 1..=cfg.seconds * TICK_HZ as u64 {
        world.step();
        for r in &world.robots {
            let e = (r.estimate.pos - r.pose.pos).norm() as f64;
            sum += e;
            n += 1;
            worst = worst.max(e);
        }
        if t % TICK_HZ as u64 == 0 {
            per_second.push(sum / n.max(1) as f64);
            (sum, n) = (0.0, 0);
        }
    }
    Ok((per_second, worst))
}

/// The study: every map in name order, each in every [`Variant`]; run `j` is map and
/// variant `j / runs` with seed `seed + j % runs`.
#[derive(Debug, Clone)]
pub struct Localisation {
    pub cfg: LocalisationConfig,
    pub maps: Vec<MapStamp>,
}

/// What one run measured: the mean error each second, and the worst error.
pub type Run = (Vec<f64>, f64);

/// The arena each map's variants run on, in the study's order (map, then variant): the map
/// itself, or for [`Variant::LaserOnly`] the map without its landmarks.
pub fn variants(arenas: &[Arc<Arena>]) -> Vec<(Arc<Arena>, Variant)> {
    arenas
        .iter()
        .flat_map(|a| {
            let bare = Arc::new(Arena::new(MapDef {
                landmarks: vec![],
                ..a.def.clone()
            }));
            [
                (a.clone(), Variant::Landmarks),
                (bare, Variant::LaserOnly),
                (a.clone(), Variant::OdometryOnly),
            ]
        })
        .collect()
}

impl Localisation {
    /// Run `j` of the study; `variants` is [`variants`] of the study's maps.
    pub fn run_one(&self, variants: &[(Arc<Arena>, Variant)], j: usize) -> Result<Run, LabError> {
        let cfg = &self.cfg;
        let (arena, variant) = variants
            .get(j / cfg.runs)
            .ok_or_else(|| LabError::Scenario(format!("run {j} is past the maps loaded")))?;
        let localise = *variant != Variant::OdometryOnly;
        one_run(
            arena.clone(),
            cfg,
            localise,
            cfg.seed + (j % cfg.runs) as u64,
        )
    }
}

impl Study for Localisation {
    const NAME: &'static str = "localisation";
    const LABEL: &'static str = "localisation";
    type Run = Run;
    type Report = Vec<Curve>;

    fn params(&self) -> Params {
        let c = &self.cfg;
        let mut p = Params::default();
        p.set("runs", c.runs);
        p.set("seed", c.seed);
        p.set("seconds", c.seconds);
        p.set("robots", c.robots);
        p.set("opponents", c.opponents);
        MapStamp::to_params(&self.maps, &mut p);
        p
    }

    fn from_params(p: &Params) -> Result<Localisation, String> {
        Ok(Localisation {
            cfg: LocalisationConfig {
                runs: p.parse("runs")?,
                seed: p.parse("seed")?,
                seconds: p.parse("seconds")?,
                robots: p.parse("robots")?,
                opponents: p.parse("opponents")?,
            },
            maps: MapStamp::from_params(p)?,
        })
    }

    fn runs(&self) -> usize {
        self.maps.len() * Variant::ALL.len() * self.cfg.runs
    }

    /// Writes `localisation.csv`, `localisation_summary.csv` and `localisation_<map>.svg`
    /// into `out`.
    fn write(&self, runs: Vec<Run>, out: &Path) -> Result<Vec<Curve>, LabError> {
        write(self, runs, out)
    }
}

fn write(study: &Localisation, results: Vec<Run>, out: &Path) -> Result<Vec<Curve>, LabError> {
    let cfg = &study.cfg;
    let variants = study
        .maps
        .iter()
        .flat_map(|m| Variant::ALL.map(|v| (m.name.clone(), v)));
    let mut curves = Vec::new();
    for (v, (map, variant)) in variants.enumerate() {
        let runs = &results[v * cfg.runs..(v + 1) * cfg.runs];
        let len = runs.iter().map(|r| r.0.len()).max().unwrap_or(0);
        let mean_per_second: Vec<f64> = (0..len)
            .map(|t| {
                let xs: Vec<f64> = runs.iter().filter_map(|r| r.0.get(t).copied()).collect();
                xs.iter().sum::<f64>() / xs.len().max(1) as f64
            })
            .collect();
        let mean = mean_per_second.iter().sum::<f64>() / mean_per_second.len().max(1) as f64;
        let worst = runs.iter().map(|r| r.1).fold(0.0, f64::max);
        curves.push(Curve {
            map,
            variant,
            mean_per_second,
            mean,
            worst,
        });
    }
    let mut csv = String::from("map,variant,time_s,mean_position_error_m\n");
    let mut summary = String::from("map,variant,runs,seconds,mean_position_error_m,worst_m\n");
    for c in &curves {
        for (t, e) in c.mean_per_second.iter().enumerate() {
            csv.push_str(&format!(
                "{},{},{},{e:.4}\n",
                c.map,
                c.variant.name(),
                t + 1
            ));
        }
        summary.push_str(&format!(
            "{},{},{},{},{:.4},{:.4}\n",
            c.map,
            c.variant.name(),
            cfg.runs,
            cfg.seconds,
            c.mean,
            c.worst
        ));
    }
    for (name, text) in [
        ("localisation.csv", &csv),
        ("localisation_summary.csv", &summary),
    ] {
        let path = out.join(name);
        crate::error::write(&path, text)?;
    }
    for per_map in curves.chunks(Variant::ALL.len()) {
        let series: Vec<Series> = per_map
            .iter()
            .map(|c| Series {
                name: c.variant.label(),
                points: c
                    .mean_per_second
                    .iter()
                    .enumerate()
                    .map(|(t, e)| ((t + 1) as f64, *e))
                    .collect(),
            })
            .collect();
        let map = &per_map[0].map;
        plot::lines_scaled(
            &out.join(format!("localisation_{map}.svg")),
            &format!(
                "Localisation error on {map} ({} runs, {} robots)",
                cfg.runs, cfg.robots
            ),
            "time (s)",
            "mean position error (m, log scale)",
            &series,
            plot::YScale::Log { floor_milli: 1 },
        )?;
    }
    Ok(curves)
}
