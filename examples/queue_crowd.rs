//! The queue's matchmaking (`game::matchmaking`) against a simulated crowd: people arrive
//! at random over a span of minutes, each with a rating drawn as a leaderboard spreads them,
//! and the pool is asked for groups once a simulated second, as the queue's service asks it.
//! Reports each person's wait (p50, p95, max), people per match, the rating spread inside a
//! match, the share of matches bots filled and the robot presets chosen, for several crowd
//! sizes, against the goal of a wait p50 ≤ 10 s and p95 ≤ 30 s. docs/queue.md has the
//! figures and why the ratings are drawn as they are.
//!
//! ```sh
//! cargo run --release --example queue_crowd                        # 50, 200 and 500 people
//! cargo run --release --example queue_crowd -- --people 200 --gather 10 --out queue.csv
//! ```
//!
//! Arrivals: a Poisson process conditioned on its count, i.e. `--people` arrival times drawn
//! uniformly over `--minutes`. Ratings: a share `--newcomers` at exactly 1500 (names not yet
//! rated), the rest normal around `--rating-mean` with `--rating-sd`, clipped to 800..=2400.
//! Nobody leaves the queue before a match. Each crowd size is simulated `--runs` times from
//! seeds `--seed`, `--seed + 1`, …, and the figures pool every run.

use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

use clap::Parser;
use lasertag::game::matchmaking::{NEW_PLAYER_RATING, Pool, Rules, preset_for};
use lasertag_core::difficulty::Difficulty;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The lowest and highest rating drawn: a leaderboard's ends (docs/queue.md).
const RATING_RANGE: (f64, f64) = (800.0, 2400.0);

#[derive(Debug, Parser)]
#[command(about = "The queue's waits and matches for a simulated crowd")]
struct Args {
    /// Crowd sizes to simulate, each a row of the table (1..=100000 each).
    #[arg(long, value_delimiter = ',', default_value = "50,200,500")]
    people: Vec<usize>,
    /// Minutes over which the crowd arrives (0.1..=1440).
    #[arg(long, default_value_t = 10.0)]
    minutes: f64,
    /// Simulations of each crowd size, each from its own seed (1..=10000).
    #[arg(long, default_value_t = 100)]
    runs: u64,
    /// The first run's seed.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Share of the crowd that are newcomers, at exactly 1500 (0..=1).
    #[arg(long, default_value_t = 0.25)]
    newcomers: f64,
    /// Mean of the rated people's ratings.
    #[arg(long, default_value_t = 1500.0)]
    rating_mean: f64,
    /// Standard deviation of the rated people's ratings (0..=1000).
    #[arg(long, default_value_t = 300.0)]
    rating_sd: f64,
    /// Seconds a formable group that is not full waits to grow (default: the served rules').
    #[arg(long)]
    gather: Option<f64>,
    /// The window's half-width at joining (default: the served rules').
    #[arg(long)]
    window_start: Option<f64>,
    /// Points the window widens a second (default: the served rules').
    #[arg(long)]
    window_growth: Option<f64>,
    /// The window's widest half-width (default: the served rules').
    #[arg(long)]
    window_cap: Option<f64>,
    /// Write the table as CSV here too.
    #[arg(long)]
    out: Option<PathBuf>,
}

/// What one crowd size's runs measured, pooled.
#[derive(Debug, Default)]
struct Measured {
    /// Every person's wait, in seconds.
    waits: Vec<f64>,
    /// Matches by people in them (index 0: one person).
    by_size: Vec<usize>,
    /// Highest minus lowest rating, of every match with two people or more.
    spreads: Vec<f64>,
    filled_by_bots: usize,
    /// People in those matches.
    beside_bots: usize,
    presets: [usize; Difficulty::ALL.len()],
}

impl Measured {
    fn matches(&self) -> usize {
        self.by_size.iter().sum()
    }
}

fn main() -> Result<(), String> {
    let args = Args::parse();
    let rules = rules_of(&args)?;
    let header = [
        "people",
        "runs",
        "wait_p50_s",
        "wait_p95_s",
        "wait_max_s",
        "matches",
        "size_1",
        "size_2",
        "size_3",
        "size_4",
        "size_5",
        "people_per_match",
        "spread_p50",
        "spread_p95",
        "bots_share",
        "people_beside_bots",
        "recruit",
        "veteran",
        "elite",
        "learned",
        "goal_met",
    ];
    let mut rows = vec![header.join(",")];
    println!(
        "{:>6} {:>5} | {:>8} {:>8} {:>8} | {:>7} {:>29} {:>6} | {:>6} {:>6} | {:>5} {:>6} | {:>23} | goal",
        "people",
        "runs",
        "wait p50",
        "p95",
        "max",
        "matches",
        "people/match 1/2/3/4/5 (%)",
        "mean",
        "spread",
        "p95",
        "bots",
        "people",
        "recruit/veteran/elite/l",
    );
    for &people in &args.people {
        let mut measured = Measured {
            by_size: vec![0; rules.max_group],
            ..Measured::default()
        };
        for run in 0..args.runs {
            simulate(
                &args,
                rules,
                people,
                args.seed.wrapping_add(run),
                &mut measured,
            );
        }
        let row = Row::of(people, args.runs, &measured);
        println!("{}", row.table_line());
        rows.push(row.csv_line());
    }
    println!(
        "goal: wait p50 ≤ 10 s, p95 ≤ 30 s. Rules: {} to {} people, window ±{} + {}/s up to ±{}, \
         groups gathered up to {} s, nobody past {} s.",
        rules.min_group,
        rules.max_group,
        rules.window.start,
        rules.window.per_second,
        rules.window.cap,
        rules.gather.as_secs_f64(),
        rules.max_wait.as_secs_f64(),
    );
    if let Some(path) = &args.out {
        let mut file =
            std::fs::File::create(path).map_err(|e| format!("{}: {e}", path.display()))?;
        writeln!(file, "{}", rows.join("\n")).map_err(|e| format!("{}: {e}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// The served rules with the flags' changes, each flag checked.
fn rules_of(args: &Args) -> Result<Rules, String> {
    let in_range = |name: &str, value: f64, low: f64, high: f64| {
        if value.is_finite() && (low..=high).contains(&value) {
            Ok(value)
        } else {
            Err(format!("--{name} must be within {low}..={high}"))
        }
    };
    if args.people.is_empty() || args.people.iter().any(|&n| !(1..=100_000).contains(&n)) {
        return Err("--people: crowd sizes within 1..=100000".into());
    }
    if !(1..=10_000).contains(&args.runs) {
        return Err("--runs must be within 1..=10000".into());
    }
    in_range("minutes", args.minutes, 0.1, 1440.0)?;
    in_range("newcomers", args.newcomers, 0.0, 1.0)?;
    in_range(
        "rating-mean",
        args.rating_mean,
        RATING_RANGE.0,
        RATING_RANGE.1,
    )?;
    in_range("rating-sd", args.rating_sd, 0.0, 1000.0)?;
    let mut rules = Rules::default();
    if let Some(gather) = args.gather {
        rules.gather = Duration::from_secs_f64(in_range("gather", gather, 0.0, 60.0)?);
    }
    if let Some(start) = args.window_start {
        rules.window.start = in_range("window-start", start, 0.0, 2000.0)?;
    }
    if let Some(growth) = args.window_growth {
        rules.window.per_second = in_range("window-growth", growth, 0.0, 1000.0)?;
    }
    if let Some(cap) = args.window_cap {
        rules.window.cap = in_range("window-cap", cap, 0.0, 2000.0)?;
    }
    Ok(rules)
}

/// One crowd of `people`, from `seed`: arrivals and ratings drawn, then the pool asked for
/// groups every simulated second until everyone has played.
fn simulate(args: &Args, rules: Rules, people: usize, seed: u64, measured: &mut Measured) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let span = args.minutes * 60.0;
    let mut arrivals: Vec<f64> = (0..people).map(|_| rng.random_range(0.0..span)).collect();
    arrivals.sort_by(f64::total_cmp);
    let ratings: Vec<f64> = (0..people)
        .map(|_| {
            if rng.random::<f64>() < args.newcomers {
                NEW_PLAYER_RATING
            } else {
                let drawn = lasertag_core::sim::gaussian(&mut rng, args.rating_sd as f32);
                (args.rating_mean + f64::from(drawn)).clamp(RATING_RANGE.0, RATING_RANGE.1)
            }
        })
        .collect();
    let mut pool = Pool::new(rules);
    let mut next = 0;
    let step = rules.call_every.as_secs_f64();
    // Everyone has arrived by `span` and played by `max_wait` later; the bound only guards
    // against rules that would keep someone forever.
    let last = ((span + rules.max_wait.as_secs_f64()) / step).ceil() as u64 + 2;
    for call in 0..=last {
        let now = call as f64 * step;
        while next < people && arrivals[next] <= now {
            pool.join(
                next as u64,
                ratings[next],
                Duration::from_secs_f64(arrivals[next]),
            );
            next += 1;
        }
        for group in pool.form(Duration::from_secs_f64(now)) {
            for &member in &group.members {
                measured.waits.push(now - arrivals[member as usize]);
            }
            let size = group.members.len();
            if let Some(count) = measured.by_size.get_mut(size - 1) {
                *count += 1;
            }
            if size >= 2 {
                measured.spreads.push(group.spread);
            }
            if group.filled_by_bots > 0 {
                measured.filled_by_bots += 1;
                measured.beside_bots += size;
            }
            let preset = preset_for(group.mean_rating);
            if let Some(i) = Difficulty::ALL.iter().position(|&d| d == preset) {
                measured.presets[i] += 1;
            }
        }
        if next == people && pool.waiting() == 0 {
            break;
        }
    }
}

/// One line of the table.
struct Row {
    people: usize,
    runs: u64,
    waits: [f64; 3],
    matches: usize,
    /// Share of matches by people in them, in percent.
    by_size: Vec<f64>,
    people_per_match: f64,
    spreads: [f64; 2],
    bots_share: f64,
    /// Share of people who played beside bots, in percent.
    beside_bots: f64,
    presets: Vec<f64>,
}

impl Row {
    fn of(people: usize, runs: u64, m: &Measured) -> Row {
        let matches = m.matches().max(1) as f64;
        let share = |n: usize| 100.0 * n as f64 / matches;
        Row {
            people,
            runs,
            waits: [
                percentile(&m.waits, 0.5),
                percentile(&m.waits, 0.95),
                percentile(&m.waits, 1.0),
            ],
            matches: m.matches(),
            by_size: m.by_size.iter().map(|&n| share(n)).collect(),
            people_per_match: m.waits.len() as f64 / matches,
            spreads: [percentile(&m.spreads, 0.5), percentile(&m.spreads, 0.95)],
            bots_share: share(m.filled_by_bots),
            beside_bots: 100.0 * m.beside_bots as f64 / m.waits.len().max(1) as f64,
            presets: m.presets.iter().map(|&n| share(n)).collect(),
        }
    }

    fn goal_met(&self) -> bool {
        self.waits[0] <= 10.0 && self.waits[1] <= 30.0
    }

    fn table_line(&self) -> String {
        let join = |values: &[f64]| {
            values
                .iter()
                .map(|v| format!("{v:.0}"))
                .collect::<Vec<_>>()
                .join("/")
        };
        format!(
            "{:>6} {:>5} | {:>7.1}s {:>7.1}s {:>7.1}s | {:>7} {:>29} {:>6.2} | {:>6.0} {:>6.0} | {:>4.0}% {:>5.1}% | {:>23} | {}",
            self.people,
            self.runs,
            self.waits[0],
            self.waits[1],
            self.waits[2],
            self.matches,
            join(&self.by_size),
            self.people_per_match,
            self.spreads[0],
            self.spreads[1],
            self.bots_share,
            self.beside_bots,
            join(&self.presets),
            if self.goal_met() { "met" } else { "missed" },
        )
    }

    fn csv_line(&self) -> String {
        let mut fields = vec![
            self.people.to_string(),
            self.runs.to_string(),
            format!("{:.2}", self.waits[0]),
            format!("{:.2}", self.waits[1]),
            format!("{:.2}", self.waits[2]),
            self.matches.to_string(),
        ];
        fields.extend(self.by_size.iter().map(|v| format!("{v:.2}")));
        fields.push(format!("{:.3}", self.people_per_match));
        fields.push(format!("{:.1}", self.spreads[0]));
        fields.push(format!("{:.1}", self.spreads[1]));
        fields.push(format!("{:.2}", self.bots_share));
        fields.push(format!("{:.2}", self.beside_bots));
        fields.extend(self.presets.iter().map(|v| format!("{v:.2}")));
        fields.push(self.goal_met().to_string());
        fields.join(",")
    }
}

/// The nearest-rank percentile `p` (0..=1) of `values`; 0 for none.
fn percentile(values: &[f64], p: f64) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    let rank = (p * sorted.len() as f64).ceil() as usize;
    sorted
        .get(rank.clamp(1, sorted.len().max(1)) - 1)
        .copied()
        .unwrap_or(0.0)
}
