//! The history in PostgreSQL, on a server the tests start themselves (`common/postgres.rs`):
//! the backend alone (a match's round trip, the same listings, statistics and retention as
//! SQLite's, migrations, a newer schema, whose matches a writer may touch and when they are
//! closed, a dropped connection, bad URLs), then the real binary several times on one
//! database: a match recorded by one server is listed and replayed by another, a server
//! starting leaves another's live match alone, and a killed server's match is closed once
//! its writer has gone silent.
//!
//! Long file: every test here shares one PostgreSQL cluster per test binary (`initdb` and a
//! start cost seconds), so the backend's tests, the binary's and the measurement stay in
//! one file.

#![cfg(unix)]

mod common;
#[path = "common/postgres.rs"]
mod pg;
#[path = "common/process.rs"]
mod process;

use std::time::{Duration, Instant};

use lasertag::store::codec::StoredClock;
use lasertag::store::codec::{StoredSettings, decode_inputs};
use lasertag::store::postgres::{Postgres, SCHEMA_VERSION};
use lasertag::store::sqlite::Sqlite;
use lasertag::store::{
    Backend, Ended, LeaderOrder, PlayerResult, Retention, Store, StoreError, Write,
};
use lasertag_core::world::{HumanInput, MatchConfig, WorldInput};
use process::{Server, create, get, step};
use serde_json::{Value, json};

const KEEP_ALL: Retention = Retention {
    max_matches: 10_000,
    max_bytes: 1 << 30,
};

fn keys(t: u64) -> (u64, WorldInput) {
    let input = HumanInput {
        forward: 1.0,
        turn: (t % 3) as f32 - 1.0,
        ..HumanInput::default()
    };
    (t, WorldInput::Keys { slot: 0, input })
}

fn office() -> std::sync::Arc<lasertag_core::sim::arena::Arena> {
    static OFFICE: std::sync::OnceLock<std::sync::Arc<lasertag_core::sim::arena::Arena>> =
        std::sync::OnceLock::new();
    OFFICE
        .get_or_init(|| common::shipped_arena("office"))
        .clone()
}

/// Match `id`'s start and one append of `n` inputs, with `name` playing.
fn started(id: &str, n: u64, name: &str) -> Vec<Write> {
    vec![
        Write::Begin {
            id: id.into(),
            arena: office(),
            settings: Box::new(StoredSettings::of(
                &MatchConfig::default(),
                StoredClock::Realtime,
                false,
                0,
                None,
                false,
            )),
            live: Box::default(),
            started_at: std::time::SystemTime::now(),
        },
        Write::Append {
            id: id.into(),
            inputs: (0..n).map(keys).collect(),
            names: Some(vec![name.into()]),
            live: None,
            tick: n,
        },
    ]
}

fn finish(id: &str, n: u64, name: &str, won: bool) -> Write {
    Write::Finish {
        id: id.into(),
        ended: Ended {
            ended_at: 1,
            ticks: n,
            winner: Some(if won { "opponents" } else { "robots" }),
            reason: Some("time_limit"),
            players: vec![PlayerResult {
                name: name.into(),
                tags: 2,
                survived_ticks: n,
                won,
                rated: true,
            }],
            rated: None,
        },
    }
}

/// Match `id` whole: begun, `n` inputs, ended with `name` playing.
fn a_match(id: &str, n: u64, name: &str, won: bool) -> Vec<Write> {
    let mut w = started(id, n, name);
    w.push(finish(id, n, name, won));
    w
}

fn ids(db: &mut dyn Backend, before: Option<&str>) -> Vec<String> {
    let listed = db.list(10, before, None).expect("list");
    listed.into_iter().map(|l| l.id).collect()
}

#[test]
fn a_recorded_match_comes_back_whole_and_only_its_writer_may_change_it() {
    let database = pg::database("round_trip");
    let mut a = Postgres::open(&database.url, KEEP_ALL).expect("open");
    let mut b = Postgres::open(&database.url, KEEP_ALL).expect("a second writer");
    // Reads through the local socket, as a server beside the database would.
    let mut reader = Postgres::reader(&database.socket_url(), KEEP_ALL).expect("reader");
    assert!(reader.target().starts_with("/tmp/"), "{}", reader.target());
    assert_ne!(a.writer_id(), b.writer_id());

    a.write(&started("m0", 30, "ada")).expect("write");
    assert!(ids(&mut reader, None).is_empty(), "still running");
    assert!(reader.load("m0").expect("load").is_none());
    // Another writer can neither take the id nor touch the match.
    b.write(&a_match("m0", 5, "eve", true))
        .expect("refused, not failed");
    a.write(&[finish("m0", 30, "ada", true)]).expect("write");

    let stored = reader.load("m0").expect("load").expect("m0 is there");
    let l = &stored.listed;
    assert_eq!(
        (l.id.as_str(), l.map.as_str(), l.ticks, l.complete),
        ("m0", "office", 30, true)
    );
    assert_eq!(l.winner.as_deref(), Some("opponents"));
    assert_eq!(l.reason.as_deref(), Some("time_limit"));
    assert_eq!(l.players, ["ada"]);
    let inputs: Vec<_> = stored
        .chunks
        .iter()
        .flat_map(|c| decode_inputs(c).expect("decode"))
        .collect();
    assert_eq!(inputs, (0..30).map(keys).collect::<Vec<_>>());
    let arena = common::shipped_arena("office");
    let map = lasertag::maps::parse(&stored.map_document).expect("the stored map parses");
    assert_eq!(map.name, arena.def.name);
    let settings: StoredSettings = serde_json::from_str(&stored.settings).expect("settings");
    assert_eq!(
        settings.config().expect("config").seed,
        MatchConfig::default().seed
    );
    let ada = reader.player("ada").expect("stats").expect("ada");
    assert_eq!((ada.matches, ada.wins, ada.tags), (1, 1, 2));
    assert!(reader.player("eve").expect("stats").is_none());
    // The writer's own reads see the same.
    assert_eq!(ids(&mut b, None), ["m0"]);
}

/// What a backend answers to the same writes: every read the store offers.
#[derive(Debug, PartialEq)]
struct Answers {
    listed: Vec<String>,
    older: Vec<String>,
    inputs_of_m2: usize,
    m0_kept: bool,
    ada: (u64, u64, u64, u64),
    played: Vec<String>,
    leaders: Vec<Vec<String>>,
    totals_count: u64,
    after_byte_limit: usize,
}

/// SQLite's retention test, on any backend: `open` makes the writer with a retention.
fn answers(open: &dyn Fn(Retention) -> Box<dyn Backend>) -> Answers {
    let mut db = open(Retention {
        max_matches: 3,
        max_bytes: 1 << 30,
    });
    let name = |i: u64| if i.is_multiple_of(2) { "ada" } else { "bob" };
    for i in 0..5 {
        let id = format!("m{i}");
        db.write(&a_match(&id, 10 + i, name(i), i != 1))
            .expect("write");
    }
    let stored = db.load("m2").expect("load").expect("m2 is there");
    // A replay's windows give the chunks `load` gives, from any position; none past the end
    // or of a match no longer stored.
    let window = |db: &mut Box<dyn Backend>, id: &str, from: usize| {
        db.input_chunks(id, from, 10).expect("a window")
    };
    assert_eq!(window(&mut db, "m2", 0), stored.chunks);
    assert!(window(&mut db, "m2", stored.chunks.len()).is_empty());
    assert!(window(&mut db, "m0", 0).is_empty(), "m0 was evicted");
    let ada = db.player("ada").expect("stats").expect("ada");
    let orders = [
        LeaderOrder::Wins,
        LeaderOrder::Tags,
        LeaderOrder::Survival,
        LeaderOrder::Matches,
    ];
    let mut a = Answers {
        listed: ids(db.as_mut(), None),
        older: ids(db.as_mut(), Some("m3")),
        inputs_of_m2: stored
            .chunks
            .iter()
            .map(|c| decode_inputs(c).expect("decode").len())
            .sum(),
        m0_kept: db.load("m0").expect("load").is_some(),
        ada: (ada.matches, ada.wins, ada.tags, ada.longest_survival_ticks),
        played: db
            .played("bob", 10)
            .expect("played")
            .into_iter()
            .map(|p| p.listed.id)
            .collect(),
        leaders: orders
            .iter()
            .map(|o| {
                let board = db.leaders(*o, 10).expect("leaders");
                board.into_iter().map(|s| s.name).collect()
            })
            .collect(),
        totals_count: db.totals().expect("totals").0,
        after_byte_limit: 0,
    };
    drop(db);
    // A byte limit evicts too.
    let mut db = open(Retention {
        max_matches: 100,
        max_bytes: 1,
    });
    db.write(&a_match("m5", 5, "cy", true)).expect("write");
    a.after_byte_limit = db.list(10, None, None).expect("list").len();
    a
}

#[test]
fn listings_statistics_and_retention_answer_as_sqlites_do() {
    let database = pg::database("same_answers");
    let url = database.url.clone();
    let postgres = answers(&|r| Box::new(Postgres::open(&url, r).expect("open")));
    let dir = common::temp_dir("sqlite-answers");
    let sqlite = answers(&|r| Box::new(Sqlite::open(&dir, r).expect("open")));
    assert_eq!(postgres, sqlite);
    assert_eq!(postgres.listed, ["m4", "m3", "m2"]);
    assert_eq!(postgres.older, ["m2"]);
    assert_eq!(postgres.inputs_of_m2, 12);
    assert!(!postgres.m0_kept, "evicted");
    assert_eq!(postgres.ada, (2, 2, 4, 14));
    assert_eq!(postgres.leaders[0][0], "ada");
    assert!(postgres.after_byte_limit <= 1);
    // Evicted matches took their rows with them.
    let orphans = database.query_text(
        "SELECT ((SELECT COUNT(*) FROM inputs WHERE seq NOT IN (SELECT seq FROM matches))
              + (SELECT COUNT(*) FROM players WHERE seq NOT IN (SELECT seq FROM matches))
              + (SELECT COUNT(*) FROM maps
                 WHERE hash NOT IN (SELECT map_hash FROM matches)))::TEXT",
    );
    assert_eq!(orphans.as_deref(), Some("0"));
}

/// A scripted series of rated matches (and one unrated), on any backend: each name's
/// rating and match count, what each of ada's matches did to her rating (newest first),
/// and the leaderboard by rating.
/// A name's (rating, deviation, rated matches), rounded, once rated.
type RatingOf = Option<(i64, i64, u64)>;

#[derive(Debug, PartialEq)]
struct Ratings {
    of: Vec<(String, RatingOf)>,
    ada_changes: Vec<(Option<i64>, Option<i64>)>,
    by_rating: Vec<String>,
}

fn rated_series(open: &dyn Fn() -> Box<dyn Backend>) -> Ratings {
    use lasertag_core::difficulty::Difficulty::{Elite, Recruit, Veteran};
    let mut db = open();
    let series = [
        ("ada", Some(Recruit), true),
        ("bob", Some(Recruit), false),
        ("ada", Some(Recruit), true),
        ("cy", Some(Elite), true),
        ("ada", Some(Elite), false),
        ("bob", Some(Recruit), false),
        ("ada", Some(Veteran), true),
        // Unrated (a custom team, or an end not by the rules): no rating.
        ("dee", None, true),
        ("ada", None, false),
    ];
    for (i, (name, preset, won)) in series.into_iter().enumerate() {
        let id = format!("r{i}");
        let mut writes = started(&id, 5, name);
        let mut end = finish(&id, 5, name, won);
        if let Write::Finish { ended, .. } = &mut end {
            ended.rated = preset;
        }
        writes.push(end);
        db.write(&writes).expect("write");
    }
    let round = |v: f64| v.round() as i64;
    let of = ["ada", "bob", "cy", "dee"]
        .iter()
        .map(|n| {
            let stats = db.player(n).expect("stats").expect("played");
            let r = stats
                .rating
                .map(|r| (round(r.rating), round(r.deviation), r.matches));
            (n.to_string(), r)
        })
        .collect();
    let ada_changes = db
        .played("ada", 10)
        .expect("played")
        .into_iter()
        .map(|p| (p.rating_before.map(round), p.rating_after.map(round)))
        .collect();
    let by_rating = db
        .leaders(LeaderOrder::Rating, 10)
        .expect("leaders")
        .into_iter()
        .map(|s| s.name)
        .collect();
    Ratings {
        of,
        ada_changes,
        by_rating,
    }
}

#[test]
fn a_series_of_rated_matches_rates_alike_in_both_databases() {
    let database = pg::database("ratings");
    let url = database.url.clone();
    let postgres = rated_series(&|| Box::new(Postgres::open(&url, KEEP_ALL).expect("open")));
    let dir = common::temp_dir("sqlite-ratings");
    let sqlite = rated_series(&|| Box::new(Sqlite::open(&dir, KEEP_ALL).expect("open")));
    assert_eq!(postgres, sqlite);
    eprintln!("ratings after the series: {:?}", postgres.of);
    eprintln!(
        "ada's matches, newest first (before, after): {:?}",
        postgres.ada_changes
    );
    let rating = |name: &str| {
        postgres
            .of
            .iter()
            .find(|(n, _)| n == name)
            .and_then(|(_, r)| *r)
    };
    let (ada, bob, cy) = (
        rating("ada").expect("ada is rated"),
        rating("bob").expect("bob is rated"),
        rating("cy").expect("cy is rated"),
    );
    assert_eq!(rating("dee"), None, "an unrated match rates nobody");
    assert_eq!((ada.2, bob.2, cy.2), (4, 2, 1));
    assert!(ada.0 > 1500 && bob.0 < 1500, "{ada:?} {bob:?}");
    // One upset moves a newcomer far, with a wide deviation left.
    assert!(cy.0 > ada.0 && cy.1 > ada.1, "{cy:?} {ada:?}");
    // Each rated match starts where the one before ended; the unrated one changes nothing.
    let changes = &postgres.ada_changes;
    assert_eq!(changes[0], (None, None));
    assert_eq!(changes[4].0, Some(1500));
    for pair in changes[1..].windows(2) {
        assert_eq!(pair[0].0, pair[1].1, "{changes:?}");
    }
    assert_eq!(changes[1].1, Some(ada.0));
    // Ranked by rating less two deviations, rated names only.
    let mut expected: Vec<_> = postgres
        .of
        .iter()
        .filter_map(|(n, r)| r.map(|r| (r.0 - 2 * r.1, n.clone())))
        .collect();
    expected.sort_by(|a, b| b.cmp(a));
    let expected: Vec<String> = expected.into_iter().map(|(_, n)| n).collect();
    assert_eq!(postgres.by_rating, expected);
    assert_eq!(postgres.by_rating.len(), 3);
}

/// A script of claims, look-alikes, limits and releases, and what the backend answered.
fn claims(db: &mut dyn Backend) -> Vec<String> {
    use lasertag::store::{ClaimLimits, NameClaim};
    let limits = ClaimLimits {
        per_client: 2,
        total: 3,
    };
    let claim = |db: &mut dyn Backend, name: &str, client: &str| {
        let name = lasertag::names::Name::parse(name).expect("a name");
        let claim = NameClaim {
            name: name.as_str().into(),
            key: name.key().into(),
            token: format!("hash-of-{}", name.as_str()),
            client: client.into(),
            claimed_at: 1,
        };
        format!("{:?}", db.claim(&claim, limits))
    };
    let mut said = vec![
        claim(db, "victim", "10.0.0.1"),
        claim(db, "vi\u{0441}tim", "10.0.0.2"),
        claim(db, "Victim", "10.0.0.2"),
        claim(db, "ada", "10.0.0.1"),
        claim(db, "bob", "10.0.0.1"),
        claim(db, "cy", "10.0.0.3"),
        claim(db, "dee", "10.0.0.4"),
    ];
    let key = |s: &str| lasertag::names::Name::parse(s).unwrap().key().to_string();
    said.push(format!(
        "{:?}",
        db.claimed(&key("VICTIM")).map(|c| c.map(|c| c.name))
    ));
    said.push(format!("{:?}", db.release(&key("victim"), "not-its-hash")));
    said.push(format!(
        "{:?}",
        db.release(&key("victim"), "hash-of-victim")
    ));
    said.push(format!(
        "{:?}",
        db.release(&key("victim"), "hash-of-victim")
    ));
    said.push(claim(db, "dee", "10.0.0.4"));
    said
}

#[test]
fn claims_of_names_answer_alike_in_both_databases() {
    let database = pg::database("names");
    let mut postgres = Postgres::open(&database.url, KEEP_ALL).expect("open");
    let dir = common::temp_dir("sqlite-names");
    let mut sqlite = Sqlite::open(&dir, KEEP_ALL).expect("open");
    let said = claims(&mut postgres);
    assert_eq!(said, claims(&mut sqlite));
    assert_eq!(
        said,
        [
            "Ok(Claimed)",
            "Ok(Taken(\"victim\"))",
            "Ok(Taken(\"victim\"))",
            "Ok(Claimed)",
            "Ok(ClientFull)",
            "Ok(Claimed)",
            "Ok(ServerFull)",
            "Ok(Some(\"victim\"))",
            "Ok(WrongToken)",
            "Ok(Released)",
            "Ok(NotClaimed)",
            "Ok(Claimed)",
        ]
    );
}

/// A script of kept policies (a name kept twice, one forgotten), and what the backend
/// answered.
fn kept_policies(db: &mut dyn Backend) -> Vec<String> {
    use lasertag::store::KeptPolicy;
    let policy = |name: &str, added_at: i64| KeptPolicy {
        name: name.into(),
        model: vec![added_at as u8, 0, 255, 7],
        token: format!("hash-of-{name}"),
        client: "10.0.0.1".into(),
        every: 4,
        added_at,
    };
    let names = |db: &mut dyn Backend| {
        let kept = db.kept_policies().expect("read");
        format!("{:?}", kept.iter().map(|k| &k.name).collect::<Vec<_>>())
    };
    let mut said = vec![
        format!("{:?}", db.keep_policy(&policy("b", 2))),
        format!("{:?}", db.keep_policy(&policy("a", 3))),
        format!("{:?}", db.keep_policy(&policy("b", 4))),
        names(db),
    ];
    let b = db.kept_policy("b").expect("read").expect("kept");
    said.push(format!("{:?}", b == policy("b", 2)));
    said.push(format!("{:?}", db.drop_policy("b")));
    said.push(format!("{:?}", db.kept_policy("b")));
    said.push(names(db));
    said
}

#[test]
fn kept_policies_answer_alike_in_both_databases() {
    let database = pg::database("policies");
    let mut postgres = Postgres::open(&database.url, KEEP_ALL).expect("open");
    let dir = common::temp_dir("sqlite-policies");
    let mut sqlite = Sqlite::open(&dir, KEEP_ALL).expect("open");
    let said = kept_policies(&mut postgres);
    assert_eq!(said, kept_policies(&mut sqlite));
    assert_eq!(
        said,
        [
            "Ok(true)",
            "Ok(true)",
            "Ok(false)",
            "[\"b\", \"a\"]",
            "true",
            "Ok(())",
            "Ok(None)",
            "[\"a\"]",
        ]
    );
}

#[test]
fn kept_policies_count_against_the_history_bytes() {
    let database = pg::database("policy_bytes");
    let retention = Retention {
        max_matches: 100,
        max_bytes: 200_000,
    };
    let mut db = Postgres::open(&database.url, retention).expect("open");
    for i in 0..3 {
        db.write(&a_match(&format!("k{i}"), 10, "ada", true))
            .expect("write");
    }
    assert_eq!(ids(&mut db, None), ["k2", "k1", "k0"]);
    // A model that takes all but 1,000 of the history's bytes: the ended matches go, the
    // newest too, at the next end.
    let policy = lasertag::store::KeptPolicy {
        name: "heavy".into(),
        model: vec![7; 199_000],
        token: "hash".into(),
        client: "10.0.0.1".into(),
        every: 2,
        added_at: 1,
    };
    assert!(db.keep_policy(&policy).expect("keep"));
    db.write(&a_match("k3", 10, "ada", true)).expect("write");
    assert_eq!(ids(&mut db, None), Vec::<String>::new());
    // Without it, they fit again.
    db.drop_policy("heavy").expect("drop");
    db.write(&a_match("k4", 10, "ada", true)).expect("write");
    assert_eq!(ids(&mut db, None), ["k4"]);
}

#[test]
fn migrations_run_once_even_at_once_and_a_newer_schema_is_refused() {
    let database = pg::database("migrations");
    // Servers of a fleet starting together: one migrates, the others wait and find it done.
    let opened: Vec<_> = (0..4)
        .map(|_| {
            let url = database.url.clone();
            std::thread::spawn(move || Postgres::open(&url, KEEP_ALL).map(drop))
        })
        .collect();
    for o in opened {
        o.join().expect("no panic").expect("open");
    }
    let version = "SELECT string_agg(version::TEXT, ',') FROM lasertag_schema";
    let expected = SCHEMA_VERSION.to_string();
    assert_eq!(database.query_text(version).as_deref(), Some(&*expected));
    Postgres::reader(&database.url, KEEP_ALL).expect("reader");
    Postgres::open(&database.url, KEEP_ALL).expect("again");
    assert_eq!(database.query_text(version).as_deref(), Some(&*expected));

    database.sql("UPDATE lasertag_schema SET version = version + 1");
    type Open = fn(&str, Retention) -> Result<Postgres, StoreError>;
    for open in [Postgres::open as Open, Postgres::reader] {
        match open(&database.url, KEEP_ALL) {
            Err(StoreError::NewerSchema { found, known }) => {
                assert_eq!((found, known), (SCHEMA_VERSION + 1, SCHEMA_VERSION))
            }
            other => panic!("expected NewerSchema, got {:?}", other.map(|_| ())),
        }
    }
}

#[test]
fn only_a_silent_writers_matches_are_closed_and_speaking_again_reopens_them() {
    let database = pg::database("silent_writer");
    let mut a = Postgres::open(&database.url, KEEP_ALL).expect("open");
    let mut b = Postgres::open(&database.url, KEEP_ALL).expect("open");
    a.write(&started("live", 7, "ada")).expect("write");
    // b starting (or beating) leaves a's live match alone.
    assert_eq!(b.close_interrupted().expect("close"), 0);
    b.heartbeat().expect("heartbeat");
    assert!(ids(&mut b, None).is_empty());

    let a_id = a.writer_id().expect("a writer").to_string();
    let age = format!("UPDATE writers SET seen_at = now() - interval '1 hour' WHERE id = '{a_id}'");
    database.sql(&age);
    assert_eq!(b.close_interrupted().expect("close"), 1);
    let cut = b.list(10, None, None).expect("list");
    assert_eq!(
        (cut[0].id.as_str(), cut[0].complete, cut[0].ticks),
        ("live", false, 7)
    );
    assert_eq!(cut[0].players, ["ada"]);
    let writers = format!("SELECT COUNT(*)::TEXT FROM writers WHERE id = '{a_id}'");
    assert_eq!(
        database.query_text(&writers).as_deref(),
        Some("0"),
        "forgotten"
    );

    // a was only cut off: its next write reopens the match, its heartbeat is back, and it
    // finishes the match whole.
    a.write(&[Write::Append {
        id: "live".into(),
        inputs: vec![keys(8)],
        names: None,
        live: None,
        tick: 9,
    }])
    .expect("write");
    assert!(ids(&mut b, None).is_empty(), "running again");
    a.heartbeat().expect("heartbeat");
    assert_eq!(database.query_text(&writers).as_deref(), Some("1"));
    assert_eq!(b.close_interrupted().expect("close"), 0);
    a.write(&[finish("live", 9, "ada", false)]).expect("write");
    let done = b.load("live").expect("load").expect("stored");
    assert_eq!((done.listed.complete, done.listed.ticks), (true, 9));
    assert_eq!(done.chunks.len(), 2);
}

#[test]
fn a_dropped_connection_is_made_again_and_an_outage_loses_no_write() {
    let database = pg::database("reconnect");
    let mut w = Postgres::open(&database.url, KEEP_ALL).expect("open");
    let mut r = Postgres::reader(&database.url, KEEP_ALL).expect("reader");
    w.write(&a_match("before", 5, "ada", true)).expect("write");
    assert_eq!(ids(&mut r, None), ["before"]);
    // What a database restart or a failover does to every open connection.
    database.sql(
        "SELECT pg_terminate_backend(pid) FROM pg_stat_activity
         WHERE datname = current_database() AND pid <> pg_backend_pid()",
    );
    w.write(&a_match("after", 6, "bob", false)).expect("write");
    assert_eq!(ids(&mut r, None), ["after", "before"]);
    let after = r.load("after").expect("load").expect("stored");
    assert_eq!((after.listed.complete, after.chunks.len()), (true, 1));

    // A database that refuses connections for a while: the writer waits for it rather than
    // drop the batch (the store's queue holds what comes meanwhile).
    let name = &database.name;
    let cluster = database.cluster.clone();
    cluster.sql(
        "postgres",
        &format!(
            "ALTER DATABASE \"{name}\" ALLOW_CONNECTIONS false;
             SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE datname = '{name}'"
        ),
    );
    let reopen = format!("ALTER DATABASE \"{name}\" ALLOW_CONNECTIONS true");
    let back = std::thread::spawn(move || {
        std::thread::sleep(Duration::from_millis(1500));
        cluster.sql("postgres", &reopen);
    });
    let t = Instant::now();
    w.write(&a_match("during", 4, "cy", true)).expect("write");
    let waited = t.elapsed();
    assert!(waited >= Duration::from_millis(1400), "{waited:?}");
    back.join().expect("reopened");
    assert_eq!(ids(&mut r, None), ["during", "after", "before"]);
}

#[test]
fn a_bad_url_or_an_unreachable_database_is_named() {
    let database = pg::database("bad_urls");
    let closed = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a port")
        .port();
    let no_database = database.url.replace(&database.name, "nowhere");
    let cases = [
        ("mysql://u@127.0.0.1/x".to_string(), "mysql://"),
        ("postgres://u@127.0.0.1:port/x".to_string(), "invalid"),
        (format!("{}?sslmode=require", database.url), "TLS"),
        (format!("postgres://u@127.0.0.1:{closed}/x"), "127.0.0.1:"),
        (no_database, "\"nowhere\" does not exist"),
    ];
    for (url, says) in &cases {
        let e = Postgres::open(url, KEEP_ALL).err().expect("refused");
        let text = e.to_string();
        assert!(text.contains(says), "{url}: {text}");
        assert!(
            matches!(e, StoreError::DatabaseUrl(_) | StoreError::Connect { .. }),
            "{e:?}"
        );
    }
    // The binary says so and exits non-zero, quickly.
    for (url, says) in &cases[2..4] {
        let started = Instant::now();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_lasertag"))
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(["serve", "--addr", "127.0.0.1:0", "--no-showcase"])
            .args(["--database", url])
            .env("NO_COLOR", "1")
            .output()
            .expect("the binary runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{url}: {stderr}");
        assert!(stderr.contains("opening the history"), "{stderr}");
        assert!(stderr.contains(says), "{stderr}");
        assert!(started.elapsed() < Duration::from_secs(20));
    }
}

/// `id`'s row in `s`'s listing, waiting (the writer commits about once a second).
async fn listed(client: &reqwest::Client, s: &Server, id: &str) -> Value {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let (status, list) = get(client, s, "/api/replays").await;
        assert_eq!(status, 200, "{list}");
        if let Some(row) = list
            .as_array()
            .and_then(|l| l.iter().find(|r| r["id"] == id))
        {
            return row.clone();
        }
        assert!(Instant::now() < deadline, "{id} never listed: {list}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// The replay of `id` on `s` shows each of `states` at its tick (its end aside: a match
/// deleted at its last tick read "running" live then).
async fn replays_as_played(client: &reqwest::Client, s: &Server, id: &str, states: &[Value]) {
    for live in states {
        let tick = live["tick"].as_u64().unwrap();
        let path = format!("/api/replays/{id}/state?tick={tick}");
        let (status, mut replayed) = get(client, s, &path).await;
        assert_eq!(status, 200, "{replayed}");
        let mut live = live.clone();
        for v in [&mut replayed, &mut live] {
            v["status"] = Value::Null;
            v["winner"] = Value::Null;
        }
        assert_eq!(replayed, live, "{id} at tick {tick}");
    }
}

#[tokio::test]
async fn a_match_recorded_on_one_server_is_served_by_another() {
    let database = pg::database("fleet");
    let args = ["--no-showcase", "--database", database.url.as_str()];
    let client = reqwest::Client::new();
    let mut one = Server::start(&args);
    let two = Server::start(&args);

    // Played and ended on one, listed and replayed by two.
    let (done, token) = create(&client, &one, 1).await;
    let mut done_states = Vec::new();
    for _ in 0..3 {
        done_states.push(step(&client, &one, &done, &token, 100).await);
    }
    let r = client
        .delete(one.url(&format!("/api/matches/{done}")))
        .bearer_auth(&token)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 204);
    let row = listed(&client, &two, &done).await;
    assert_eq!(
        (row["complete"].clone(), row["reason"].clone()),
        (json!(true), json!("stopped"))
    );
    let (status, detail) = get(&client, &two, &format!("/api/replays/{done}")).await;
    assert_eq!(status, 200, "{detail}");
    assert!(detail["ticks"].as_u64().unwrap() >= 300, "{detail}");
    replays_as_played(&client, &two, &done, &done_states).await;

    // A match live on one while another server starts: left running.
    let (live, token) = create(&client, &one, 2).await;
    let live_states = vec![step(&client, &one, &live, &token, 100).await];
    let running = format!("SELECT (ended_at IS NULL)::TEXT FROM matches WHERE id = '{live}'");
    let stored_ticks = format!("SELECT ticks::TEXT FROM matches WHERE id = '{live}'");
    let deadline = Instant::now() + Duration::from_secs(20);
    // The task hands its inputs to the store about once a second.
    while database.query_text(&stored_ticks).as_deref() != Some("100") {
        assert!(
            Instant::now() < deadline,
            "the live match never reached the database"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    let three = Server::start(&args);
    assert_eq!(database.query_text(&running).as_deref(), Some("true"));
    let (_, list) = get(&client, &three, "/api/replays").await;
    assert!(!list.to_string().contains(&live), "{list}");

    // One dies; once its writer has been silent long enough, the next server to look closes
    // its match, and any server replays it up to its last stored tick.
    one.child.kill().expect("SIGKILL");
    one.child.wait().expect("the server dies");
    drop(three);
    database.sql(&format!(
        "UPDATE writers SET seen_at = now() - interval '1 hour'
         WHERE id = (SELECT writer FROM matches WHERE id = '{live}')"
    ));
    let four = Server::start(&args);
    // It looks at the store's matches as soon as it serves, on a task of its own: on a
    // loaded machine that comes a moment after its address is logged.
    let mut closed = None;
    for _ in 0..300 {
        closed = database.query_text(&running);
        if closed.as_deref() == Some("false") {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    assert_eq!(closed.as_deref(), Some("false"));
    let row = listed(&client, &two, &live).await;
    assert_eq!(
        (row["complete"].clone(), row["ticks"].clone()),
        (json!(false), json!(100))
    );
    replays_as_played(&client, &two, &live, &live_states).await;
    replays_as_played(&client, &four, &done, &done_states[..1]).await;
}

/// What the two backends cost the writer thread, for docs/operations.md:
/// `cargo test --test store_postgres -- --ignored --nocapture throughput`.
/// PostgreSQL here runs with fsync off (`-F`), and SQLite with `synchronous = NORMAL` in WAL
/// mode also commits without an fsync, so both are the cost of the work, not of the disk.
#[test]
#[ignore = "a measurement, not a check"]
fn throughput() {
    let database = pg::database("throughput");
    let dir = common::temp_dir("sqlite-throughput");
    let url = database.url.clone();
    let sqlite = || -> Box<dyn Backend> { Box::new(Sqlite::open(&dir, KEEP_ALL).expect("open")) };
    let postgres =
        || -> Box<dyn Backend> { Box::new(Postgres::open(&url, KEEP_ALL).expect("open")) };
    type Open<'a> = &'a dyn Fn() -> Box<dyn Backend>;
    let backends: [(&str, Open); 2] = [("SQLite", &sqlite), ("PostgreSQL", &postgres)];
    for (name, open) in backends {
        // Whole short matches (start, 200 inputs, end) through a store's writer thread.
        let store = Store::with(open(), open(), None);
        let n = 2000u64;
        let t = Instant::now();
        for i in 0..n {
            for w in a_match(&format!("{name}-m{i}"), 200, "ada", i.is_multiple_of(2)) {
                let mut w = w;
                while let Err(back) = store.send(w) {
                    w = *back;
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
        }
        store.flush(Duration::from_secs(120)).expect("flush");
        let whole = n as f64 / t.elapsed().as_secs_f64();
        // A second of 500 live matches: one batch of an append (20 inputs) each.
        let mut db = open();
        let live: Vec<String> = (0..500).map(|i| format!("{name}-live{i}")).collect();
        let begins: Vec<Write> = live
            .iter()
            .flat_map(|id| started(id, 0, "ada").into_iter().take(1))
            .collect();
        db.write(&begins).expect("begin");
        let mut batch_ms = Vec::new();
        for second in 1..=10u64 {
            let appends: Vec<Write> = live
                .iter()
                .map(|id| Write::Append {
                    id: id.clone(),
                    inputs: (second * 20..second * 20 + 20).map(keys).collect(),
                    names: None,
                    live: None,
                    tick: second * 20,
                })
                .collect();
            let t = Instant::now();
            db.write(&appends).expect("append");
            batch_ms.push(t.elapsed().as_secs_f64() * 1e3);
        }
        batch_ms.sort_by(f64::total_cmp);
        // One match at a time, a transaction each: the latency of a commit.
        let t = Instant::now();
        for i in 0..200 {
            db.write(&a_match(&format!("{name}-one{i}"), 20, "bob", false))
                .expect("write");
        }
        let commit_ms = t.elapsed().as_secs_f64() * 1e3 / 200.0;
        println!(
            "{name}: {whole:.0} whole matches/s through the writer; a batch of 500 appends \
             {:.1} ms (median of 10); one match a transaction {commit_ms:.2} ms",
            batch_ms[5]
        );
    }
}
