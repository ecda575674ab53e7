//! The fleet (`--fleet`, docs/operations.md "Fleet"): a real `redis-server` and real
//! `lasertag` processes on loopback.
//!
//! - One node's `GET /api/matches` lists every node's matches, each with the node that
//!   hosts it; a request for a match another node hosts is answered 307 to that node; a new
//!   match goes to the least-loaded node.
//! - A node killed with SIGKILL leaves every listing within the bound the docs give
//!   (`--fleet-ttl-s` + `--fleet-heartbeat-s`).
//! - A node sent SIGTERM with `--drain-s` is listed as draining at once, takes no new
//!   match, tells its players `finished` (`server_shutdown`) when the drain ends, leaves the
//!   directory and exits 0.
//! - In headless Chromium, the lobby of one node plays a match hosted on another.
//! - People who press *Play with others* on different nodes wait in one queue and play in
//!   one match: a page on one node and a client of another.
//! - With the fleet's shared PostgreSQL (`--database`), a match one node recorded is
//!   listed and replayed by another, state for state.
//!
//! Needs `redis-server`, PostgreSQL's server and Chromium: `bash tests/run.sh` installs both when
//! they are missing; without them these tests fail rather than pass unseen.

#![cfg(unix)]

#[path = "common/cdp.rs"]
#[allow(dead_code)]
mod cdp;
mod common;
#[path = "common/fleet_nodes.rs"]
mod fleet_nodes;
#[path = "common/postgres.rs"]
mod postgres;
#[path = "common/process.rs"]
mod process;
#[path = "common/redis_server.rs"]
mod redis_server;

use fleet_nodes::{HEARTBEAT_S, SLACK, TTL_S, create_here, no_redirects, node};

use std::process::Command;
use std::time::{Duration, Instant};

use common::{Got, Ws};
use process::Server;
use redis_server::RedisServer;
use serde_json::{Value, json};

async fn listing(client: &reqwest::Client, server: &Server) -> Vec<Value> {
    let r = client
        .get(server.url("/api/matches"))
        .send()
        .await
        .expect("the listing answers");
    assert_eq!(r.status(), 200);
    r.json().await.expect("a JSON listing")
}

/// The ids a listing shows as hosted on `node`.
fn hosted_on(listing: &[Value], node: &str) -> Vec<String> {
    listing
        .iter()
        .filter(|m| m["node"]["id"] == node)
        .map(|m| m["id"].as_str().unwrap_or_default().to_owned())
        .collect()
}

/// Polls `check` every 50 ms until it holds, failing after `secs`; returns when it held.
async fn until<F, Fut>(secs: u64, what: &str, mut check: F) -> Instant
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = bool>,
{
    let started = Instant::now();
    loop {
        if check().await {
            return Instant::now();
        }
        assert!(
            started.elapsed() < Duration::from_secs(secs),
            "{what}: not within {secs} s"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

/// Waits until the page plays match `id` as a player, its snapshots coming.
async fn playing(browser: &mut cdp::Browser, id: &str) {
    browser
        .wait_for(
            &format!(
                "__lasertag.matchId === '{id}' && __lasertag.role === 'player' && __lasertag.connected && __lasertag.snapshots > 5"
            ),
            30,
        )
        .await;
}

/// `server`'s metrics, as Prometheus reads them.
async fn metrics_of(http: &reqwest::Client, server: &Server) -> String {
    let r = http.get(server.url("/metrics")).send().await;
    r.expect("the metrics answer").text().await.expect("text")
}

fn metric(text: &str, name: &str) -> Option<f64> {
    text.lines()
        .find_map(|l| l.strip_prefix(name)?.trim().parse().ok())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_nodes_list_redirect_place_lose_a_killed_node_and_drain_one() {
    let redis = RedisServer::start();
    let a = node(&redis, "a", &[]);
    let b = node(&redis, "b", &["--drain-s", "3"]);
    let mut c = node(&redis, "c", &[]);
    let http = reqwest::Client::new();
    let raw = no_redirects();

    // A match on each node: manual ones on a and c, one people play on b.
    let on_a = create_here(&http, &a, json!({"map": "office", "clock": "manual"})).await;
    let on_b = create_here(
        &http,
        &b,
        json!({"map": "office", "opponent_control": "human", "planner": "idle",
            "time_limit_s": 120, "spectator_delay_s": 0}),
    )
    .await;
    let on_c = create_here(&http, &c, json!({"map": "office", "clock": "manual"})).await;
    assert_eq!(on_b["node"]["id"], "b", "{on_b}");
    assert_eq!(on_b["node"]["local"], true);
    let id = |m: &Value| m["id"].as_str().unwrap().to_owned();
    let (id_a, id_b, id_c) = (id(&on_a), id(&on_b), id(&on_c));

    // 1. Any node's lobby lists every node's matches, each with the node that hosts it.
    for lobby in [&a, &b, &c] {
        until(10, "every match listed", || async {
            listing(&http, lobby).await.len() == 3
        })
        .await;
    }
    let all = listing(&http, &a).await;
    for (m, node, server) in [(&id_a, "a", &a), (&id_b, "b", &b), (&id_c, "c", &c)] {
        let listed = all.iter().find(|x| x["id"] == m.as_str()).expect("listed");
        assert_eq!(listed["node"]["id"], node, "{listed}");
        assert_eq!(listed["node"]["url"], server.url(""), "{listed}");
        assert_eq!(listed["node"]["local"], node == "a", "{listed}");
        assert_eq!(listed["node"]["draining"], false, "{listed}");
        assert_eq!(
            listed["map"], "office",
            "other nodes' summaries are whole: {listed}"
        );
    }
    let metrics = metrics_of(&http, &a).await;
    assert_eq!(metric(&metrics, "lasertag_fleet_nodes"), Some(3.0));
    assert!(metric(&metrics, "lasertag_fleet_redis_round_trips_total") > Some(0.0));

    // 2. A request for b's match on a is sent to b: 307, the same path, the node named.
    let r = raw
        .get(a.url(&format!("/api/matches/{id_b}/stats?x=1")))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 307);
    let location = r.headers()["location"].to_str().unwrap().to_owned();
    assert_eq!(location, b.url(&format!("/api/matches/{id_b}/stats?x=1")));
    assert_eq!(
        r.headers()["access-control-allow-origin"],
        "*",
        "a page may read it"
    );
    let body: Value = r.json().await.unwrap();
    assert_eq!(body["node"]["id"], "b", "{body}");
    assert_eq!(body["location"], location.as_str());
    // So is the WebSocket (which a browser cannot follow: the page goes to b itself).
    match tokio_tungstenite::connect_async(format!("ws://{}/ws/matches/{id_b}", a.addr)).await {
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => assert_eq!(r.status(), 307),
        other => panic!("expected a 307 to the socket on b: {other:?}"),
    }
    // A match nobody holds is a 404, as outside a fleet.
    let r = raw
        .get(a.url("/api/matches/0123456789abcdef"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 404);
    // Joining through a, following the redirect as HTTP clients do, takes a seat on b.
    let r = http
        .post(a.url(&format!("/api/matches/{id_b}/players")))
        .json(&json!({"name": "alice"}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    let joined: Value = r.json().await.unwrap();
    let token = joined["token"].as_str().unwrap();
    let (stream, _) = tokio_tungstenite::connect_async(format!(
        "ws://{}/ws/matches/{id_b}?token={token}",
        b.addr
    ))
    .await
    .expect("the player's socket on b");
    let mut player = Ws { stream };
    player.next_of("snapshot").await;

    // 3. A new match goes to the least-loaded node with room. One each: a keeps it (a tie
    // stays); a then holds 2, so the next goes to b (the first of the emptiest, by id).
    let post_a = || {
        raw.post(a.url("/api/matches"))
            .json(&json!({"map": "office", "clock": "manual"}))
            .send()
    };
    let created: Value = http
        .post(a.url("/api/matches"))
        .json(&json!({"map": "office", "clock": "manual"}))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(created["node"]["id"], "a", "{created}");
    let r = post_a().await.unwrap();
    assert_eq!(r.status(), 307);
    let location = r.headers()["location"].to_str().unwrap().to_owned();
    assert_eq!(location, b.url("/api/matches?place=local"));
    // The same request to `Location` creates it there.
    let placed: Value = http
        .post(&location)
        .json(&json!({"map": "office", "clock": "manual"}))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(placed["node"]["id"], "b", "{placed}");
    let placed = id(&placed);
    until(10, "a hears of b's new match", || async {
        hosted_on(&listing(&http, &a).await, "b").contains(&placed)
    })
    .await;
    // b holds 2 now, as does a: c is the emptiest.
    let r = post_a().await.unwrap();
    assert_eq!(r.status(), 307);
    assert_eq!(
        r.headers()["location"].to_str().unwrap(),
        c.url("/api/matches?place=local")
    );
    let r = raw
        .post(a.url("/api/matches?place=nowhere"))
        .json(&json!({"map": "office"}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 400);

    // 4. SIGKILL c: its key expires and every lobby drops it within TTL + heartbeat.
    c.child.kill().expect("SIGKILL");
    let killed = Instant::now();
    let gone = until(20, "the killed node leaves a's listing", || async {
        hosted_on(&listing(&http, &a).await, "c").is_empty()
    })
    .await;
    let took = gone - killed;
    let bound = Duration::from_secs_f64(TTL_S + HEARTBEAT_S);
    eprintln!("a SIGKILLed node left the listing {took:?} after the kill (bound {bound:?})");
    assert!(took <= bound + SLACK, "{took:?} > {bound:?} + {SLACK:?}");
    let _ = c.child.wait();

    // 5. SIGTERM b, which drains for 3 s: listed as draining at once; no new match.
    let status = Command::new("kill")
        .args(["-TERM", &b.child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
    let signalled = Instant::now();
    until(5, "a lists b as draining", || async {
        let all = listing(&http, &a).await;
        all.iter()
            .filter(|m| m["node"]["id"] == "b")
            .all(|m| m["node"]["draining"] == true)
            && !hosted_on(&all, "b").is_empty()
    })
    .await;
    let r = http
        .post(b.url("/api/matches?place=local"))
        .json(&json!({"map": "office", "clock": "manual"}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 503, "a draining node takes no new match");
    let r = raw
        .post(b.url("/api/matches"))
        .json(&json!({"map": "office", "clock": "manual"}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 307, "it sends new matches to a node with room");
    assert_eq!(
        r.headers()["location"].to_str().unwrap(),
        a.url("/api/matches?place=local")
    );
    // Its player plays on, then is told why the match ended and the socket closes.
    let finished = loop {
        match player.next().await {
            Got::Json(v) if v["type"] == "finished" => break v,
            Got::Json(_) => {}
            other => panic!("the player's socket ended without `finished`: {other:?}"),
        }
    };
    assert_eq!(finished["reason"], "server_shutdown", "{finished}");
    assert!(
        signalled.elapsed() >= Duration::from_millis(2500),
        "the match went on through the drain: ended after {:?}",
        signalled.elapsed()
    );
    let mut b = b;
    let exit = loop {
        if let Some(status) = b.child.try_wait().unwrap() {
            break status;
        }
        assert!(
            signalled.elapsed() < Duration::from_secs(3 + 5),
            "b still running 5 s after its drain"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    assert!(exit.success(), "{exit}");
    // It deleted its key on the way out (rather than leaving it to expire)...
    let mut redis_client = redis::Client::open(redis.url())
        .unwrap()
        .get_multiplexed_async_connection()
        .await
        .unwrap();
    let exists: i64 = redis::cmd("EXISTS")
        .arg("lasertag:fleet:node:b")
        .query_async(&mut redis_client)
        .await
        .unwrap();
    assert_eq!(exists, 0, "b's key is gone");
    // ...so its matches leave a's listing at a's next read.
    until(5, "b's matches leave a's listing", || async {
        hosted_on(&listing(&http, &a).await, "b").is_empty()
    })
    .await;
    let left = listing(&http, &a).await;
    assert!(left.iter().all(|m| m["node"]["id"] == "a"), "{left:?}");
}

/// A page opened on node a plays a match hosted on node b: the lobby lists it with its
/// node, Play joins on b (a cross-origin request) and opens the socket there, and the
/// player's keys move its opponent on b.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_page_on_one_node_plays_a_match_hosted_on_another() {
    let redis = RedisServer::start();
    let a = node(&redis, "a", &[]);
    let b = node(&redis, "b", &[]);
    let http = reqwest::Client::new();
    // A robot idles far away: the player is free to move.
    let created = create_here(
        &http,
        &b,
        json!({"map": "office", "robots": 1, "opponents": 1, "opponent_control": "human",
            "planner": "idle", "time_limit_s": 120, "spectator_delay_s": 0,
            "robot_starts": [[22.0, 1.5, 0.0]], "opponent_starts": [[3.0, 8.0]]}),
    )
    .await;
    let id = created["id"].as_str().unwrap().to_owned();
    let owner = created["owner_token"].as_str().unwrap().to_owned();
    let opponent = || async {
        let r: Value = http
            .get(b.url(&format!("/api/matches/{id}")))
            .bearer_auth(&owner)
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        r["opponents"][0].clone()
    };

    let mut browser = cdp::Browser::launch().await;
    browser.navigate(&a.url("/")).await;
    let row = format!("document.querySelector('#matches tbody tr[data-id=\"{id}\"]')");
    let cell = browser
        .wait_for(&format!("{row} && {row}.cells[0].textContent"), 20)
        .await;
    browser
        .eval("document.getElementById('name').value = 'visitor'")
        .await;
    assert!(
        cell.as_str().is_some_and(|c| c.ends_with(" · b")),
        "the lobby names the node: {cell}"
    );
    browser
        .eval(&format!("{row}.querySelector('button.play').click()"))
        .await;
    playing(&mut browser, &id).await;
    assert_eq!(browser.eval("__lasertag.base").await, json!(b.url("")));
    assert_eq!(browser.eval("location.origin").await, json!(a.url("")));
    let on_b = listing(&http, &b).await;
    let listed = on_b
        .iter()
        .find(|m| m["id"] == id.as_str())
        .expect("listed");
    assert_eq!(listed["players"], 1, "seated on b: {listed}");
    let before = opponent().await;
    browser.key("KeyW", true).await;
    tokio::time::sleep(Duration::from_millis(800)).await;
    browser.key("KeyW", false).await;
    tokio::time::sleep(Duration::from_millis(200)).await;
    let after = opponent().await;
    let moved = (after["x"].as_f64().unwrap() - before["x"].as_f64().unwrap()).abs()
        + (after["y"].as_f64().unwrap() - before["y"].as_f64().unwrap()).abs();
    assert!(moved > 0.2, "moved {moved} m on b: {before} -> {after}");
    let errors = browser.eval("__lasertag.errors").await;
    assert_eq!(errors, json!([]), "{errors}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn people_who_queue_on_different_nodes_play_together() {
    let redis = RedisServer::start();
    let a = node(&redis, "a", &[]);
    let b = node(&redis, "b", &[]);
    let http = reqwest::Client::new();
    until(10, "b sees a", || async {
        metric(&metrics_of(&http, &b).await, "lasertag_fleet_nodes") == Some(2.0)
    })
    .await;
    // The queue is the lowest id's: b sends its newcomers to a.
    let r = no_redirects()
        .post(b.url("/api/queue"))
        .json(&json!({"name": "looker"}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 307);
    assert_eq!(r.headers()["location"], a.url("/api/queue").as_str());

    // A page served by b presses *Play with others*.
    let mut browser = cdp::Browser::launch().await;
    browser.navigate(&b.url("/")).await;
    browser
        .wait_for("window.__lasertag && __lasertag.page === 'lobby'", 20)
        .await;
    browser
        .eval("document.getElementById('name').value = 'visitor'; document.getElementById('door-queue').click()")
        .await;
    browser
        .wait_for("__lasertag.queue && __lasertag.queue.people !== null", 20)
        .await;
    assert_eq!(
        browser.eval("__lasertag.queue.base").await,
        json!(a.url(""))
    );

    // A client of b joins too (following the 307), and waits on a.
    let r = http
        .post(b.url("/api/queue"))
        .json(&json!({"name": "friend"}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 202);
    assert!(r.url().as_str().starts_with(&a.url("")), "{}", r.url());
    let ticket: Value = r.json().await.unwrap();
    let url = format!(
        "{}/ws/queue/{}?token={}",
        a.url("").replacen("http", "ws", 1),
        ticket["ticket"].as_str().unwrap(),
        ticket["token"].as_str().unwrap()
    );
    let (stream, _) = tokio_tungstenite::connect_async(url).await.unwrap();
    let mut ws = Ws { stream };
    let seat = loop {
        match ws.next().await {
            Got::Json(v) if v["type"] == "waiting" => {}
            Got::Json(v) if v["type"] == "matched" => break v,
            other => panic!("{other:?}"),
        }
    };
    let id = seat["match_id"].as_str().unwrap().to_owned();
    // The page plays the same match, on a.
    playing(&mut browser, &id).await;
    assert_eq!(browser.eval("__lasertag.base").await, json!(a.url("")));
    let on_a = listing(&http, &a).await;
    let listed = on_a
        .iter()
        .find(|m| m["id"] == id.as_str())
        .expect("listed");
    assert_eq!(listed["node"]["id"], "a", "{listed}");
    assert!(
        listed["players"].as_u64() >= Some(1),
        "the page is seated: {listed}"
    );
    let errors = browser.eval("__lasertag.errors").await;
    assert_eq!(errors, json!([]), "{errors}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_replay_recorded_on_one_node_is_served_by_another() {
    let redis = RedisServer::start();
    // The PostgreSQL client blocks on a runtime of its own: not on this test's.
    let db = std::thread::spawn(|| postgres::database("fleet_replay"))
        .join()
        .expect("a database");
    let (b, c) = (
        node(&redis, "b", &["--database", &db.url]),
        node(&redis, "c", &["--database", &db.url]),
    );
    let http = no_redirects();
    // A short manual match on b, played to its end.
    let created = create_here(
        &http,
        &b,
        json!({"map": "office", "clock": "manual", "time_limit_s": 2, "seed": 7}),
    )
    .await;
    let id = created["id"].as_str().expect("an id").to_owned();
    let stepped = http
        .post(b.url(&format!("/api/matches/{id}/step")))
        .bearer_auth(created["owner_token"].as_str().expect("an owner token"))
        .json(&json!({"ticks": 100}))
        .send()
        .await
        .expect("b answers");
    assert_eq!(stepped.status(), 200);
    let ended: Value = stepped.json().await.expect("JSON");
    assert_eq!(ended["status"], "finished", "{ended}");

    // c never hosted it: it reads it from the shared database once b's writer has.
    until(20, "c lists b's ended match among the replays", || {
        let (http, url) = (http.clone(), c.url("/api/replays"));
        let id = id.clone();
        async move {
            let Ok(r) = http.get(url).send().await else {
                return false;
            };
            let listed: Value = r.json().await.unwrap_or(Value::Null);
            listed.as_array().is_some_and(|all| {
                all.iter()
                    .any(|m| m["id"] == id.as_str() && m["complete"] == true)
            })
        }
    })
    .await;
    for tick in [0, 17, 40] {
        let path = format!("/api/replays/{id}/state?tick={tick}");
        let on_c = http.get(c.url(&path)).send().await.expect("c answers");
        assert_eq!(on_c.status(), 200, "{path} on c");
        let on_b = http.get(b.url(&path)).send().await.expect("b answers");
        assert_eq!(on_b.status(), 200, "{path} on b");
        let (on_c, on_b): (Value, Value) = (on_c.json().await.unwrap(), on_b.json().await.unwrap());
        assert_eq!(on_c["tick"], tick);
        assert_eq!(on_c, on_b, "{path}: c and b replay the match alike");
    }
}
