//! The analogue of Coltin et al.'s Table I: a robot loses sight of an
//! opponent that a teammate can see; how long until it sees the opponent again?
//!
//! The paper kicks a ball out of one robot's view towards a teammate and times how long the
//! first robot takes to find it again: with neither teammate nor kick hypotheses (6.13 ±
//! 2.35 s), with the teammate's hypotheses (3.99 ± 1.73 s), with the kick's predicted
//! hypotheses (1.63 ± 0.38 s). Here, on `office`:
//!
//! - robot B (`r0`) stands in the corridor and sees the opponent 4 m ahead;
//! - robot A (`r1`) stands in the room south of the corridor, facing the door, and stays
//!   there as a sentinel (its motion is overridden to stop; it senses, tracks and
//!   broadcasts as usual), like the paper's second robot that only turns its head;
//! - the opponent (API-driven) walks down the corridor, through the door into A's room and
//!   on to a random point of the room in A's view (drawn from the run's seed), where it
//!   stops.
//!
//! B loses sight of it in the doorway; A sees it come in. The time measured runs from the
//! first tick B does not see the opponent after the opponent entered the doorway to the
//! first tick B detects it again (capped at `limit_s`; runs that never do are counted at the
//! cap and reported). Robots cannot tag (tag range 0), so nothing ends the search early; both
//! run the `coordinated` planner with its own tracker (the per-robot machinery of
//! `lasertag_core::radio`, latency `latency_ticks`), with `claim_keep` 1: by default a robot leaves
//! an opponent its teammate watches to that teammate (the pursuer's view is claimed, so it
//! is worth little to anyone else), which is right for a team hunting opponents but means B
//! would not try to see it again. The paper's robots, too, each look at the ball.
//!
//! Four conditions, each `runs` times with the same seeds and routes:
//!
//! | condition | B hears A's sightings | B's tracker predicts motion |
//! |---|---|---|
//! | `none` | no | no |
//! | `shared` | yes | no |
//! | `predicted` | no | yes |
//! | `both` | yes | yes (the normal team) |
//!
//! Writes `reacquire.csv` (every run), `reacquire_summary.csv` (mean ± std per condition)
//! and `reacquire.svg` (bars with ± std error bars).

use crate::error::LabError;
use std::path::Path;
use std::sync::Arc;

use nalgebra::Point2;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::part::Params;
use crate::plot;
use crate::record::{Fields, Line, Record};
use crate::study::{MapStamp, Study};
use lasertag_core::planner::PlannerKind;
use lasertag_core::sim::arena::Arena;
use lasertag_core::sim::{AGENT_RADIUS, Motion, Physics, Pose, TICK_HZ};
use lasertag_core::world::{ControlKind, MatchConfig, OpponentOrder, Placement};
use lasertag_core::world::{MatchStatus, World};

#[derive(Debug, Clone)]
pub struct ReacquireConfig {
    pub runs: usize,
    pub seed: u64,
    /// Longest search counted (seconds).
    pub limit_s: u64,
    /// The radio's latency in ticks (loss is 0: a lost sighting would blur the conditions).
    pub latency_ticks: u32,
}

/// What B knows: teammates' sightings, the tracker's motion prediction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Condition {
    pub name: &'static str,
    pub label: &'static str,
    pub shared: bool,
    pub predicted: bool,
}

pub const CONDITIONS: [Condition; 4] = [
    Condition {
        name: "none",
        label: "no hypotheses",
        shared: false,
        predicted: false,
    },
    Condition {
        name: "shared",
        label: "teammate's",
        shared: true,
        predicted: false,
    },
    Condition {
        name: "predicted",
        label: "prediction",
        shared: false,
        predicted: true,
    },
    Condition {
        name: "both",
        label: "both",
        shared: true,
        predicted: true,
    },
];

/// The set-up on `office` (see the module docs).
const B_START: [f32; 3] = [5.0, 8.0, 0.0];
const A_START: [f32; 3] = [15.0, 5.8, std::f32::consts::PI];
const OPPONENT_START: [f32; 2] = [9.0, 8.0];
/// The corridor's door into A's room, and the room's free rectangle the opponent ends in.
const DOOR_X: f32 = 10.75;
const DOORWAY_Y: f32 = 7.0;
const ROOM: ([f32; 2], [f32; 2]) = ([8.7, 0.6], [15.4, 6.3]);

/// One run's outcome.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    /// Seconds from losing sight to seeing again; `None` if not within the limit.
    pub time_s: Option<f64>,
    /// Share of the lost time during which the teammate saw the opponent.
    pub teammate_saw: f64,
    /// Where the opponent stopped.
    pub end: Point2<f32>,
}

/// The opponent's end point for run `seed`: uniform over the free space of the room that
/// A's laser covers from where it stands (so the teammate does see it).
fn end_point(arena: &Arena, physics: &Physics, seed: u64) -> Point2<f32> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x05ee_d0f7_ab1e);
    let ([x0, y0], [x1, y1]) = ROOM;
    let a = Pose::new(A_START[0], A_START[1], A_START[2]);
    for _ in 0..10_000 {
        let p = Point2::new(rng.random_range(x0..x1), rng.random_range(y0..y1));
        let in_view = (p - a.pos).norm() < physics.laser_range - 0.5
            && a.bearing_to(p).abs() < physics.laser_fov / 2.0 - 0.1
            && arena.line_of_sight(a.pos, p);
        if in_view && arena.disc_is_free(p, AGENT_RADIUS + 0.1) {
            return p;
        }
    }
    Point2::new(DOOR_X, 5.6)
}

/// One tick, A held in place first.
fn step(world: &mut World) {
    world.robots[1].command.motion = Motion::Stop;
    world.step();
}

pub fn one_run(
    arena: Arc<Arena>,
    c: Condition,
    seed: u64,
    cfg: &ReacquireConfig,
) -> Result<Outcome, LabError> {
    let physics = Physics {
        tag_range: 0.0, // nobody ends the search by tagging
        ..Physics::default()
    };
    let config = MatchConfig {
        robots: 2,
        opponents: 1,
        opponent_control: ControlKind::Api,
        planner: PlannerKind::Coordinated,
        placement: Placement::Given {
            robots: vec![B_START, A_START],
            opponents: vec![OPPONENT_START],
        },
        seed,
        time_limit_ticks: u64::MAX / 2,
        physics: physics.clone(),
        coordination: lasertag_core::planner::coordinated::Settings {
            claim_keep: 1.0,
            ..Default::default()
        },
        tracker: lasertag_core::tracker::Settings {
            predict: c.predicted,
            ..lasertag_core::tracker::Settings::default()
        },
        radio: lasertag_core::radio::Settings {
            latency_ticks: cfg.latency_ticks,
            loss: 0.0,
            share_sightings: c.shared,
            per_robot: true,
        },
        ..MatchConfig::default()
    };
    let end = end_point(&arena, &physics, seed);
    let mut world = World::new(arena, config)?;
    world.order_opponent(
        0,
        OpponentOrder::Waypoints(vec![
            Point2::new(DOOR_X, OPPONENT_START[1]),
            Point2::new(DOOR_X, 5.6),
            end,
        ]),
    )?;
    let sees = |w: &World, i: usize| !w.robots[i].scan.detections.is_empty();
    let limit = cfg.limit_s * TICK_HZ as u64;
    let mut lost_at: Option<u64> = None;
    let mut teammate_ticks = 0u64;
    // Set-up: at most 30 s for the opponent to reach the doorway out of B's sight.
    while world.status == MatchStatus::Running && world.tick < 30 * TICK_HZ as u64 {
        step(&mut world);
        if world.opponents[0].pose.pos.y < DOORWAY_Y && !sees(&world, 0) {
            lost_at = Some(world.tick);
            break;
        }
    }
    let Some(lost) = lost_at else {
        return Err(LabError::Scenario(format!(
            "seed {seed}: the opponent never left B's sight"
        )));
    };
    while world.tick < lost + limit {
        if sees(&world, 0) {
            let ticks = world.tick - lost;
            return Ok(Outcome {
                time_s: Some(ticks as f64 / TICK_HZ as f64),
                teammate_saw: teammate_ticks as f64 / ticks.max(1) as f64,
                end,
            });
        }
        teammate_ticks += sees(&world, 1) as u64;
        step(&mut world);
    }
    Ok(Outcome {
        time_s: None,
        teammate_saw: teammate_ticks as f64 / limit.max(1) as f64,
        end,
    })
}

/// Mean and sample standard deviation, with misses counted at `limit`.
fn mean_std(times: &[Option<f64>], limit: f64) -> (f64, f64) {
    let xs: Vec<f64> = times.iter().map(|t| t.unwrap_or(limit)).collect();
    let n = xs.len().max(1) as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, var.sqrt())
}

/// One condition's summary.
#[derive(Debug, Clone)]
pub struct Summary {
    pub condition: Condition,
    pub mean_s: f64,
    pub std_s: f64,
    pub median_s: f64,
    pub found: usize,
    pub runs: usize,
    pub teammate_saw: f64,
}

/// The study: run `j` is condition `j / runs` with seed `seed + j % runs`, on `office`.
#[derive(Debug, Clone)]
pub struct Reacquire {
    pub cfg: ReacquireConfig,
    pub map: MapStamp,
}

impl Record for Outcome {
    fn write(&self, out: &mut Line) {
        self.time_s.write(out);
        self.teammate_saw.write(out);
        self.end.write(out);
    }
    fn read(input: &mut Fields) -> Result<Outcome, String> {
        Ok(Outcome {
            time_s: Record::read(input)?,
            teammate_saw: Record::read(input)?,
            end: Record::read(input)?,
        })
    }
}

impl Reacquire {
    /// Run `j` of the study on `arena` (office).
    pub fn run_one(&self, arena: &Arc<Arena>, j: usize) -> Result<Outcome, LabError> {
        let cfg = &self.cfg;
        let c = CONDITIONS
            .get(j / cfg.runs)
            .ok_or_else(|| LabError::Scenario(format!("run {j} is past the conditions")))?;
        one_run(arena.clone(), *c, cfg.seed + (j % cfg.runs) as u64, cfg)
    }
}

impl Study for Reacquire {
    const NAME: &'static str = "reacquire";
    const LABEL: &'static str = "reacquire runs";
    type Run = Outcome;
    type Report = Vec<Summary>;

    fn params(&self) -> Params {
        let c = &self.cfg;
        let mut p = Params::default();
        p.set("runs", c.runs);
        p.set("seed", c.seed);
        p.set("limit_s", c.limit_s);
        p.set("latency_ticks", c.latency_ticks);
        MapStamp::to_params(std::slice::from_ref(&self.map), &mut p);
        p
    }

    fn from_params(p: &Params) -> Result<Reacquire, String> {
        let [map] = <[MapStamp; 1]>::try_from(MapStamp::from_params(p)?)
            .map_err(|maps| format!("{} maps where the experiment runs on one", maps.len()))?;
        Ok(Reacquire {
            cfg: ReacquireConfig {
                runs: p.parse("runs")?,
                seed: p.parse("seed")?,
                limit_s: p.parse("limit_s")?,
                latency_ticks: p.parse("latency_ticks")?,
            },
            map,
        })
    }

    fn runs(&self) -> usize {
        CONDITIONS.len() * self.cfg.runs
    }

    /// Writes `reacquire.csv`, `reacquire_summary.csv` and `reacquire.svg` into `out`.
    fn write(&self, runs: Vec<Outcome>, out: &Path) -> Result<Vec<Summary>, LabError> {
        write(&self.cfg, runs, out)
    }
}

fn write(
    cfg: &ReacquireConfig,
    results: Vec<Outcome>,
    out: &Path,
) -> Result<Vec<Summary>, LabError> {
    let limit = cfg.limit_s as f64;
    let mut csv = String::from("condition,seed,end_x,end_y,found,time_s,teammate_saw_share\n");
    let mut summary_csv = String::from(
        "condition,shared,predicted,runs,found,mean_s,std_s,median_s,teammate_saw_share\n",
    );
    let mut summaries = Vec::new();
    for (k, c) in CONDITIONS.iter().enumerate() {
        let outcomes = &results[k * cfg.runs..(k + 1) * cfg.runs];
        for (i, o) in outcomes.iter().enumerate() {
            csv.push_str(&format!(
                "{},{},{:.2},{:.2},{},{},{:.3}\n",
                c.name,
                cfg.seed + i as u64,
                o.end.x,
                o.end.y,
                o.time_s.is_some(),
                o.time_s.map_or(String::new(), |t| format!("{t:.2}")),
                o.teammate_saw
            ));
        }
        let times: Vec<Option<f64>> = outcomes.iter().map(|o| o.time_s).collect();
        let (mean_s, std_s) = mean_std(&times, limit);
        let mut sorted: Vec<f64> = times.iter().map(|t| t.unwrap_or(limit)).collect();
        sorted.sort_by(f64::total_cmp);
        let median_s = match sorted.len() {
            0 => f64::NAN,
            n if n % 2 == 1 => sorted[n / 2],
            n => (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0,
        };
        let found = times.iter().filter(|t| t.is_some()).count();
        let teammate_saw =
            outcomes.iter().map(|o| o.teammate_saw).sum::<f64>() / outcomes.len().max(1) as f64;
        summary_csv.push_str(&format!(
            "{},{},{},{},{found},{mean_s:.2},{std_s:.2},{median_s:.2},{teammate_saw:.3}\n",
            c.name, c.shared, c.predicted, cfg.runs
        ));
        summaries.push(Summary {
            condition: *c,
            mean_s,
            std_s,
            median_s,
            found,
            runs: cfg.runs,
            teammate_saw,
        });
    }
    let write = |name: &str, text: &str| {
        let p = out.join(name);
        crate::error::write(&p, text)
    };
    write("reacquire.csv", &csv)?;
    write("reacquire_summary.csv", &summary_csv)?;
    let bars: Vec<plot::Bar> = summaries
        .iter()
        .map(|s| plot::Bar {
            name: s.condition.label,
            value: s.mean_s,
            error: s.std_s,
        })
        .collect();
    plot::bars(
        &out.join("reacquire.svg"),
        &format!(
            "Time to see the opponent again ({} runs each, mean ± std)",
            cfg.runs
        ),
        "seconds",
        &bars,
    )?;
    Ok(summaries)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn misses_count_at_the_limit_in_the_mean() {
        let (mean, std) = mean_std(&[Some(2.0), Some(4.0), None], 6.0);
        assert!((mean - 4.0).abs() < 1e-9);
        assert!((std - 2.0).abs() < 1e-9);
    }
}
