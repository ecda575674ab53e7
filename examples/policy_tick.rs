//! A match driven by a trained policy against its admission price: the learned preset (2
//! robots, `policy:learned`) against one `wander` bot and one `evade` bot on every shipped
//! map, each tick timed as the match task runs it (the policy's orders, then `World::step`),
//! beside the price `POST /api/matches` charges it (`admission::match_on` + `admission::policy`,
//! with the inference timed as the server times it when it loads the policy).
//!
//! ```sh
//! cargo run --release --example policy_tick                # 2 minutes of play a match
//! cargo run --release --example policy_tick -- --seconds 30
//! ```
//!
//! docs/performance.md, "Trained policies", has its figures.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use clap::Parser;
use lasertag::game::admission;
use lasertag::game::policies::time_inference;
use lasertag::maps::MapStore;
use lasertag_core::bots::BotKind;
use lasertag_core::difficulty::Difficulty;
use lasertag_core::world::{MatchConfig, MatchStatus, World, WorldInput};
use lasertag_policy::team::DEFAULT_EVERY;
use lasertag_policy::{Limits, Policy, TeamPolicy};

#[derive(Parser)]
struct Args {
    /// Seconds of play a match (the preset's limit is 120).
    #[arg(long, default_value_t = 120)]
    seconds: u64,
    /// The match's seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

fn percentile(sorted: &[f64], q: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

fn main() {
    let args = Args::parse();
    let store = MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps"))
        .expect("the shipped maps load");
    let policy = Arc::new(
        Policy::from_onnx(
            lasertag_policy::shipped("learned").expect("the shipped policy"),
            &Limits::default(),
        )
        .expect("the shipped policy loads"),
    );
    let inference_us = time_inference(&policy);
    println!(
        "policy learned: {} multiply-adds, one inference {inference_us:.1} µs (as the server times it)",
        policy.multiply_adds()
    );
    println!(
        "{:<10} {:<7} {:>6} {:>9} {:>9} {:>9} {:>9} {:>11} {:>9}",
        "map", "bot", "ticks", "mean ms", "p50 ms", "p99 ms", "max ms", "policy µs", "price ms"
    );
    for name in ["office", "warehouse", "hallway", "maze"] {
        let Some(map) = store.get(name) else { continue };
        for bot in [BotKind::Wander, BotKind::Evade] {
            let mut config = MatchConfig {
                opponent_bot: bot,
                seed: args.seed,
                ..MatchConfig::default()
            };
            Difficulty::Learned.apply(&mut config);
            config.time_limit_ticks = args.seconds * 20;
            let price = admission::match_on(&map.arena.def, &config)
                + admission::policy(&map.arena.def, &config, inference_us, DEFAULT_EVERY);
            let mut world = World::new(map.arena.clone(), config).expect("the match starts");
            let mut team = TeamPolicy::new(
                policy.clone(),
                &world.arena,
                world.robots.len(),
                &world.config.physics,
                DEFAULT_EVERY,
            )
            .expect("the policy fits the preset");
            let (mut ticks, mut policy_us) = (Vec::new(), 0.0);
            while world.status == MatchStatus::Running {
                let start = Instant::now();
                for (robot, order) in team.orders(&world) {
                    let _ = world.apply(&WorldInput::Robot { robot, order });
                }
                policy_us += start.elapsed().as_secs_f64() * 1e6;
                world.step();
                ticks.push(start.elapsed().as_secs_f64() * 1e3);
            }
            let n = ticks.len();
            let mean = ticks.iter().sum::<f64>() / n as f64;
            ticks.sort_by(f64::total_cmp);
            println!(
                "{:<10} {:<7} {:>6} {:>9.3} {:>9.3} {:>9.3} {:>9.3} {:>11.2} {:>9.3}",
                name,
                format!("{bot:?}").to_lowercase(),
                n,
                mean,
                percentile(&ticks, 0.5),
                percentile(&ticks, 0.99),
                ticks[n - 1],
                policy_us / n as f64,
                price.tick_ms
            );
        }
    }
}
