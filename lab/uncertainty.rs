//! Measured where it matters: Fabiani & Latombe's uncertainty-aware motion
//! against the same planner without it, for robots whose localisation is weak.
//!
//! With the default localiser (30 laser beams against the map) a robot's spread stays at
//! centimetres and the uncertainty terms never fire. Here robots localise as in Fabiani &
//! Latombe, from landmarks and odometry alone (`beams` laser beams, 0 by default), with
//! noisier wheels (`odometry_scale` times the default noise). Both variants run the
//! coordinated planner on the same seeds, hence the same starts and the same noise draws
//! until their choices differ:
//! - `aware`: the defaults (uncertain above 0.15 m of spread: landmark-seeking
//!   destinations, narrow passages avoided, the pursuit look-ahead);
//! - `unaware`: the same with `uncertainty_spread` infinite, so nobody ever counts as
//!   uncertain.
//!
//! Two kinds of run per map, variant and seed:
//! - hunts: tagging off for a fixed time (the robots keep searching), measuring the robots'
//!   true localisation error and the share of robot-time more than 1 m off (lost): what the
//!   trade buys;
//! - captures against the `wander` and `evade` bots: the capture time, what it costs.

use crate::error::LabError;
use std::path::Path;
use std::sync::Arc;

use crate::capture::{bot_name, mann_whitney_p, mean_ci, stats};
use crate::part::Params;
use crate::plot::{self, Bar, Series};
use crate::record::{Fields, Line, Record};
use crate::study::{MapStamp, Study};
use lasertag_core::bots::BotKind;
use lasertag_core::planner::PlannerKind;
use lasertag_core::sim::TICK_HZ;
use lasertag_core::sim::arena::Arena;
use lasertag_core::world::{MatchConfig, Placement};
use lasertag_core::world::{Side, World};

/// A robot whose estimate is further than this from the truth is lost (m).
pub const LOST_M: f32 = 1.0;

#[derive(Debug, Clone)]
pub struct UncertaintyConfig {
    pub runs: usize,
    pub seed: u64,
    pub time_limit_s: u64,
    /// Laser beams the localiser uses (0: landmarks and odometry alone).
    pub beams: usize,
    /// Odometry noise as a multiple of the default (game-rules.md: 5%, 2°/m, 2% of turns).
    pub odometry_scale: f32,
    /// Length of each hunt (tagging off) in seconds.
    pub hunt_s: u64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Variant {
    Aware,
    Unaware,
}

impl Variant {
    pub const ALL: [Variant; 2] = [Variant::Aware, Variant::Unaware];

    pub fn name(self) -> &'static str {
        match self {
            Variant::Aware => "aware",
            Variant::Unaware => "unaware",
        }
    }

    fn label(self) -> &'static str {
        match self {
            Variant::Aware => "uncertainty-aware",
            Variant::Unaware => "unaware",
        }
    }
}

/// The match of one run: the weak robot, the coordinated planner, aware or not.
fn config(cfg: &UncertaintyConfig, bot: BotKind, variant: Variant, seed: u64) -> MatchConfig {
    let d = MatchConfig::default();
    let k = cfg.odometry_scale;
    let physics = lasertag_core::sim::Physics {
        odometry: lasertag_core::sim::Odometry {
            distance: d.physics.odometry.distance * k,
            heading_deg_per_m: d.physics.odometry.heading_deg_per_m * k,
            turn: d.physics.odometry.turn * k,
        },
        ..d.physics.clone()
    };
    let localiser = lasertag_core::localise::Settings {
        beams: cfg.beams,
        ..lasertag_core::localise::Settings::for_odometry(&physics)
    };
    let mut coordination = d.coordination.clone();
    if variant == Variant::Unaware {
        // Not the API's maximum (10 m): a robot lost for minutes can be more unsure than that.
        coordination.uncertainty_spread = f32::INFINITY;
    }
    MatchConfig {
        robots: 2,
        opponents: 1,
        opponent_bot: bot,
        planner: PlannerKind::Coordinated,
        placement: Placement::Random,
        seed,
        time_limit_ticks: cfg.time_limit_s * TICK_HZ as u64,
        physics,
        localiser,
        coordination,
        ..d
    }
}

/// What one hunt measured (tagging off, a fixed duration: the robots keep searching).
#[derive(Debug, Clone, PartialEq)]
pub struct Hunt {
    /// Per second, the mean over robots and that second's ticks of the position error (m).
    pub error_per_second: Vec<f64>,
    /// Mean over robots and ticks of the position error (m).
    pub mean_error_m: f64,
    /// Share of robot-ticks more than [`LOST_M`] off.
    pub lost_share: f64,
    /// Share of robot-ticks whose spread made them uncertain for the (aware) planner.
    pub uncertain_share: f64,
}

/// Seconds until the opponent was tagged; `None` at the time limit.
pub fn capture_run(
    arena: Arc<Arena>,
    cfg: &UncertaintyConfig,
    bot: BotKind,
    variant: Variant,
    seed: u64,
) -> Result<Option<f64>, LabError> {
    let config = config(cfg, bot, variant, seed);
    let mut world = World::new(arena, config)?;
    while world.step() {}
    Ok((world.winner == Some(Side::Robots)).then(|| world.time_s()))
}

/// A hunt of `cfg.hunt_s` seconds against a wandering bot with tagging off.
pub fn hunt_run(
    arena: Arc<Arena>,
    cfg: &UncertaintyConfig,
    variant: Variant,
    seed: u64,
) -> Result<Hunt, LabError> {
    let mut config = config(cfg, BotKind::Wander, variant, seed);
    config.physics.tag_range = 0.0;
    config.time_limit_ticks = cfg.hunt_s * TICK_HZ as u64;
    // Against the aware threshold in both variants, so that the shares compare.
    let uncertain_above =
        lasertag_core::planner::coordinated::Settings::default().uncertainty_spread;
    let mut world = World::new(arena, config)?;
    let mut error_per_second = Vec::with_capacity(cfg.hunt_s as usize);
    let (mut n, mut total, mut lost, mut uncertain) = (0usize, 0.0f64, 0usize, 0usize);
    let (mut second_sum, mut second_n) = (0.0f64, 0usize);
    for t in 1..=cfg.hunt_s * TICK_HZ as u64 {
        world.step();
        for r in &world.robots {
            let e = (r.estimate.pos - r.pose.pos).norm();
            n += 1;
            total += e as f64;
            second_sum += e as f64;
            second_n += 1;
            lost += usize::from(e > LOST_M);
            uncertain += usize::from(r.spread > uncertain_above);
        }
        if t % TICK_HZ as u64 == 0 {
            error_per_second.push(second_sum / second_n.max(1) as f64);
            (second_sum, second_n) = (0.0, 0);
        }
    }
    let n = n.max(1) as f64;
    Ok(Hunt {
        error_per_second,
        mean_error_m: total / n,
        lost_share: lost as f64 / n,
        uncertain_share: uncertain as f64 / n,
    })
}

fn p_text(v: f64) -> String {
    if v.is_nan() {
        "-".to_string()
    } else if v < 0.001 {
        "<0.001".to_string()
    } else {
        format!("{v:.3}")
    }
}

const BOTS: [BotKind; 2] = [BotKind::Wander, BotKind::Evade];

/// The study: on every map, both variants. Its runs are the hunts first (map, then variant;
/// `runs` seeds each), then the captures (map, then variant, then bot); run `j` of each
/// kind's list has seed `seed + j % runs`.
#[derive(Debug, Clone)]
pub struct Uncertainty {
    pub cfg: UncertaintyConfig,
    pub maps: Vec<MapStamp>,
}

/// What one run measured.
#[derive(Debug, Clone, PartialEq)]
pub enum Run {
    Hunt(Hunt),
    /// The capture time; `None` at the time limit.
    Capture(Option<f64>),
}

impl Record for Run {
    fn write(&self, out: &mut Line) {
        match self {
            Run::Hunt(h) => {
                out.field("hunt");
                h.error_per_second.write(out);
                for x in [h.mean_error_m, h.lost_share, h.uncertain_share] {
                    x.write(out);
                }
            }
            Run::Capture(t) => {
                out.field("capture");
                t.write(out);
            }
        }
    }
    fn read(input: &mut Fields) -> Result<Run, String> {
        let kind: String = input.next("hunt or capture")?;
        match kind.as_str() {
            "hunt" => Ok(Run::Hunt(Hunt {
                error_per_second: Record::read(input)?,
                mean_error_m: Record::read(input)?,
                lost_share: Record::read(input)?,
                uncertain_share: Record::read(input)?,
            })),
            "capture" => Ok(Run::Capture(Record::read(input)?)),
            _ => Err(format!("{kind:?} is not hunt or capture")),
        }
    }
}

impl Uncertainty {
    /// The hunts' (map, variant) and the captures' (map, bot, variant), in order.
    #[allow(clippy::type_complexity)]
    fn kinds(&self) -> (Vec<(usize, Variant)>, Vec<(usize, BotKind, Variant)>) {
        let mut captures = Vec::new();
        let mut hunts = Vec::new();
        for map in 0..self.maps.len() {
            for &variant in &Variant::ALL {
                hunts.push((map, variant));
                for bot in BOTS {
                    captures.push((map, bot, variant));
                }
            }
        }
        (hunts, captures)
    }

    /// Run `j` of the study; `arenas` are the study's maps, in its order.
    pub fn run_one(&self, arenas: &[Arc<Arena>], j: usize) -> Result<Run, LabError> {
        let (cfg, runs) = (&self.cfg, self.cfg.runs);
        let (hunts, captures) = self.kinds();
        let arena = |map: usize| {
            arenas.get(map).cloned().ok_or_else(|| {
                LabError::Scenario(format!("run {j} is on map {map}, which is not loaded"))
            })
        };
        let seed = cfg.seed + (j % runs) as u64;
        if let Some(&(map, variant)) = hunts.get(j / runs) {
            return hunt_run(arena(map)?, cfg, variant, seed).map(Run::Hunt);
        }
        let &(map, bot, variant) = captures
            .get(j / runs - hunts.len())
            .ok_or_else(|| LabError::Scenario(format!("run {j} is past the study's")))?;
        capture_run(arena(map)?, cfg, bot, variant, seed).map(Run::Capture)
    }
}

impl Study for Uncertainty {
    const NAME: &'static str = "uncertainty";
    const LABEL: &'static str = "uncertainty runs";
    type Run = Run;
    /// The summary tables.
    type Report = String;

    fn params(&self) -> Params {
        let c = &self.cfg;
        let mut p = Params::default();
        p.set("runs", c.runs);
        p.set("seed", c.seed);
        p.set("time_limit_s", c.time_limit_s);
        p.set("beams", c.beams);
        p.set("odometry_scale", c.odometry_scale);
        p.set("hunt_s", c.hunt_s);
        MapStamp::to_params(&self.maps, &mut p);
        p
    }

    fn from_params(p: &Params) -> Result<Uncertainty, String> {
        Ok(Uncertainty {
            cfg: UncertaintyConfig {
                runs: p.parse("runs")?,
                seed: p.parse("seed")?,
                time_limit_s: p.parse("time_limit_s")?,
                beams: p.parse("beams")?,
                odometry_scale: p.parse("odometry_scale")?,
                hunt_s: p.parse("hunt_s")?,
            },
            maps: MapStamp::from_params(p)?,
        })
    }

    fn runs(&self) -> usize {
        let (hunts, captures) = self.kinds();
        (hunts.len() + captures.len()) * self.cfg.runs
    }

    /// Writes `uncertainty_capture.csv`, `uncertainty_hunt.csv`, their summaries and plots
    /// into `out`; returns the summaries as a table.
    fn write(&self, runs: Vec<Run>, out: &Path) -> Result<String, LabError> {
        write(self, runs, out)
    }
}

fn write(study: &Uncertainty, all: Vec<Run>, out: &Path) -> Result<String, LabError> {
    let cfg = &study.cfg;
    let (hunts, captures) = study.kinds();
    let bots = BOTS;
    let runs = cfg.runs;
    let mut hunted = Vec::new();
    let mut captured = Vec::new();
    for (j, r) in all.into_iter().enumerate() {
        match (j < hunts.len() * runs, r) {
            (true, Run::Hunt(h)) => hunted.push(h),
            (false, Run::Capture(t)) => captured.push(t),
            _ => {
                return Err(LabError::Scenario(format!(
                    "run {j} is of the wrong kind (the hunts come first, then the captures)"
                )));
            }
        }
    }
    let limit = cfg.time_limit_s as f64;

    let mut hunt_csv = String::from("map,variant,seed,mean_error_m,lost_share,uncertain_share\n");
    for (k, &(map, variant)) in hunts.iter().enumerate() {
        for (i, h) in hunted[k * runs..(k + 1) * runs].iter().enumerate() {
            hunt_csv.push_str(&format!(
                "{},{},{},{:.4},{:.4},{:.4}\n",
                study.maps[map].name,
                variant.name(),
                cfg.seed + i as u64,
                h.mean_error_m,
                h.lost_share,
                h.uncertain_share
            ));
        }
    }
    let mut capture_csv = String::from("map,bot,variant,seed,captured,time_s\n");
    for (k, &(map, bot, variant)) in captures.iter().enumerate() {
        for (i, t) in captured[k * runs..(k + 1) * runs].iter().enumerate() {
            capture_csv.push_str(&format!(
                "{},{},{},{},{},{}\n",
                study.maps[map].name,
                bot_name(bot),
                variant.name(),
                cfg.seed + i as u64,
                t.is_some(),
                t.map_or(String::new(), |v| format!("{v:.2}"))
            ));
        }
    }

    // Hunts: localisation error and time lost, per map and variant.
    let mut table = format!(
        "hunts ({} s, tagging off, {runs} runs each)\n{:<10} {:<8} {:>17} {:>7} {:>6} {:>10} {:>7} {:>9}\n",
        cfg.hunt_s, "map", "variant", "mean error", "p", "lost", "runs lost", "p", "uncertain"
    );
    let mut hunt_summary = String::from(
        "map,variant,runs,seconds,mean_error_m,mean_error_ci95_half_m,error_p,lost_share,runs_ever_lost,lost_p,uncertain_share\n",
    );
    let mut lost_bars = Vec::new();
    let mut labels = Vec::new();
    for (map, MapStamp { name: map_name, .. }) in study.maps.iter().enumerate() {
        let of = |v: Variant| {
            let k = hunts.iter().position(|h| *h == (map, v)).unwrap_or(0);
            &hunted[k * runs..(k + 1) * runs]
        };
        let errors = |hs: &[Hunt]| hs.iter().map(|h| h.mean_error_m).collect::<Vec<_>>();
        let losts = |hs: &[Hunt]| hs.iter().map(|h| h.lost_share).collect::<Vec<_>>();
        let unaware = of(Variant::Unaware);
        let mut series = Vec::new();
        for &variant in &Variant::ALL {
            let hs = of(variant);
            let (err, err_half) = mean_ci(&errors(hs));
            let (lost, lost_half) = mean_ci(&losts(hs));
            let ever = hs.iter().filter(|h| h.lost_share > 0.0).count();
            let uncertain = hs.iter().map(|h| h.uncertain_share).sum::<f64>() / runs as f64;
            let (error_p, lost_p) = if variant == Variant::Unaware {
                (f64::NAN, f64::NAN)
            } else {
                (
                    mann_whitney_p(&errors(hs), &errors(unaware)),
                    mann_whitney_p(&losts(hs), &losts(unaware)),
                )
            };
            hunt_summary.push_str(&format!(
                "{map_name},{},{runs},{},{err:.4},{err_half:.4},{error_p:.3e},{lost:.4},{ever},{lost_p:.3e},{uncertain:.4}\n",
                variant.name(),
                cfg.hunt_s
            ));
            table.push_str(&format!(
                "{:<10} {:<8} {:>17} {:>7} {:>5.1}% {:>10} {:>7} {:>8.1}%\n",
                map_name,
                variant.name(),
                format!("{err:.3} ± {err_half:.3} m"),
                p_text(error_p),
                100.0 * lost,
                format!("{ever}/{runs}"),
                p_text(lost_p),
                100.0 * uncertain
            ));
            labels.push(format!("{map_name} {}", variant.name()));
            lost_bars.push((100.0 * lost, 100.0 * lost_half));
            let len = hs
                .iter()
                .map(|h| h.error_per_second.len())
                .max()
                .unwrap_or(0);
            let points = (0..len)
                .map(|t| {
                    let xs: Vec<f64> = hs
                        .iter()
                        .filter_map(|h| h.error_per_second.get(t).copied())
                        .collect();
                    (
                        (t + 1) as f64,
                        xs.iter().sum::<f64>() / xs.len().max(1) as f64,
                    )
                })
                .collect();
            series.push(Series {
                name: variant.label(),
                points,
            });
        }
        plot::lines_scaled(
            &out.join(format!("uncertainty_error_{map_name}.svg")),
            &format!(
                "Localisation error while hunting on {map_name} ({} beams, odometry noise ×{}, {runs} runs)",
                cfg.beams, cfg.odometry_scale
            ),
            "time (s)",
            "mean position error (m, log scale)",
            &series,
            plot::YScale::Log { floor_milli: 1 },
        )?;
    }
    let bars: Vec<Bar> = lost_bars
        .iter()
        .zip(&labels)
        .map(|(&(value, error), name)| Bar { name, value, error })
        .collect();
    plot::bars(
        &out.join("uncertainty_lost.svg"),
        &format!(
            "Robot-time lost (> {LOST_M} m off) while hunting, {} s, {runs} runs",
            cfg.hunt_s
        ),
        "% of robot-time (95% CI)",
        &bars,
    )?;

    // Captures: what the trade costs in search time.
    table.push_str(&format!(
        "\ncaptures ({} s limit, {runs} runs each)\n{:<10} {:<7} {:<8} {:>8} {:>8} {:>15} {:>7}\n",
        cfg.time_limit_s, "map", "bot", "variant", "captured", "median", "mean", "p"
    ));
    let mut capture_summary = String::from(
        "map,bot,variant,runs,captured,median_s,mean_s,mean_ci95_low_s,mean_ci95_high_s,mann_whitney_p\n",
    );
    for (map, MapStamp { name: map_name, .. }) in study.maps.iter().enumerate() {
        for &bot in &bots {
            let of = |v: Variant| {
                let k = captures
                    .iter()
                    .position(|c| *c == (map, bot, v))
                    .unwrap_or(0);
                &captured[k * runs..(k + 1) * runs]
            };
            let values =
                |t: &[Option<f64>]| t.iter().map(|v| v.unwrap_or(limit)).collect::<Vec<_>>();
            let unaware = of(Variant::Unaware);
            for &variant in &Variant::ALL {
                let times = of(variant);
                let (median, mean, lo, hi) = stats(times, limit);
                let p = if variant == Variant::Unaware {
                    f64::NAN
                } else {
                    mann_whitney_p(&values(times), &values(unaware))
                };
                let n = times.iter().filter(|t| t.is_some()).count();
                capture_summary.push_str(&format!(
                    "{map_name},{},{},{runs},{n},{median:.2},{mean:.2},{lo:.2},{hi:.2},{p:.3e}\n",
                    bot_name(bot),
                    variant.name()
                ));
                table.push_str(&format!(
                    "{:<10} {:<7} {:<8} {:>4}/{:<3} {:>7.1}s {:>15} {:>7}\n",
                    map_name,
                    bot_name(bot),
                    variant.name(),
                    n,
                    runs,
                    median,
                    format!("{mean:.1} [{lo:.1}, {hi:.1}]"),
                    p_text(p)
                ));
            }
        }
    }
    for (name, text) in [
        ("uncertainty_hunt.csv", &hunt_csv),
        ("uncertainty_hunt_summary.csv", &hunt_summary),
        ("uncertainty_capture.csv", &capture_csv),
        ("uncertainty_capture_summary.csv", &capture_summary),
    ] {
        let path = out.join(name);
        crate::error::write(&path, text)?;
    }
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The two variants differ only in the planner's threshold, and the weak robot really is
    /// weak: no beams, noisier wheels, a motion model that knows it.
    #[test]
    fn the_variants_differ_only_in_whether_anyone_counts_as_uncertain() {
        let cfg = UncertaintyConfig {
            runs: 1,
            seed: 0,
            time_limit_s: 10,
            beams: 0,
            odometry_scale: 4.0,
            hunt_s: 10,
        };
        let aware = config(&cfg, BotKind::Wander, Variant::Aware, 3);
        let unaware = config(&cfg, BotKind::Wander, Variant::Unaware, 3);
        assert_eq!(aware.localiser, unaware.localiser);
        assert_eq!(aware.localiser.beams, 0);
        assert!((aware.physics.odometry.distance - 0.2).abs() < 1e-6);
        assert_eq!(
            aware.coordination.uncertainty_spread,
            lasertag_core::planner::coordinated::Settings::default().uncertainty_spread
        );
        assert_eq!(
            lasertag_core::planner::coordinated::Settings {
                uncertainty_spread: aware.coordination.uncertainty_spread,
                ..unaware.coordination.clone()
            },
            aware.coordination
        );
    }
}
