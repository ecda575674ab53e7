//! A fleet on a shared PostgreSQL store takes over the matches of a node that cannot run
//! them (docs/operations.md, "Matches survive their server"): real `redis-server`,
//! PostgreSQL and `lasertag` processes on loopback.
//!
//! - A node killed with SIGKILL: once its lease has run out another node adopts its running
//!   matches (same ids and tokens, from their last stored tick), and the lobby points there;
//!   a match driven by a policy uploaded to the dead node plays on by it.
//! - A node that stops (SIGTERM) hands its matches to a node with room: its clients get
//!   `moved` with that node's URL before the close, and the match goes on there.
//! - A node paused with SIGSTOP past its lease loses its match to another and, woken with
//!   SIGCONT, stops it and writes nothing more to it (its fence is gone).
//! - A node that adopted matches, one of which then finished, drains and hands the other
//!   over without a warning: nothing more of the finished match is written, and it is not
//!   "suspended".
//!
//! Needs `redis-server` and PostgreSQL's server (`bash tests/run.sh` installs them).

#![cfg(unix)]

mod common;
#[path = "common/fleet_nodes.rs"]
mod fleet_nodes;
#[path = "common/postgres.rs"]
mod postgres;
#[path = "common/process.rs"]
mod process;
#[path = "common/redis_server.rs"]
mod redis_server;

use std::process::Command;
use std::time::{Duration, Instant};

use common::{Got, Ws};
use process::Server;
use redis_server::RedisServer;
use serde_json::{Value, json};

/// A node on the shared store `db`.
fn on(redis: &RedisServer, db: &str, id: &str) -> Server {
    fleet_nodes::node(redis, id, &["--database", db])
}

/// A match made on `s` itself: (id, owner token).
async fn made_on(http: &reqwest::Client, s: &Server, body: Value) -> (String, String) {
    let v = fleet_nodes::create_here(http, s, body).await;
    (
        v["id"].as_str().unwrap().to_string(),
        v["owner_token"].as_str().unwrap().to_string(),
    )
}

/// Waits (at most `secs`) until `s` itself runs match `id`: a 200 without a redirect.
async fn until_hosted(
    http: &reqwest::Client,
    s: &Server,
    id: &str,
    token: Option<&str>,
    secs: u64,
) -> Value {
    let start = Instant::now();
    loop {
        let mut r = http.get(s.url(&format!("/api/matches/{id}")));
        if let Some(t) = token {
            r = r.bearer_auth(t);
        }
        if let Ok(r) = r.send().await
            && r.status() == 200
        {
            return r.json().await.expect("JSON");
        }
        assert!(
            start.elapsed() < Duration::from_secs(secs),
            "{id} not run by {} within {secs} s",
            s.addr
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

fn signal(s: &Server, sig: &str) {
    let status = Command::new("kill")
        .args([sig, &s.child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dead_nodes_matches_are_adopted_and_a_stopping_node_hands_its_over() {
    let redis = RedisServer::start();
    let db = std::thread::spawn(|| postgres::database("adoption"))
        .join()
        .expect("a database");
    let mut a = on(&redis, &db.url, "a");
    let b = on(&redis, &db.url, "b");
    let http = fleet_nodes::no_redirects();
    let (live, _) = made_on(
        &http,
        &a,
        json!({"map": "office", "robots": 2, "opponents": 2, "opponent_bot": "evade",
            "seed": 4, "time_limit_s": 600}),
    )
    .await;
    let (manual, token) = made_on(
        &http,
        &a,
        json!({"map": "office", "clock": "manual", "seed": 8, "opponent_bot": "evade"}),
    )
    .await;
    let stepped = process::step(&http, &a, &manual, &token, 200).await;
    // A policy uploaded to a after b started, and a match it drives.
    let r = http
        .post(a.url("/api/policies?name=uploaded-on-a"))
        .header("content-type", "application/onnx")
        .body(common::small_policy())
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let driven_body = json!({"map": "office", "clock": "manual", "seed": 9,
        "planner": "policy:uploaded-on-a"});
    let (driven, driven_token) = made_on(&http, &a, driven_body.clone()).await;
    tokio::time::sleep(Duration::from_millis(1600)).await; // the store has it
    a.child.kill().expect("SIGKILL");
    a.child.wait().expect("a dies");
    let killed = Instant::now();

    // b takes both once a's lease has run out (10 s), at its next look (every 2 s).
    let state = until_hosted(&http, &b, &manual, Some(&token), 30).await;
    eprintln!("adopted {:?} after the kill", killed.elapsed());
    assert_eq!(state["tick"], 200, "{state}");
    assert_eq!(
        state["robots"], stepped["robots"],
        "the same match, as it was"
    );
    let running = until_hosted(&http, &b, &live, None, 10).await;
    assert_eq!(running["status"], "running", "{running}");
    // b loaded the policy it lacked with the match it drives, which plays on by it as its
    // twin started on b does.
    until_hosted(&http, &b, &driven, Some(&driven_token), 10).await;
    let (twin, twin_token) = made_on(&http, &b, driven_body).await;
    let mut states = Vec::new();
    for (id, token) in [(&driven, &driven_token), (&twin, &twin_token)] {
        let state = process::step(&http, &b, id, token, 60).await;
        assert_eq!(state["policy"], "uploaded-on-a", "{state}");
        states.push(state["robots"].clone());
    }
    assert_eq!(states[0], states[1], "the adopted match plays as its twin");
    // The owner token still changes it, on b.
    let r = http
        .post(b.url(&format!("/api/matches/{manual}/step")))
        .bearer_auth(&token)
        .json(&json!({"ticks": 5}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    // b's lobby lists them as its own.
    let listing: Value = http
        .get(b.url("/api/matches"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    for id in [&live, &manual] {
        let m = listing
            .as_array()
            .unwrap()
            .iter()
            .find(|m| m["id"] == id.as_str())
            .unwrap_or_else(|| panic!("{id} listed: {listing}"));
        assert_eq!(m["node"]["id"], "b", "{m}");
    }

    // b stops: its matches go to c, and b's spectator is told where.
    let c = on(&redis, &db.url, "c");
    tokio::time::sleep(Duration::from_secs(2)).await; // b sees c in the directory
    let (stream, _) =
        tokio_tungstenite::connect_async(format!("ws://{}/ws/matches/{live}", b.addr))
            .await
            .expect("a spectator on b");
    let mut spectator = Ws { stream };
    spectator.next_of("snapshot").await;
    signal(&b, "-TERM");
    let moved = loop {
        match spectator.next().await {
            Got::Json(v) if v["type"] == "moved" => break v,
            Got::Json(_) => {}
            other => panic!("closed without `moved`: {other:?}"),
        }
    };
    assert_eq!(moved["url"], format!("http://{}", c.addr), "{moved}");
    assert!(matches!(
        spectator.next().await,
        Got::Closed { code: 1012, .. }
    ));
    let running = until_hosted(&http, &c, &live, None, 15).await;
    assert_eq!(running["status"], "running", "{running}");
    until_hosted(&http, &c, &manual, Some(&token), 15).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_paused_past_its_lease_loses_its_match_and_writes_nothing_more_to_it() {
    let redis = RedisServer::start();
    let db = std::thread::spawn(|| postgres::database("adoption_paused"))
        .join()
        .expect("a database");
    let d = on(&redis, &db.url, "d");
    let e = on(&redis, &db.url, "e");
    let http = fleet_nodes::no_redirects();
    let (id, _) = made_on(
        &http,
        &d,
        json!({"map": "office", "robots": 2, "opponents": 2, "opponent_bot": "evade",
            "seed": 6, "time_limit_s": 600}),
    )
    .await;
    tokio::time::sleep(Duration::from_millis(1600)).await;
    let holder = |db: &postgres::Database| {
        let id = id.clone();
        let q = format!("SELECT writer || ':' || fence FROM matches WHERE id = '{id}'");
        db.query_text(&q).expect("the match's row")
    };
    let before = holder(&db);
    assert!(before.ends_with(":0"), "{before}");

    signal(&d, "-STOP");
    until_hosted(&http, &e, &id, None, 30).await;
    let taken = holder(&db);
    assert_ne!(taken, before, "e holds it now");
    assert!(taken.ends_with(":1"), "{taken}");
    let ticks_on_e = || {
        db.query_text(&format!(
            "SELECT ticks::TEXT FROM matches WHERE id = '{id}'"
        ))
        .and_then(|t| t.parse::<u64>().ok())
        .unwrap_or(0)
    };
    signal(&d, "-CONT");
    // d wakes up with the match in memory and its lease long gone: it stops it.
    tokio::time::sleep(Duration::from_secs(3)).await;
    assert_eq!(holder(&db), taken, "d took nothing back");
    let r = http
        .get(d.url(&format!("/api/matches/{id}")))
        .send()
        .await
        .unwrap();
    assert_ne!(r.status(), 200, "d no longer runs it");
    // The match goes on on e alone.
    let t0 = ticks_on_e();
    tokio::time::sleep(Duration::from_millis(2500)).await;
    assert!(ticks_on_e() > t0, "e's record moves on");
    assert_eq!(holder(&db), taken);
    let metrics = reqwest::get(d.url("/metrics"))
        .await
        .unwrap()
        .text()
        .await
        .unwrap();
    assert!(
        metrics.contains("lasertag_matches_removed_total{reason=\"moved\"} 1"),
        "{}",
        metrics
            .lines()
            .filter(|l| l.contains("removed"))
            .collect::<Vec<_>>()
            .join("\n")
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_drain_after_an_adoption_whose_match_finished_warns_of_nothing() {
    let redis = RedisServer::start();
    let db = std::thread::spawn(|| postgres::database("adoption_drain"))
        .join()
        .expect("a database");
    let mut p = on(&redis, &db.url, "p");
    let q = fleet_nodes::node(
        &redis,
        "q",
        &["--database", db.url.as_str(), "--drain-s", "3"],
    );
    let http = fleet_nodes::no_redirects();
    let (ends, token) = made_on(
        &http,
        &p,
        json!({"map": "office", "clock": "manual", "seed": 5, "opponent_bot": "evade",
            "time_limit_s": 10}),
    )
    .await;
    process::step(&http, &p, &ends, &token, 100).await;
    let (lasts, _) = made_on(
        &http,
        &p,
        json!({"map": "office", "robots": 2, "opponents": 2, "opponent_bot": "evade",
            "seed": 7, "time_limit_s": 600}),
    )
    .await;
    tokio::time::sleep(Duration::from_millis(1600)).await; // the store has them
    p.child.kill().expect("SIGKILL");
    p.child.wait().expect("p dies");

    until_hosted(&http, &q, &ends, Some(&token), 30).await;
    until_hosted(&http, &q, &lasts, None, 10).await;
    // The adopted match ends on q (its time limit is tick 200), and stays listed a while.
    let state = process::step(&http, &q, &ends, &token, 150).await;
    assert_eq!(state["status"], "finished", "{state}");
    // A few seconds of q's housekeeping with it finished.
    tokio::time::sleep(Duration::from_secs(3)).await;
    let r = on(&redis, &db.url, "r");
    tokio::time::sleep(Duration::from_secs(2)).await; // q sees r in the directory
    signal(&q, "-TERM");
    // The drain (3 s, for the running match), then the hand-over to r.
    until_hosted(&http, &r, &lasts, None, 30).await;
    let mut q = q;
    let _ = q.child.wait();
    tokio::time::sleep(Duration::from_millis(300)).await; // the log's last lines read
    let warned = q.warnings.lock().unwrap_or_else(|e| e.into_inner()).clone();
    assert_eq!(warned, Vec::<String>::new());
    let log = q.log.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let suspended: Vec<&String> = log.iter().filter(|l| l.contains("suspended")).collect();
    assert_eq!(suspended.len(), 1, "{suspended:?}");
    assert!(suspended[0].contains(&lasts), "{suspended:?}");
    assert!(
        log.iter().any(|l| l.contains("matches handed over")),
        "{log:?}"
    );
}
