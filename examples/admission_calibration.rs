//! What admission charges a match for its ticks against what its ticks cost: for every shipped
//! map and a spread of settings, the price (`game::admission::match_on`, milliseconds a tick)
//! beside the measured mean and p99 tick of seeded matches run in this process (the core
//! alone: `World::step`, one thread, nothing else running). The settings are
//! `admission::calibration_settings`.
//!
//! ```sh
//! cargo run --release --example admission_calibration                 # every map, every setting
//! cargo run --release --example admission_calibration -- --out docs/results/admission_calibration.csv
//! ```
//!
//! Each row: 3 seeds (`--seeds`) of up to 60 s of match (`--ticks`), every tick timed. The
//! ratio columns say how far the price is from each measure. The CSV is what
//! `tests/admission_calibration.rs` holds the price function against.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use lasertag::game::admission;
use lasertag::maps::MapStore;
use lasertag_core::world::{MatchConfig, World};

#[derive(Debug, Parser)]
#[command(about = "Admission's tick price against measured tick times, per map and setting")]
struct Args {
    /// Seeds per map and setting (1..=50).
    #[arg(long, default_value_t = 3)]
    seeds: u64,
    /// Ticks per match at most (20..=12000).
    #[arg(long, default_value_t = 1200)]
    ticks: u64,
    /// Directory of map files.
    #[arg(long, default_value = "maps")]
    maps: PathBuf,
    /// Write the table as CSV here too.
    #[arg(long)]
    out: Option<PathBuf>,
}

fn main() -> Result<(), String> {
    let args = Args::parse();
    if !(1..=50).contains(&args.seeds) || !(20..=12_000).contains(&args.ticks) {
        return Err("--seeds 1..=50, --ticks 20..=12000".into());
    }
    let store = MapStore::load_dir(&args.maps).map_err(|e| format!("loading maps: {e}"))?;
    let mut names: Vec<String> = store.iter().map(|m| m.arena.def.name.clone()).collect();
    names.sort();
    let mut rows = vec![
        "map,setting,robots,opponents,particles_per_role,radio_perfect,planner,priced_ms,mean_ms,p99_ms,max_ms,ticks"
            .to_string(),
    ];
    println!(
        "{:<10} {:<18} {:>9} {:>9} {:>9} {:>9} {:>11} {:>10}",
        "map", "setting", "priced", "mean", "p99", "max", "priced/p99", "ticks"
    );
    for name in &names {
        let Some(map) = store.get(name) else { continue };
        let arena = map.arena.clone();
        for (setting, config) in admission::calibration_settings() {
            let priced = admission::match_on(&arena.def, &config).tick_ms;
            let mut times = Vec::new();
            for seed in 0..args.seeds {
                let config = MatchConfig {
                    seed,
                    ..config.clone()
                };
                let mut world =
                    World::new(arena.clone(), config).map_err(|e| format!("{name}: {e}"))?;
                while world.tick < args.ticks {
                    let start = Instant::now();
                    if !world.step() {
                        break;
                    }
                    times.push(start.elapsed().as_secs_f64() * 1e3);
                }
            }
            times.sort_by(f64::total_cmp);
            let q = |p: f64| times[((times.len() - 1) as f64 * p) as usize];
            let mean = times.iter().sum::<f64>() / times.len() as f64;
            let (p99, max) = (q(0.99), q(1.0));
            println!(
                "{name:<10} {setting:<18} {priced:>6.2} ms {mean:>6.2} ms {p99:>6.2} ms {max:>6.2} ms {:>11.2} {:>10}",
                priced / p99,
                times.len()
            );
            rows.push(format!(
                "{name},{setting},{},{},{},{},{},{priced:.4},{mean:.4},{p99:.4},{max:.4},{}",
                config.robots,
                config.opponents,
                config.tracker.particles_per_role,
                config.radio.perfect(),
                config.planner.name(),
                times.len()
            ));
        }
    }
    if let Some(out) = &args.out {
        let mut f = std::fs::File::create(out).map_err(|e| format!("{}: {e}", out.display()))?;
        for row in &rows {
            writeln!(f, "{row}").map_err(|e| e.to_string())?;
        }
        println!("wrote {}", out.display());
    }
    Ok(())
}
