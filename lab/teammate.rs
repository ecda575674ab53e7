//! A person on the robot team, measured: how soon one planned robot and one person-like
//! pursuer tag the opponent, against two planned robots, and whether the coordinated
//! planner's accounting for a teammate it cannot command (its claim, see
//! `planner::coordinated`) shortens the hunt.
//!
//! The person is scripted ([`Person`]): robot r1 driven from outside, seeing what a person on
//! the team sees — its own laser's detections and the team's belief — and told nothing of the
//! planner's choices. It chases what it sees, firing when the opponent is in its tag cone,
//! and otherwise walks to where the belief is densest for the distance, choosing again when
//! it gets there or after 10 s: the greedy route a person follows.
//!
//! For each map and bot it runs `runs` seeded matches per team from random starts (run `i`
//! of every team uses the same seed, so the same starts), and writes every capture time, a
//! summary (median, mean with its 95% interval, capture within the limit, the median's ratio
//! to two coordinated robots' and a Mann–Whitney U test against them, and the accounting's
//! effect) and one plot per map and bot: the share of runs that have tagged by each time.

use std::path::Path;
use std::sync::Arc;

use nalgebra::Point2;

use crate::capture::{bot_name, mann_whitney_p, stats};
use crate::error::LabError;
use crate::part::Params;
use crate::plot::{self, Series};
use crate::study::{MapStamp, Study};
use lasertag_core::bots::BotKind;
use lasertag_core::planner::PlannerKind;
use lasertag_core::planner::coordinated;
use lasertag_core::sim::TICK_HZ;
use lasertag_core::sim::arena::Arena;
use lasertag_core::world::{MatchConfig, MatchStatus, Placement, RobotOrder, Side, World};

const BOTS: [BotKind; 2] = [BotKind::Wander, BotKind::Evade];

/// A team of two robots.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Team {
    /// Both planned by `planner`.
    Two(PlannerKind),
    /// r0 planned by `planner`, r1 the scripted person; `claims`: whether the planner
    /// accounts for the person (the coordinated planner's `outside_claims`).
    WithPerson { planner: PlannerKind, claims: bool },
}

/// The teams, in the table's order: the first is what the others are compared with.
const TEAMS: [(&str, Team); 5] = [
    ("coordinated x2", Team::Two(PlannerKind::Coordinated)),
    (
        "coordinated + person",
        Team::WithPerson {
            planner: PlannerKind::Coordinated,
            claims: true,
        },
    ),
    (
        "coordinated + person (unaccounted)",
        Team::WithPerson {
            planner: PlannerKind::Coordinated,
            claims: false,
        },
    ),
    (
        "baseline + person",
        Team::WithPerson {
            planner: PlannerKind::Baseline,
            claims: true,
        },
    ),
    ("baseline x2", Team::Two(PlannerKind::Baseline)),
];

/// Side of the cells the person bins the belief into to find where it is densest (m).
const PERSON_CELL_M: f32 = 2.0;
/// Metres at which a cell's hypotheses count for half: how much the person prefers near.
const PERSON_NEAR_M: f32 = 5.0;
/// Ticks before the person chooses again on the way (10 s).
const PERSON_RECHOOSE_TICKS: u64 = 10 * TICK_HZ as u64;

/// The scripted person driving robot `robot` (see the module docs).
#[derive(Debug, Clone, Default)]
struct Person {
    target: Option<Point2<f32>>,
    chose_at: u64,
    chasing: bool,
}

impl Person {
    /// Its order for the next tick, if it changes anything.
    fn decide(&mut self, world: &World, robot: usize) -> Option<RobotOrder> {
        let o = world.observation(robot)?;
        if o.frozen {
            return None;
        }
        let physics = &world.config.physics;
        if let Some(d) = o
            .detections
            .iter()
            .min_by(|a, b| a.range.total_cmp(&b.range))
        {
            // Turn towards it, close in while facing it, fire once it is in the cone.
            self.chasing = true;
            self.target = None;
            let aim = d.bearing.abs() <= physics.tag_half_angle && d.range <= physics.tag_range;
            return Some(RobotOrder::Drive {
                forward: if d.bearing.abs() < 0.5 { 1.0 } else { 0.2 },
                turn: (2.0 * d.bearing).clamp(-1.0, 1.0),
                tag: aim && o.tag_ready,
            });
        }
        let here = o.estimate.pos;
        let arrived = self.target.is_some_and(|t| (t - here).norm() < 1.0);
        let stale = world.tick >= self.chose_at + PERSON_RECHOOSE_TICKS;
        if !(self.chasing || self.target.is_none() || arrived || stale) {
            return None;
        }
        self.chasing = false;
        self.chose_at = world.tick;
        let target = densest_near(world, here)?;
        self.target = Some(target);
        Some(RobotOrder::Waypoints(vec![target]))
    }
}

/// Where the team's belief holds the most hypotheses for the distance from `here`: one
/// particle of the best cell (particles lie in free space, so a route reaches it).
fn densest_near(world: &World, here: Point2<f32>) -> Option<Point2<f32>> {
    let (w, h) = (world.arena.width(), world.arena.height());
    let cols = (w / PERSON_CELL_M).ceil().max(1.0) as usize;
    let rows = (h / PERSON_CELL_M).ceil().max(1.0) as usize;
    let mut mass = vec![0.0f32; cols * rows];
    let mut example: Vec<Option<Point2<f32>>> = vec![None; cols * rows];
    for role in world
        .team
        .merged_belief()
        .iter()
        .filter(|r| !r.tagged && r.count > 0)
    {
        for (p, wgt) in role.particles().iter().zip(role.weights()) {
            let c = ((p.x / PERSON_CELL_M) as usize).min(cols - 1);
            let r = ((p.y / PERSON_CELL_M) as usize).min(rows - 1);
            mass[r * cols + c] += wgt * role.count as f32;
            example[r * cols + c].get_or_insert(*p);
        }
    }
    (0..mass.len())
        .filter_map(|k| example[k].map(|p| (p, mass[k])))
        .map(|(p, m)| (p, m / (1.0 + (p - here).norm() / PERSON_NEAR_M)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(p, _)| p)
}

/// One setting of the study.
#[derive(Debug, Clone, Copy)]
struct Setting {
    map: usize,
    bot: BotKind,
    team: usize,
}

/// The study: `runs` matches per map, bot and team. Run `j` is setting `j / runs` (map,
/// then bot, then team) with seed `seed + j % runs`.
#[derive(Debug, Clone)]
pub struct TeammateStudy {
    pub runs: usize,
    pub seed: u64,
    pub time_limit_s: u64,
    pub maps: Vec<MapStamp>,
}

/// Seconds until the opponent was tagged; `None` when not within the limit.
pub type Run = Option<f64>;

impl TeammateStudy {
    fn settings(&self) -> Vec<Setting> {
        let mut settings = Vec::new();
        for map in 0..self.maps.len() {
            for bot in BOTS {
                for team in 0..TEAMS.len() {
                    settings.push(Setting { map, bot, team });
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
        let (planner, person, claims) = match TEAMS[s.team].1 {
            Team::Two(p) => (p, false, true),
            Team::WithPerson { planner, claims } => (planner, true, claims),
        };
        let config = MatchConfig {
            robots: 2,
            opponents: 1,
            opponent_bot: s.bot,
            planner,
            outside_robots: if person {
                vec![false, true]
            } else {
                Vec::new()
            },
            placement: Placement::Random,
            seed: self.seed + (j % self.runs) as u64,
            time_limit_ticks: self.time_limit_s * TICK_HZ as u64,
            coordination: coordinated::Settings {
                outside_claims: claims,
                ..coordinated::Settings::default()
            },
            ..MatchConfig::default()
        };
        let mut world = World::new(arena.clone(), config)?;
        let mut scripted = Person::default();
        while world.status == MatchStatus::Running {
            if person && let Some(order) = scripted.decide(&world, 1) {
                // A target the path search cannot reach is dropped: the next tick chooses
                // again (as a person gives up on a place they cannot get to).
                if world.order_robot(1, order).is_err() {
                    scripted.target = None;
                }
            }
            world.step();
        }
        Ok((world.winner == Some(Side::Robots)).then(|| world.time_s()))
    }
}

impl Study for TeammateStudy {
    const NAME: &'static str = "teammate";
    const LABEL: &'static str = "teammate runs";
    type Run = Run;
    /// The summary table.
    type Report = String;

    fn params(&self) -> Params {
        let mut p = Params::default();
        p.set("runs", self.runs);
        p.set("seed", self.seed);
        p.set("time_limit_s", self.time_limit_s);
        MapStamp::to_params(&self.maps, &mut p);
        p
    }

    fn from_params(p: &Params) -> Result<TeammateStudy, String> {
        Ok(TeammateStudy {
            runs: p.parse("runs")?,
            seed: p.parse("seed")?,
            time_limit_s: p.parse("time_limit_s")?,
            maps: MapStamp::from_params(p)?,
        })
    }

    fn runs(&self) -> usize {
        self.settings().len() * self.runs
    }

    fn write(&self, runs: Vec<Run>, out: &Path) -> Result<String, LabError> {
        let limit = self.time_limit_s as f64;
        let mut csv = String::from("map,bot,team,seed,captured,time_s\n");
        let mut summary = String::from(
            "map,bot,team,runs,captured,median_s,mean_s,mean_ci95_low,mean_ci95_high,ratio_to_coordinated_x2,p_vs_coordinated_x2\n",
        );
        let mut table = format!(
            "{:<10} {:<7} {:<36} {:>9} {:>9} {:>17} {:>6} {:>8}\n",
            "map", "bot", "team", "captured", "median", "mean (95% CI)", "ratio", "p"
        );
        let settings = self.settings();
        let times_of = |k: usize| &runs[k * self.runs..(k + 1) * self.runs];
        for m in 0..self.maps.len() {
            let map = &self.maps[m].name;
            for bot in BOTS {
                let base = settings
                    .iter()
                    .position(|s| s.map == m && s.bot == bot)
                    .ok_or_else(|| LabError::Scenario("no setting for a map and bot".into()))?;
                let reference: Vec<f64> =
                    times_of(base).iter().map(|t| t.unwrap_or(limit)).collect();
                let (ref_median, ..) = stats(times_of(base), limit);
                let mut series = Vec::new();
                for (t, (name, _)) in TEAMS.iter().enumerate() {
                    let k = base + t;
                    let times = times_of(k);
                    for (i, v) in times.iter().enumerate() {
                        csv.push_str(&format!(
                            "{map},{},{name},{},{},{}\n",
                            bot_name(bot),
                            self.seed + i as u64,
                            v.is_some(),
                            v.map_or(String::new(), |v| format!("{v:.2}"))
                        ));
                    }
                    let (median, mean, lo, hi) = stats(times, limit);
                    let captured = times.iter().flatten().count();
                    let xs: Vec<f64> = times.iter().map(|v| v.unwrap_or(limit)).collect();
                    let p = if t == 0 {
                        f64::NAN
                    } else {
                        mann_whitney_p(&xs, &reference)
                    };
                    let ratio = median / ref_median;
                    summary.push_str(&format!(
                        "{map},{},{name},{},{captured},{median:.2},{mean:.2},{lo:.2},{hi:.2},{ratio:.3},{p:.4}\n",
                        bot_name(bot),
                        self.runs
                    ));
                    table.push_str(&format!(
                        "{map:<10} {:<7} {name:<36} {:>5}/{:<3} {:>8.1}s {:>5.1} [{:>4.1}, {:>4.1}] {:>6.2} {:>8}\n",
                        bot_name(bot),
                        captured,
                        self.runs,
                        median,
                        mean,
                        lo,
                        hi,
                        ratio,
                        if t == 0 { "—".to_string() } else { format!("{p:.3}") }
                    ));
                    let mut won: Vec<f64> = times.iter().flatten().copied().collect();
                    won.sort_by(f64::total_cmp);
                    let points = (0..=self.time_limit_s)
                        .map(|s| {
                            let n = won.partition_point(|v| *v <= s as f64);
                            (s as f64, n as f64 / self.runs as f64)
                        })
                        .collect();
                    series.push(Series { name, points });
                }
                // The accounting's own test: the same person, accounted for or not.
                let with = times_of(base + 1)
                    .iter()
                    .map(|t| t.unwrap_or(limit))
                    .collect::<Vec<_>>();
                let without = times_of(base + 2)
                    .iter()
                    .map(|t| t.unwrap_or(limit))
                    .collect::<Vec<_>>();
                let (m_with, ..) = stats(times_of(base + 1), limit);
                let (m_without, ..) = stats(times_of(base + 2), limit);
                table.push_str(&format!(
                    "{map:<10} {:<7} accounting for the person: median {m_with:.1}s against {m_without:.1}s not accounted (ratio {:.2}, p {:.3})\n",
                    bot_name(bot),
                    m_with / m_without,
                    mann_whitney_p(&with, &without)
                ));
                plot::lines(
                    &out.join(format!("teammate_{map}_{}.svg", bot_name(bot))),
                    &format!(
                        "Tagged by time, each team: {map} vs {} bot ({} runs)",
                        bot_name(bot),
                        self.runs
                    ),
                    "time (s)",
                    "share of runs that have tagged the opponent",
                    &series,
                )?;
            }
        }
        crate::error::write(&out.join("teammate.csv"), &csv)?;
        crate::error::write(&out.join("teammate_summary.csv"), &summary)?;
        Ok(table)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 14 m × 8 m room with a pillar in the middle.
    fn room() -> Arc<Arena> {
        use lasertag_core::sim::arena::MapDef;
        Arc::new(Arena::new(MapDef {
            name: "room".into(),
            width: 14.0,
            height: 8.0,
            obstacles: vec![vec![
                Point2::new(6.5, 3.5),
                Point2::new(7.5, 3.5),
                Point2::new(7.5, 4.5),
                Point2::new(6.5, 4.5),
            ]],
            robot_spawns: vec![[1.0, 4.0, 0.0], [1.0, 2.0, 0.0]],
            opponent_spawns: vec![Point2::new(13.0, 7.0)],
            landmarks: vec![Point2::new(7.0, 1.0)],
        }))
    }

    /// The scripted person moves (by its orders, which are valid), and the team with it
    /// tags the wandering bot.
    #[test]
    fn the_person_walks_the_belief_and_its_team_tags() {
        let arenas = vec![room()];
        let study = TeammateStudy {
            runs: 2,
            seed: 11,
            time_limit_s: 300,
            maps: MapStamp::all(&arenas),
        };
        // Setting 1 is office, wander, coordinated + person.
        let captured = (0..2)
            .filter_map(|i| study.run_one(&arenas, 2 + i).expect("runs"))
            .count();
        assert!(
            captured >= 1,
            "the team with the person tagged in neither run"
        );
        let config = MatchConfig {
            robots: 2,
            opponents: 1,
            outside_robots: vec![false, true],
            placement: Placement::Random,
            seed: 11,
            ..MatchConfig::default()
        };
        let mut world = World::new(arenas[0].clone(), config).expect("valid");
        let start = world.robots[1].pose.pos;
        let mut person = Person::default();
        for _ in 0..200 {
            if let Some(order) = person.decide(&world, 1) {
                world
                    .order_robot(1, order)
                    .expect("the person's orders are valid");
            }
            world.step();
        }
        // In this open room it sees the bot at once and closes in (the match may be over
        // within a second).
        assert!(
            (world.robots[1].pose.pos - start).norm() > 0.3,
            "the person stood still"
        );
    }
}
