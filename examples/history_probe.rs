//! What the history costs and how fast it answers, from the library alone (no sockets):
//!
//! 1. a 10-minute office match with a person's keys changing a few times a second (and one
//!    with a robot command every tick, the heaviest research use) played tick by tick, with
//!    and without the recording's work on the tick path (noting each input, handing the
//!    unstored ones over every second): the cost per tick;
//! 2. the bytes each stores per match-minute (settings and deflated inputs, as the database
//!    holds them);
//! 3. seeks to random ticks of the 10-minute match: preparing it (what a first opening
//!    starts in the background: the whole match re-simulated, its keyframes kept) and the
//!    p50/p95/max of the seeks after;
//! 4. the database under retention: `--matches` short matches written through a real store
//!    with `--keep-mb`, and the file's size after.
//!
//! `cargo run --release --example history_probe -- [--minutes 10] [--seeks 200]
//! [--matches 2000] [--keep-mb 2]`

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use lasertag::game::record::Recording;
use lasertag::game::replay::Replay;
use lasertag::game::view::{Clock, MatchMeta};
use lasertag::maps::MapStore;
use lasertag::store::codec::StoredClock;
use lasertag::store::codec::{StoredSettings, encode_inputs};
use lasertag::store::{Ended, Retention, Store, Write};
use lasertag_core::planner::PlannerKind;
use lasertag_core::world::{ControlKind, HumanInput, MatchConfig, RobotOrder, World, WorldInput};
use rand::{RngExt, SeedableRng};

fn flag(name: &str, default: u64) -> u64 {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

/// What one played match gives back.
struct Played {
    world: World,
    inputs: Vec<(u64, WorldInput)>,
    /// Mean µs of a tick's step alone, and of the recording's work per tick.
    step_us: f64,
    record_us: f64,
}

/// `ticks` of a match on `arena`, its inputs from `input_at` (tick → an input or none).
fn play(
    arena: Arc<lasertag_core::sim::arena::Arena>,
    config: MatchConfig,
    ticks: u64,
    mut input_at: impl FnMut(u64) -> Option<WorldInput>,
) -> Played {
    let mut world = World::new(arena, config).expect("world");
    let mut recording = Recording::new(false);
    let (mut step, mut record) = (Duration::ZERO, Duration::ZERO);
    let mut handed = Vec::new();
    for t in 0..ticks {
        if let Some(input) = input_at(t) {
            let _ = world.apply(&input);
            let r = Instant::now();
            recording.note(&world, input);
            record += r.elapsed();
        }
        let s = Instant::now();
        world.step();
        step += s.elapsed();
        // Once a second the task hands the unstored inputs to the store's queue.
        if t % 20 == 19 {
            let r = Instant::now();
            let unstored = recording.unstored().to_vec();
            let n = unstored.len();
            handed.push(unstored);
            recording.mark_stored(n);
            record += r.elapsed();
        }
    }
    Played {
        world,
        inputs: recording.inputs().unwrap_or_default().to_vec(),
        step_us: step.as_secs_f64() * 1e6 / ticks as f64,
        record_us: record.as_secs_f64() * 1e6 / ticks as f64,
    }
}

fn meta(id: &str) -> MatchMeta {
    MatchMeta {
        id: id.into(),
        map: "office".into(),
        clock: Clock::Manual,
        players: 0,
        spectators: 0,
        free_slots: 0,
        free_pursuer_slots: 0,
        bots_joinable: false,
        spectator_delay_ticks: 0,
        head_start_ticks: 0,
        difficulty: None,
        rated: false,
    }
}

fn main() {
    let minutes = flag("--minutes", 10);
    let seeks = flag("--seeks", 200) as usize;
    let matches = flag("--matches", 2000);
    let keep_mb = flag("--keep-mb", 2);
    let ticks = minutes * 60 * 20;
    let maps = MapStore::load_dir(Path::new("maps")).expect("run from the repository");
    let arena = maps.get("office").expect("office").arena.clone();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);

    // A person: keys change about three times a second, a shot now and then.
    let mut person = MatchConfig {
        opponent_control: ControlKind::Human,
        opponents: 1,
        seed: 1,
        time_limit_ticks: ticks + 1,
        ..MatchConfig::default()
    };
    // The robots cannot tag, so the match lasts its whole length (it is the length of the
    // replay that matters to a seek, not who wins).
    person.physics.tag_range = 0.01;
    let mut seat = true;
    let played = play(arena.clone(), person.clone(), ticks, |t| {
        if std::mem::take(&mut seat) {
            return Some(WorldInput::Seat {
                slot: 0,
                name: "probe".into(),
            });
        }
        (rng.random_range(0..7) == 0).then(|| WorldInput::Keys {
            slot: 0,
            input: lasertag::game::record::normalised(HumanInput {
                forward: rng.random_range(-1..=1) as f32,
                turn: rng.random_range(-1..=1) as f32,
                tag: rng.random_bool(0.05),
                seen_tick: Some(t.saturating_sub(3)),
            }),
        })
    });
    let settings = serde_json::to_string(&StoredSettings::of(
        &person,
        StoredClock::Realtime,
        false,
        600,
        None,
        false,
    ))
    .expect("settings");
    let stored = settings.len()
        + played
            .inputs
            .chunks(60)
            .map(|c| encode_inputs(c).len())
            .sum::<usize>();
    println!(
        "a person's {minutes}-minute match ({} inputs):",
        played.inputs.len()
    );
    println!(
        "  tick {:.1} µs, recording {:.3} µs per tick ({:.3} %)",
        played.step_us,
        played.record_us,
        100.0 * played.record_us / played.step_us
    );
    println!(
        "  stored {stored} B: {:.1} KB per match-minute",
        stored as f64 / 1000.0 / minutes as f64
    );

    // A researcher's robots: a drive command for each robot every tick.
    let api = MatchConfig {
        planner: PlannerKind::Api,
        seed: 2,
        time_limit_ticks: ticks + 1,
        ..MatchConfig::default()
    };
    let api_ticks = 60 * 20;
    let mut k = 0u64;
    let api_played = play(arena.clone(), api, api_ticks, |_| {
        k += 1;
        Some(WorldInput::Robot {
            robot: (k % 2) as usize,
            order: RobotOrder::Drive {
                forward: (k % 7) as f32 / 7.0,
                turn: -((k % 5) as f32) / 5.0,
                tag: k.is_multiple_of(40),
            },
        })
    });
    let api_bytes: usize = api_played
        .inputs
        .chunks(20)
        .map(|c| encode_inputs(c).len())
        .sum();
    println!(
        "robots driven from outside, one command a tick for a minute: tick {:.1} µs, recording {:.3} µs ({:.3} %), {:.1} KB per match-minute",
        api_played.step_us,
        api_played.record_us,
        100.0 * api_played.record_us / api_played.step_us,
        api_bytes as f64 / 1000.0
    );

    // Seeks.
    let replay = Replay::of(
        &played.world,
        meta("probe"),
        arena.clone(),
        person,
        played.inputs.clone(),
        SystemTime::now(),
    );
    // What the first opening starts in the background: the whole match once, keyframes kept.
    let first = Instant::now();
    replay.prepare();
    let first = first.elapsed();
    let mut times: Vec<f64> = (0..seeks)
        .map(|_| {
            let t = rng.random_range(0..=replay.last_tick);
            let s = Instant::now();
            replay.world_at(t).expect("seek");
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    println!(
        "seeks in the {minutes}-minute match: preparing it (the first opening, in the background) {:.0} ms; then p50 {:.1} ms, p95 {:.1} ms, max {:.1} ms ({seeks} random ticks)",
        first.as_secs_f64() * 1e3,
        percentile(&times, 0.5),
        percentile(&times, 0.95),
        percentile(&times, 1.0)
    );

    // Retention through a real store.
    let dir = std::env::temp_dir().join(format!("lasertag-history-probe-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let store = Store::open(
        &dir,
        Retention {
            max_matches: 1_000_000,
            max_bytes: keep_mb << 20,
        },
    )
    .expect("store");
    let chunk: Vec<_> = played.inputs.iter().take(200).cloned().collect();
    let mut most = 0;
    for i in 0..matches {
        let id = format!("m{i}");
        let settings = StoredSettings::of(
            &MatchConfig::default(),
            StoredClock::Realtime,
            false,
            0,
            None,
            false,
        );
        let writes = [
            Write::Begin {
                id: id.clone(),
                arena: arena.clone(),
                settings: Box::new(settings),
                live: Box::default(),
                started_at: SystemTime::now(),
            },
            Write::Append {
                id: id.clone(),
                inputs: chunk.clone(),
                names: Some(vec![format!("p{}", i % 50)]),
                live: None,
                tick: 1200,
            },
            Write::Finish {
                id,
                ended: Ended {
                    ended_at: 0,
                    ticks: 1200,
                    winner: Some("robots"),
                    reason: Some("all_tagged"),
                    players: vec![],
                    rated: None,
                },
            },
        ];
        for w in writes {
            let mut w = w;
            while let Err(back) = store.send(w) {
                w = *back;
                std::thread::sleep(Duration::from_millis(1));
            }
        }
        if i % 100 == 99 {
            store.flush(Duration::from_secs(30)).expect("flush");
            most = most.max(store.file_bytes());
        }
    }
    store.flush(Duration::from_secs(30)).expect("flush");
    let (kept, bytes) = store.read(|b| b.totals()).expect("totals");
    println!(
        "{matches} one-minute matches through a store keeping {keep_mb} MB: {kept} kept ({:.2} MB of recordings), database files {:.2} MB now, at most {:.2} MB",
        bytes as f64 / 1e6,
        store.file_bytes() as f64 / 1e6,
        most as f64 / 1e6
    );
    let _ = std::fs::remove_dir_all(&dir);
}
