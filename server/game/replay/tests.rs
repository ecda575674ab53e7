//! The replay's keyframes and the history's byte budget.

use super::*;
use crate::game::view::Clock;
use crate::maps::MapStore;
use lasertag_core::world::{ControlKind, HumanInput};

/// A two-minute office match with a person's keys changing now and then.
fn recorded() -> Replay {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let maps = MapStore::load_dir(&root.join("maps")).expect("shipped maps");
    let arena = maps.get("office").expect("office").arena.clone();
    let config = MatchConfig {
        opponent_control: ControlKind::Human,
        seed: 3,
        ..MatchConfig::default()
    };
    let mut world = World::new(arena.clone(), config.clone()).expect("world");
    let mut inputs = Vec::new();
    for t in 0..400u64 {
        if t.is_multiple_of(37) {
            let input = WorldInput::Keys {
                slot: 0,
                input: HumanInput {
                    forward: if t.is_multiple_of(74) { 1.0 } else { -0.5 },
                    turn: 0.3,
                    ..HumanInput::default()
                },
            };
            world.apply(&input).expect("keys");
            inputs.push((world.tick, input));
        }
        world.step();
    }
    let meta = MatchMeta {
        id: "m".into(),
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
    };
    Replay::of(&world, meta, arena, config, inputs, SystemTime::now())
}

/// `r` under another id (sharing its arena and inputs).
fn renamed(r: &Replay, id: &str) -> Replay {
    Replay {
        meta: MatchMeta {
            id: id.into(),
            ..r.meta.clone()
        },
        last_tick: r.last_tick,
        winner: r.winner,
        players: r.players.clone(),
        started_at: r.started_at,
        ended_at: r.ended_at,
        reason: r.reason,
        complete: r.complete,
        arena: r.arena.clone(),
        config: r.config.clone(),
        inputs: r.inputs.clone(),
        spacing: r.spacing,
        keyframes: Mutex::new(Vec::new()),
    }
}

/// `r` on an arena of its own (a copy of its map), as a match on an inline map has.
fn on_own_arena(r: &Replay, id: &str) -> Replay {
    Replay {
        arena: Arc::new(Arena::new(r.arena.def.clone())),
        ..renamed(r, id)
    }
}

#[test]
fn the_replays_kept_in_memory_fit_in_their_byte_budget() {
    let first = recorded();
    let each = admission::map(&first.arena.def).memory + first.inputs_bytes();
    let fit = (CACHED_BYTES / each) as usize;
    assert!(fit < 40, "{each} bytes each");
    let history = History::new(HISTORY_CAPACITY);
    for k in 0..fit + 5 {
        history.keep(on_own_arena(&first, &format!("m{k}")));
    }
    let kept = history.replays.lock().unwrap().len();
    assert_eq!(kept, fit.max(1), "{each} bytes each");
    // The newest stay, the oldest went.
    assert!(history.get(&format!("m{}", fit + 4)).is_some());
    assert!(history.get("m0").is_none());
    // Replays on one stored map pay for its arena once.
    let shared = History::new(HISTORY_CAPACITY);
    for k in 0..CACHED_WITH_STORE + 5 {
        shared.keep(renamed(&first, &format!("s{k}")));
    }
    assert_eq!(shared.replays.lock().unwrap().len(), CACHED_WITH_STORE + 5);
}

#[test]
fn keyframes_fit_in_their_byte_budget() {
    // An office match's world: many keyframes, never closer than the least spacing.
    assert_eq!(keyframe_spacing(1_000, 400_000), Some(MIN_KEYFRAME_SPACING));
    let every = keyframe_spacing(100_000, 1_000_000).unwrap();
    assert!(
        (100_000 / every + 1) * 1_000_000 <= KEYFRAME_BYTES,
        "{every}"
    );
    // A world bigger than the budget keeps none.
    assert_eq!(keyframe_spacing(6_000, KEYFRAME_BYTES), None);
    let replay = recorded();
    assert!(replay.spacing.is_some());
}

#[test]
fn a_cursor_played_forward_meets_every_seek() {
    let replay = recorded();
    let mut cursor = replay.cursor(100).expect("cursor");
    let mut steps = 0;
    while replay.advance(&mut cursor).expect("inputs") {
        steps += 1;
        let tick = cursor.world().tick;
        if tick.is_multiple_of(23) || tick == replay.last_tick {
            let seek = replay.world_at(tick).expect("seek");
            assert_eq!(seek.digest(), cursor.world().digest(), "tick {tick}");
        }
    }
    assert_eq!(steps, replay.last_tick - 100);
    assert!(!replay.advance(&mut cursor).expect("inputs"));
}

#[test]
fn a_long_record_is_replayed_from_the_store_in_windows() {
    use crate::store::codec::{StoredClock, StoredSettings};
    use crate::store::{Ended, Retention};
    use lasertag_core::world::OpponentOrder;
    use nalgebra::Point2;

    // An opponent driven by commands of 1,000 waypoints: more than a replay keeps in memory.
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let maps = MapStore::load_dir(&root.join("maps")).expect("shipped maps");
    let arena = maps.get("office").expect("office").arena.clone();
    let config = MatchConfig {
        opponent_control: ControlKind::Api,
        seed: 5,
        ..MatchConfig::default()
    };
    let route = |k: u64| {
        OpponentOrder::Waypoints(
            (0..1000)
                .map(|i| Point2::new(2.0 + ((i + k) % 20) as f32, 2.0 + (i % 7) as f32))
                .collect(),
        )
    };
    let mut world = World::new(arena.clone(), config.clone()).expect("world");
    let mut chunks: Vec<Vec<(u64, WorldInput)>> = vec![Vec::new()];
    let mut bytes = 0;
    while bytes <= 2 * inputs::MEMORY_BYTES {
        let tick = world.tick;
        for k in 0..3 {
            let input = WorldInput::Opponent {
                slot: 0,
                order: route(tick + k),
            };
            world.apply(&input).expect("order");
            bytes += crate::game::record::order_bytes(&input).unwrap() as u64;
            chunks.last_mut().unwrap().push((tick, input));
        }
        world.step();
        // An append about once a second of play, as a match's task makes them.
        if world.tick.is_multiple_of(20) {
            chunks.push(Vec::new());
        }
    }
    let last_tick = world.tick;
    let all: Vec<_> = chunks.iter().flatten().cloned().collect();
    let in_memory = Replay::of(
        &world,
        recorded().meta,
        arena.clone(),
        config.clone(),
        all,
        SystemTime::now(),
    );

    let dir = std::env::temp_dir().join(format!("lasertag-replay-windows-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let store = Store::open(
        &dir,
        Retention {
            max_matches: 10,
            max_bytes: 1 << 30,
        },
    )
    .expect("store");
    let settings = StoredSettings::of(&config, StoredClock::Manual, false, 0, None, false);
    store
        .send(Write::Begin {
            id: "long".into(),
            arena,
            settings: Box::new(settings),
            live: Box::default(),
            started_at: SystemTime::now(),
        })
        .expect("begin");
    for inputs in chunks {
        store
            .send(Write::Append {
                id: "long".into(),
                inputs,
                names: None,
                live: None,
                tick: last_tick,
            })
            .expect("append");
    }
    store
        .send(Write::Finish {
            id: "long".into(),
            ended: Ended {
                ended_at: 1,
                ticks: last_tick,
                winner: None,
                reason: Some("stopped"),
                players: Vec::new(),
                rated: None,
            },
        })
        .expect("finish");
    store
        .flush(std::time::Duration::from_secs(10))
        .expect("flush");

    let history = History::with_store(store);
    let stored = history.load("long").expect("load").expect("stored");
    assert!(
        stored.inputs.stored(),
        "past the memory bound the inputs stay in the store"
    );
    assert!(
        stored.inputs_bytes() < 64 << 10,
        "{}",
        stored.inputs_bytes()
    );
    assert!(in_memory.inputs_bytes() > inputs::MEMORY_BYTES);
    for tick in [0, 1, 19, 20, 21, last_tick / 2, last_tick - 1, last_tick] {
        let (a, b) = (
            in_memory.world_at(tick).unwrap(),
            stored.world_at(tick).unwrap(),
        );
        assert_eq!(a.digest(), b.digest(), "tick {tick}");
    }
    let mut cursor = stored.cursor(7).expect("cursor");
    while stored.advance(&mut cursor).expect("a window") {
        let tick = cursor.world().tick;
        if tick.is_multiple_of(17) || tick == last_tick {
            assert_eq!(
                cursor.world().digest(),
                in_memory.world_at(tick).unwrap().digest(),
                "tick {tick}"
            );
        }
    }
    assert_eq!(cursor.world().tick, last_tick);
    let _ = std::fs::remove_dir_all(&dir);
}
