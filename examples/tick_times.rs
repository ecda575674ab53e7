//! Tick-duration percentiles of the functional core alone (no server, no sockets): seeded
//! `coordinated` matches against `evade` bots, every tick timed. The rare heavy ticks are
//! the planner's negotiation turns; this is where to see them.
//!
//! `cargo run --release --example tick_times -- [robots] [opponents] [map] [matches]
//! [radio latency ticks] [radio loss]` (defaults: 2 robots, 1 opponent, office, 10 matches of
//! up to 2 minutes, perfect radio; a latency or loss gives every robot its own tracker).

use std::path::Path;
use std::time::Instant;

use lasertag::maps::MapStore;
use lasertag_core::bots::BotKind;
use lasertag_core::planner::PlannerKind;
use lasertag_core::settings::Group;
use lasertag_core::world::World;
use lasertag_core::world::{MatchConfig, Placement};

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let num = |i: usize, default: usize| -> Result<usize, String> {
        args.get(i).map_or(Ok(default), |s| {
            s.parse().map_err(|_| format!("not a number: {s}"))
        })
    };
    let (robots, opponents) = (num(0, 2)?, num(1, 1)?);
    let map = args.get(2).map_or("office", String::as_str);
    let matches = num(3, 10)? as u64;
    let mut radio = lasertag_core::radio::Settings::default();
    for (name, i) in [("latency_ticks", 4), ("loss", 5)] {
        if let Some(text) = args.get(i) {
            radio.set_text(name, text).map_err(|e| e.to_string())?;
        }
    }
    let store = MapStore::load_dir(Path::new("maps")).map_err(|e| e.to_string())?;
    let arena = store
        .get(map)
        .ok_or_else(|| format!("no map {map:?}"))?
        .arena
        .clone();
    let mut times = Vec::new();
    for seed in 0..matches {
        let config = MatchConfig {
            robots,
            opponents,
            opponent_bot: BotKind::Evade,
            planner: PlannerKind::Coordinated,
            placement: Placement::Random,
            seed,
            radio: radio.clone(),
            ..MatchConfig::default()
        };
        let mut world = World::new(arena.clone(), config).map_err(|e| e.to_string())?;
        while world.tick < 2400 {
            let start = Instant::now();
            if !world.step() {
                break;
            }
            times.push(start.elapsed().as_secs_f64() * 1e3);
        }
    }
    times.sort_by(f64::total_cmp);
    let q = |p: f64| times[((times.len() - 1) as f64 * p) as usize];
    println!(
        "{map}, {robots} robots, {opponents} opponents, {} ticks: p50 {:.2} ms, p90 {:.2}, \
         p99 {:.2}, p99.9 {:.2}, max {:.2}",
        times.len(),
        q(0.5),
        q(0.9),
        q(0.99),
        q(0.999),
        q(1.0)
    );
    Ok(())
}
