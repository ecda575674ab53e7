//! The SQLite backend against a real file: retention, listing, loading, statistics, the
//! schema's version and matches left running.

use super::super::codec::StoredSettings;
use super::super::{Backend, Ended, PlayerResult, Retention, Write};
use super::*;
use crate::store::codec::StoredClock;
use lasertag_core::world::{HumanInput, MatchConfig, MatchStatus, World, WorldInput};

fn dir(what: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("lasertag-sqlite-{what}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// Match `id` whole: begun, an append of `n` inputs, ended with `name` playing.
fn a_match(id: &str, n: usize, name: &str, won: bool) -> Vec<Write> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let maps = crate::maps::MapStore::load_dir(&root.join("maps")).expect("maps");
    let arena = maps.get("office").expect("office").arena.clone();
    let keys = WorldInput::Keys {
        slot: 0,
        input: HumanInput {
            forward: 1.0,
            ..HumanInput::default()
        },
    };
    vec![
        Write::Begin {
            id: id.into(),
            arena,
            settings: Box::new(StoredSettings::of(
                &MatchConfig::default(),
                StoredClock::Realtime,
                false,
                0,
                None,
                false,
            )),
            live: Box::new(crate::store::codec::StoredLive {
                owner: Some("ab".repeat(32)),
                ..Default::default()
            }),
            started_at: std::time::SystemTime::now(),
        },
        Write::Append {
            id: id.into(),
            inputs: (0..n as u64).map(|t| (t, keys.clone())).collect(),
            names: Some(vec![name.into()]),
            live: None,
            tick: n as u64,
        },
        Write::Finish {
            id: id.into(),
            ended: Ended {
                ended_at: 1,
                ticks: n as u64,
                winner: Some(if won { "opponents" } else { "robots" }),
                reason: Some("time_limit"),
                players: vec![PlayerResult {
                    name: name.into(),
                    tags: 2,
                    survived_ticks: n as u64,
                    won,
                    rated: true,
                }],
                rated: None,
            },
        },
    ]
}

#[test]
fn retention_keeps_the_newest_and_statistics_add_up() {
    let d = dir("retention");
    let retention = Retention {
        max_matches: 3,
        max_bytes: 1 << 30,
    };
    let mut db = Sqlite::open(&d, retention).expect("open");
    for i in 0..5 {
        db.write(&a_match(
            &format!("m{i}"),
            10 + i,
            if i % 2 == 0 { "ada" } else { "bob" },
            i != 1,
        ))
        .expect("write");
    }
    let listed: Vec<String> = db
        .list(10, None, None)
        .expect("list")
        .into_iter()
        .map(|l| l.id)
        .collect();
    assert_eq!(listed, ["m4", "m3", "m2"]);
    let older: Vec<String> = db
        .list(10, Some("m3"), None)
        .expect("list")
        .into_iter()
        .map(|l| l.id)
        .collect();
    assert_eq!(older, ["m2"]);
    let stored = db.load("m2").expect("load").expect("m2 is there");
    let inputs: usize = stored
        .chunks
        .iter()
        .map(|c| super::super::codec::decode_inputs(c).expect("decode").len())
        .sum();
    assert_eq!(inputs, 12);
    assert!(db.load("m0").expect("load").is_none(), "evicted");
    let ada = db.player("ada").expect("stats").expect("ada");
    assert_eq!(
        (ada.matches, ada.wins, ada.tags, ada.longest_survival_ticks),
        (2, 2, 4, 14)
    );
    let by_wins = db.leaders(LeaderOrder::Wins, 10).expect("leaders");
    assert_eq!(by_wins[0].name, "ada");
    // A byte limit evicts too.
    let mut db = Sqlite::open(
        &d,
        Retention {
            max_matches: 100,
            max_bytes: 1,
        },
    )
    .expect("reopen");
    db.write(&a_match("m5", 5, "cy", true)).expect("write");
    assert!(db.list(10, None, None).expect("list").len() <= 1);
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_newer_schema_is_refused_and_an_unfinished_match_is_kept_for_resuming_or_lost() {
    let d = dir("schema");
    let retention = Retention {
        max_matches: 10,
        max_bytes: 1 << 30,
    };
    let mut db = Sqlite::open(&d, retention).expect("open");
    let mut writes = a_match("cut", 7, "ada", false);
    writes.pop();
    db.write(&writes).expect("write");
    assert!(
        db.list(10, None, None).expect("list").is_empty(),
        "still running"
    );
    assert_eq!(db.unfinished().expect("unfinished"), ["cut"]);
    let left = db
        .load_unfinished("cut")
        .expect("load")
        .expect("the running match");
    assert_eq!(left.stored.listed.ticks, 7);
    assert_eq!(left.stored.chunks.len(), 1);
    let live = crate::store::codec::StoredLive::from_json(&left.live.expect("live record"));
    assert_eq!(live.expect("parses").owner, Some("ab".repeat(32)));
    assert!(db.load("cut").expect("load").is_none(), "not ended");
    db.write(&[Write::Lost { id: "cut".into() }]).expect("lost");
    assert!(db.unfinished().expect("unfinished").is_empty());
    let cut = db.list(10, None, None).expect("list");
    assert_eq!((cut[0].complete, cut[0].ticks), (false, 7));
    assert_eq!(cut[0].reason.as_deref(), Some("lost"));
    assert_eq!(cut[0].players, ["ada"]);
    db.connection()
        .pragma_update(None, "user_version", SCHEMA_VERSION + 1)
        .expect("pragma");
    drop(db);
    assert!(matches!(open(&d), Err(StoreError::NewerSchema { .. })));
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn a_running_match_keeps_its_two_newest_checkpoints_and_its_end_lets_them_go() {
    let d = dir("checkpoints");
    let retention = Retention {
        max_matches: 10,
        max_bytes: 1 << 30,
    };
    let mut db = Sqlite::open(&d, retention).expect("open");
    let mut writes = a_match("long", 7, "ada", false);
    let finish = writes.pop().expect("the finish");
    db.write(&writes).expect("write");
    let Write::Begin { arena, .. } = &writes[0] else {
        panic!("a begin first")
    };
    let mut world = World::new(arena.clone(), MatchConfig::default()).expect("world");
    let mut last = 0;
    for tick in [20, 40, 60] {
        while world.tick < tick {
            assert_ne!(world.status, MatchStatus::Finished, "the match runs on");
            world.step();
        }
        let write = Write::Checkpoint {
            id: "long".into(),
            tick,
            applied: 7,
            keep_from: last,
            world: Box::new(world.clone()),
            max_bytes: u64::MAX,
        };
        db.write(&[write]).expect("checkpoint");
        last = tick;
    }
    let left = db.load_unfinished("long").expect("load").expect("running");
    let ticks: Vec<u64> = left.checkpoints.iter().map(|c| c.tick).collect();
    assert_eq!(ticks, [60, 40], "the newest two, newest first");
    let back = crate::store::codec::decode_checkpoint(
        World::new(arena.clone(), MatchConfig::default()).expect("world"),
        &left.checkpoints[0].state,
    )
    .expect("restores");
    assert_eq!(back.digest(), world.digest());
    // One past its price is not stored; the others stay.
    let big = Write::Checkpoint {
        id: "long".into(),
        tick: 80,
        applied: 7,
        keep_from: 60,
        world: Box::new(world.clone()),
        max_bytes: 10,
    };
    db.write(&[big]).expect("the batch goes through");
    let left = db.load_unfinished("long").expect("load").expect("running");
    assert_eq!(left.checkpoints.len(), 2);
    db.write(&[finish]).expect("finish");
    let kept: i64 = db
        .connection()
        .query_row("SELECT COUNT(*) FROM checkpoints", [], |r| r.get(0))
        .expect("count");
    assert_eq!(kept, 0, "an ended match replays from its start");
    let _ = std::fs::remove_dir_all(&d);
}

/// Bytes of the files in `d` (the database, its write-ahead log and shared memory).
fn dir_bytes(d: &std::path::Path) -> u64 {
    std::fs::read_dir(d)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok()?.metadata().ok())
                .map(|m| m.len())
                .sum()
        })
        .unwrap_or(0)
}

#[test]
fn retention_holds_the_data_directory_to_its_bytes_with_large_maps() {
    use lasertag_core::sim::arena::{Arena, MapDef};
    use nalgebra::Point2;
    let d = dir("map-bytes");
    let max_bytes = 1 << 20;
    let mut db = Sqlite::open(
        &d,
        Retention {
            max_matches: 10_000,
            max_bytes,
        },
    )
    .expect("open");
    for k in 0..16 {
        // About 150 KB of map document each, every map its own.
        let squares: Vec<Vec<Point2<f32>>> = (0..1200)
            .map(|i| {
                let (x, y) = (
                    1.0 + (i % 40) as f32 + k as f32 * 0.001,
                    1.0 + (i / 40) as f32,
                );
                vec![
                    Point2::new(x, y),
                    Point2::new(x + 0.2, y),
                    Point2::new(x + 0.2, y + 0.2),
                    Point2::new(x, y + 0.2),
                ]
            })
            .collect();
        let arena = std::sync::Arc::new(Arena::new(MapDef {
            name: format!("big{k}"),
            width: 42.0,
            height: 32.0,
            obstacles: squares,
            robot_spawns: vec![[0.5, 0.5, 0.0]],
            opponent_spawns: vec![Point2::new(41.5, 31.5)],
            landmarks: vec![],
        }));
        let mut writes = a_match(&format!("m{k}"), 20, "ada", true);
        if let Write::Begin { arena: a, .. } = &mut writes[0] {
            *a = arena;
        }
        // As a server writes: the start (with its map) in one batch, the rest in later ones.
        db.write(&writes[..1]).expect("write the start");
        db.write(&writes[1..]).expect("write the rest");
        let on_disk = dir_bytes(&d);
        assert!(
            on_disk <= max_bytes,
            "after {k} matches: {on_disk} bytes on disk: {:?}",
            std::fs::read_dir(&d)
                .map(|es| es
                    .filter_map(|e| e.ok())
                    .map(|e| (e.file_name(), e.metadata().map(|m| m.len()).unwrap_or(0)))
                    .collect::<Vec<_>>())
                .unwrap_or_default()
        );
    }
    // The newest is kept; the oldest went.
    assert!(db.load("m15").expect("load").is_some());
    assert!(db.load("m0").expect("load").is_none());
    let _ = std::fs::remove_dir_all(&d);
}

#[test]
fn the_history_lists_matches_as_they_ended_and_can_leave_a_prefix_out() {
    let d = dir("end-order");
    let retention = Retention {
        max_matches: 100,
        max_bytes: 1 << 30,
    };
    let mut db = Sqlite::open(&d, retention).expect("open");
    let ending_at = |id: &str, at| {
        let mut w = a_match(id, 3, "ada", true);
        if let Some(Write::Finish { ended, .. }) = w.last_mut() {
            ended.ended_at = at;
        }
        w
    };
    // They start a, b, c and end c, b, a.
    let all = [
        ending_at("a", 30),
        ending_at("showcase-b", 20),
        ending_at("c", 10),
    ];
    for w in &all {
        db.write(&w[..2]).expect("begin");
    }
    for w in all.iter().rev() {
        db.write(&w[2..]).expect("finish");
    }
    let mut ids = |before, without| -> Vec<String> {
        let listed = db.list(10, before, without).expect("list");
        listed.into_iter().map(|l| l.id).collect()
    };
    assert_eq!(ids(None, None), ["a", "showcase-b", "c"]);
    assert_eq!(ids(Some("a"), None), ["showcase-b", "c"]);
    assert_eq!(ids(Some("showcase-b"), None), ["c"]);
    assert_eq!(ids(None, Some("showcase-")), ["a", "c"]);
    assert_eq!(ids(Some("unknown"), None).len(), 3);
    let _ = std::fs::remove_dir_all(&d);
}
