//! Matches survive their server (the API spec's "Matches survive their server"): the real
//! binary is killed with SIGKILL in the middle of play and started again on the same store;
//! every match comes back under its id and tokens, from its last stored tick, and goes on as
//! the same match would have gone on had nothing happened (its twin, started afresh with
//! the same seed and inputs, is the witness). An uploaded policy outlives its server too,
//! and drives its match on.
//!
//! Long file: every test here kills and starts the real binary on one store, and they share
//! the helpers that read a match and compare it with its twin.

#![cfg(unix)]

mod common;
#[path = "common/process.rs"]
mod process;

use std::time::Duration;

use common::{Got, Ws};
use process::Server;
use serde_json::{Value, json};

/// A server on the store in `dir`.
fn serve(dir: &std::path::Path) -> Server {
    Server::start(&["--no-showcase", "--data-dir", &dir.display().to_string()])
}

/// A server on the store in `dir` that takes requests as fast as one client sends them.
fn serve_unthrottled(dir: &std::path::Path) -> Server {
    Server::start_with_env(
        &["--no-showcase", "--data-dir", &dir.display().to_string()],
        &[
            ("LASERTAG_REQUESTS_PER_S", "1000000"),
            ("LASERTAG_REQUEST_BURST", "1000000"),
        ],
    )
}

/// SIGKILL: no shutdown, no last write.
fn kill(s: &mut Server) {
    s.child.kill().expect("SIGKILL");
    s.child.wait().expect("the server dies");
}

/// What a match task has sent the store is at most a second behind: wait that out.
async fn stored() {
    tokio::time::sleep(Duration::from_millis(1600)).await;
}

async fn send(
    client: &reqwest::Client,
    method: reqwest::Method,
    s: &Server,
    path: &str,
    token: Option<&str>,
    body: Option<Value>,
) -> (u16, Value, Option<String>) {
    let mut r = client.request(method, s.url(path));
    if let Some(t) = token {
        r = r.bearer_auth(t);
    }
    if let Some(b) = body {
        r = r.json(&b);
    }
    let r = r.send().await.unwrap();
    let retry = r
        .headers()
        .get("retry-after")
        .map(|v| v.to_str().unwrap().to_string());
    (
        r.status().as_u16(),
        r.json().await.unwrap_or(Value::Null),
        retry,
    )
}

/// `GET path` once the match is back: a 503 while it is being resumed must say when to
/// ask again.
async fn when_back(client: &reqwest::Client, s: &Server, path: &str, token: Option<&str>) -> Value {
    for _ in 0..600 {
        let (status, body, retry) = send(client, reqwest::Method::GET, s, path, token, None).await;
        match status {
            200 => return body,
            503 => {
                assert_eq!(retry.as_deref(), Some("1"), "503 while resuming: {body}");
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
            other => panic!("GET {path}: {other} {body}"),
        }
    }
    panic!("{path} not back within 30 s");
}

async fn create(client: &reqwest::Client, s: &Server, body: Value) -> (String, String) {
    let (status, r, _) = send(
        client,
        reqwest::Method::POST,
        s,
        "/api/matches",
        None,
        Some(body),
    )
    .await;
    assert_eq!(status, 201, "{r}");
    (
        r["id"].as_str().unwrap().to_string(),
        r["owner_token"].as_str().unwrap().to_string(),
    )
}

async fn step(client: &reqwest::Client, s: &Server, id: &str, token: &str, ticks: u64) -> Value {
    let path = format!("/api/matches/{id}/step");
    let (status, r, _) = send(
        client,
        reqwest::Method::POST,
        s,
        &path,
        Some(token),
        Some(json!({"ticks": ticks})),
    )
    .await;
    assert_eq!(status, 200, "{r}");
    r
}

/// A match's state, belief and events with what names the match itself taken out, for
/// comparing a match with its twin.
async fn reading(client: &reqwest::Client, s: &Server, id: &str, token: &str) -> Value {
    let get = |path: String| async move {
        let (status, v, _) = send(client, reqwest::Method::GET, s, &path, Some(token), None).await;
        assert_eq!(status, 200, "{path}: {v}");
        v
    };
    let mut state = get(format!("/api/matches/{id}")).await;
    let belief = get(format!("/api/matches/{id}/belief")).await;
    let events = get(format!("/api/matches/{id}/events")).await;
    for k in ["id", "created_at", "started_at", "spectators", "node"] {
        state.as_object_mut().unwrap().remove(k);
    }
    json!({"state": state, "belief": belief, "events": events["events"]})
}

#[tokio::test]
async fn a_manual_match_killed_with_sigkill_resumes_and_goes_on_as_its_twin() {
    let dir = common::temp_dir("resume-manual");
    let client = reqwest::Client::new();
    let body = json!({"map": "office", "clock": "manual", "seed": 11, "robots": 2,
        "opponents": 2, "opponent_bot": "evade"});
    let mut a = serve(&dir);
    let (id, token) = create(&client, &a, body.clone()).await;
    step(&client, &a, &id, &token, 300).await;
    let before = reading(&client, &a, &id, &token).await;
    stored().await;
    kill(&mut a);

    let b = serve(&dir);
    when_back(&client, &b, &format!("/api/matches/{id}"), None).await;
    // Same id, same owner token, the same match at the same tick.
    let resumed = reading(&client, &b, &id, &token).await;
    assert_eq!(resumed["state"]["tick"], 300);
    assert_eq!(resumed, before, "the match as it was before the kill");
    // A stranger's token changes nothing (the owner token is stored only as a hash).
    let (status, _, _) = send(
        &client,
        reqwest::Method::POST,
        &b,
        &format!("/api/matches/{id}/step"),
        Some("0123456789abcdef0123456789abcdef"),
        Some(json!({"ticks": 1})),
    )
    .await;
    assert_eq!(status, 403);

    // Its twin never stopped.
    let (twin, twin_token) = create(&client, &b, body).await;
    step(&client, &b, &twin, &twin_token, 300).await;
    for ticks in [1, 49, 400] {
        step(&client, &b, &id, &token, ticks).await;
        step(&client, &b, &twin, &twin_token, ticks).await;
        let (one, other) = (
            reading(&client, &b, &id, &token).await,
            reading(&client, &b, &twin, &twin_token).await,
        );
        assert_eq!(one, other, "after {ticks} more ticks");
    }
}

#[tokio::test]
async fn a_bots_match_killed_with_sigkill_ends_with_its_twins_winner_at_its_tick() {
    let dir = common::temp_dir("resume-bots");
    let client = reqwest::Client::new();
    let settings = json!({"map": "office", "seed": 5, "robots": 2, "opponents": 2,
        "opponent_bot": "wander", "time_limit_s": 25});
    let mut a = serve(&dir);
    let (id, _) = create(&client, &a, settings.clone()).await;
    tokio::time::sleep(Duration::from_secs(3)).await;
    let (_, live, _) = send(
        &client,
        reqwest::Method::GET,
        &a,
        &format!("/api/matches/{id}"),
        None,
        None,
    )
    .await;
    assert_eq!(
        live["status"], "running",
        "the kill comes mid-match: {live}"
    );
    stored().await;
    kill(&mut a);

    let b = serve(&dir);
    let back = when_back(&client, &b, &format!("/api/matches/{id}"), None).await;
    assert!(back["tick"].as_u64().unwrap() >= 60, "{back}");
    // The twin: the same match stepped by hand to its end.
    let mut twin_settings = settings;
    twin_settings["clock"] = json!("manual");
    let (twin, twin_token) = create(&client, &b, twin_settings).await;
    let twin_end = step(&client, &b, &twin, &twin_token, 100_000).await;
    assert_eq!(twin_end["status"], "finished");
    // Once over, its replay says how it ended.
    let end = loop {
        let (status, v, _) = send(
            &client,
            reqwest::Method::GET,
            &b,
            &format!("/api/replays/{id}"),
            None,
            None,
        )
        .await;
        if status == 200 {
            break v;
        }
        assert_eq!(status, 404, "{v}");
        tokio::time::sleep(Duration::from_millis(200)).await;
    };
    assert_eq!(end["complete"], true, "{end}");
    assert_eq!(
        (&end["winner"], &end["ticks"]),
        (&twin_end["winner"], &twin_end["tick"]),
        "resumed {end}\ntwin {twin_end}"
    );
}

async fn ws(s: &Server, path: &str) -> Ws {
    let (stream, _) = tokio_tungstenite::connect_async(format!("ws://{}{path}", s.addr))
        .await
        .expect("WebSocket handshake");
    Ws { stream }
}

#[tokio::test]
async fn a_player_takes_their_seat_again_after_a_sigkill_and_the_truth_stays_late() {
    let dir = common::temp_dir("resume-player");
    let client = reqwest::Client::new();
    let mut a = serve(&dir);
    let (id, owner) = create(
        &client,
        &a,
        json!({"map": "office", "opponent_control": "human", "opponents": 1, "planner": "idle"}),
    )
    .await;
    let (status, joined, _) = send(
        &client,
        reqwest::Method::POST,
        &a,
        &format!("/api/matches/{id}/players"),
        None,
        Some(json!({"name": "alice"})),
    )
    .await;
    assert_eq!(status, 201, "{joined}");
    let token = joined["token"].as_str().unwrap().to_string();
    let mut player = ws(&a, &format!("/ws/matches/{id}?token={token}")).await;
    assert_eq!(player.next_of("welcome").await["you"], "o0");
    for seq in 1..=20 {
        player
            .send_json(
                &json!({"type": "input", "forward": 1.0, "turn": 0.3, "tag": false, "seq": seq}),
            )
            .await
            .unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let seen = player.next_of("snapshot").await;
    stored().await;
    kill(&mut a);
    // The player's socket is cut, as a crash cuts it (after what it had on its way).
    while let Got::Json(_) = player.next().await {}

    let b = serve(&dir);
    let shown = when_back(&client, &b, &format!("/api/matches/{id}"), None).await;
    // A stranger sees what spectators saw before (the 30 s delay holds), and no seed.
    assert_eq!(shown["tick"], 0, "the truth stays delayed: {shown}");
    assert_eq!(shown["seed"], Value::Null, "the seed stays secret: {shown}");
    let live = when_back(&client, &b, &format!("/api/matches/{id}"), Some(&owner)).await;
    assert!(live["tick"].as_u64().unwrap() + 20 >= seen["tick"].as_u64().unwrap());
    // Its token takes the seat again; the body is where it was.
    let mut again = ws(&b, &format!("/ws/matches/{id}?token={token}")).await;
    let welcome = again.next_of("welcome").await;
    assert_eq!(
        (welcome["you"].as_str(), welcome["name"].as_str()),
        (Some("o0"), Some("alice"))
    );
    let snapshot = again.next_of("snapshot").await;
    assert_eq!(snapshot["you"], "o0", "{snapshot}");
    let moved = &live["opponents"][0];
    assert!(
        (moved["x"].as_f64().unwrap() - shown["opponents"][0]["x"].as_f64().unwrap()).abs() > 0.1
            || (moved["y"].as_f64().unwrap() - shown["opponents"][0]["y"].as_f64().unwrap()).abs()
                > 0.1,
        "the body moved before the kill and kept its place: {moved}"
    );

    // And again: a resumed match's seats survive the next crash too.
    again
        .send_json(&json!({"type": "input", "forward": 1.0, "turn": 0.0, "tag": false, "seq": 1}))
        .await
        .unwrap();
    stored().await;
    let mut b = b;
    kill(&mut b);
    let c = serve(&dir);
    when_back(&client, &c, &format!("/api/matches/{id}"), None).await;
    let mut third = ws(&c, &format!("/ws/matches/{id}?token={token}")).await;
    let welcome = third.next_of("welcome").await;
    assert_eq!(welcome["you"], "o0", "{welcome}");
}

/// An hour of `act` commands for 8 robots at 20 Hz (72,000 requests, 576,000 orders): far
/// past what memory holds of a recording, all stored, all resumed after a SIGKILL.
#[tokio::test]
async fn an_api_match_with_an_hour_of_commands_resumes_with_every_one() {
    use lasertag::game::record::{MEMORY_ORDER_BYTES, order_bytes};
    use lasertag_core::world::{RobotOrder, WorldInput};
    let dir = common::temp_dir("resume-api");
    let client = reqwest::Client::new();
    let mut a = serve_unthrottled(&dir);
    let (id, token) = create(
        &client,
        &a,
        json!({"map": "office", "clock": "manual", "seed": 3, "robots": 8, "opponents": 1,
            "planner": "api", "localisation": false, "time_limit_s": 7200}),
    )
    .await;
    let acts: usize = 3600 * 20;
    let each = order_bytes(&WorldInput::Robot {
        robot: 0,
        order: RobotOrder::Stop,
    })
    .unwrap();
    assert!(
        acts * 8 * each > 2 * MEMORY_ORDER_BYTES,
        "an hour is past memory's bound"
    );
    let commands: serde_json::Map<String, Value> = (0..8)
        .map(|r| {
            (
                format!("r{r}"),
                json!({"forward": 0.5, "turn": if r % 2 == 0 { 0.2 } else { -0.2 }}),
            )
        })
        .collect();
    let act = json!({"commands": commands, "ticks": 1});
    let path = format!("/api/matches/{id}/act");
    // One at a time: a manual match steps for one request at once (409 for another).
    for _ in 0..acts {
        let (status, r, _) = send(
            &client,
            reqwest::Method::POST,
            &a,
            &path,
            Some(&token),
            Some(act.clone()),
        )
        .await;
        assert_eq!(status, 200, "{r}");
    }
    let before = reading(&client, &a, &id, &token).await;
    assert_eq!(before["state"]["tick"].as_u64(), Some(acts as u64));
    stored().await;
    kill(&mut a);

    let b = serve_unthrottled(&dir);
    when_back(&client, &b, &format!("/api/matches/{id}"), None).await;
    assert_eq!(reading(&client, &b, &id, &token).await, before);
    let (status, r, _) = send(
        &client,
        reqwest::Method::POST,
        &b,
        &path,
        Some(&token),
        Some(act),
    )
    .await;
    assert_eq!(status, 200, "{r}");
    assert_eq!(r["tick"].as_u64(), Some(acts as u64 + 1));
}

/// A tmpfs of a few megabytes mounted at a fresh directory (the tests run as root, as CI
/// does), unmounted when dropped, so that a store can be given a disk that fills.
struct SmallDisk {
    dir: std::path::PathBuf,
}

impl SmallDisk {
    fn mount(what: &str, mb: u64) -> SmallDisk {
        let dir = common::temp_dir(what);
        std::fs::create_dir_all(&dir).expect("a mount point");
        let status = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={mb}m"), "tmpfs"])
            .arg(&dir)
            .status()
            .expect("mount runs");
        assert!(status.success(), "mounting a tmpfs needs root");
        SmallDisk { dir }
    }

    /// Fills the disk to the last byte with one file, which it returns.
    fn fill(&self) -> std::path::PathBuf {
        use std::io::Write;
        let path = self.dir.join("filler");
        let mut f = std::fs::File::create(&path).expect("the filler");
        let chunk = vec![0u8; 64 * 1024];
        while f.write_all(&chunk).is_ok() {}
        let small = [0u8; 512];
        while f.write_all(&small).is_ok() {}
        let _ = f.sync_all();
        path
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount")
            .arg("-l")
            .arg(&self.dir)
            .status();
    }
}

#[tokio::test]
async fn a_full_disk_stops_the_record_not_the_play_and_the_record_keeps_no_gap() {
    let disk = SmallDisk::mount("resume-full-disk", 24);
    let dir = disk.dir.join("data");
    let client = reqwest::Client::new();
    let mut a = serve_unthrottled(&dir);
    let (id, token) = create(
        &client,
        &a,
        json!({"map": "office", "clock": "manual", "seed": 9, "robots": 2, "opponents": 1,
            "planner": "api", "localisation": false}),
    )
    .await;
    let path = format!("/api/matches/{id}/act");
    let act = |tick: u64| {
        let turn = if (tick / 20).is_multiple_of(2) {
            0.5
        } else {
            -0.5
        };
        json!({"commands": {"r0": {"forward": 1.0, "turn": turn}, "r1": {"forward": 0.6, "turn": -turn}},
            "ticks": 1})
    };
    let drive = |n: u64| {
        let (client, a, path, token) = (&client, &a, &path, &token);
        async move {
            let mut last = 0;
            for _ in 0..n {
                let (status, r, _) = send(
                    client,
                    reqwest::Method::POST,
                    a,
                    path,
                    Some(token),
                    Some(act(last)),
                )
                .await;
                assert_eq!(status, 200, "{r}");
                last = r["tick"].as_u64().unwrap();
            }
            last
        }
    };
    let tick = drive(100).await;
    stored().await;
    let filler = disk.fill();
    // Play goes on while nothing can be written, and the operator is told.
    let played = drive(300).await;
    assert!(played > tick, "the match plays on: {played}");
    stored().await;
    let told = a
        .warnings
        .lock()
        .unwrap()
        .iter()
        .any(|l| l.contains("could not store") && l.contains("cannot be written"));
    assert!(
        told,
        "the log says the history cannot be written: {:?}",
        a.warnings.lock().unwrap()
    );
    // Room again: the writer stores what waited, and the record has no gap.
    std::fs::remove_file(filler).expect("the filler goes");
    drive(20).await;
    stored().await;
    stored().await;
    let before = reading(&client, &a, &id, &token).await;
    kill(&mut a);
    let b = serve_unthrottled(&dir);
    when_back(&client, &b, &format!("/api/matches/{id}"), None).await;
    assert_eq!(
        reading(&client, &b, &id, &token).await,
        before,
        "resumed whole"
    );
    let db = rusqlite::Connection::open(dir.join("lasertag.db")).expect("the database");
    let check: String = db
        .query_row("PRAGMA integrity_check", [], |r| r.get(0))
        .expect("integrity_check");
    assert_eq!(check, "ok");
}

async fn upload_policy(client: &reqwest::Client, s: &Server, name: &str) -> (u16, Value) {
    let r = client
        .post(s.url(&format!("/api/policies?name={name}&decide_every=4")))
        .header("content-type", "application/onnx")
        .body(common::small_policy())
        .send()
        .await
        .unwrap();
    (r.status().as_u16(), r.json().await.unwrap_or(Value::Null))
}

/// (name, shipped, decide_every) of every policy `s` holds.
async fn policy_names(client: &reqwest::Client, s: &Server) -> Vec<(String, bool, u64)> {
    let (status, list, _) =
        send(client, reqwest::Method::GET, s, "/api/policies", None, None).await;
    assert_eq!(status, 200, "{list}");
    list.as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["name"].as_str().unwrap().to_string(),
                p["shipped"].as_bool().unwrap(),
                p["decide_every"].as_u64().unwrap(),
            )
        })
        .collect()
}

#[tokio::test]
async fn an_uploaded_policy_outlives_its_server_and_drives_its_match_on() {
    let dir = common::temp_dir("resume-policy");
    let client = reqwest::Client::new();
    let body = json!({"map": "office", "clock": "manual", "seed": 23,
        "planner": "policy:kept", "time_limit_s": 60});
    let mut a = serve(&dir);
    let (status, created) = upload_policy(&client, &a, "kept").await;
    assert_eq!(status, 201, "{created}");
    let owner = created["owner_token"].as_str().unwrap().to_string();
    let (id, token) = create(&client, &a, body.clone()).await;
    step(&client, &a, &id, &token, 101).await;
    let before = reading(&client, &a, &id, &token).await;
    stored().await;
    kill(&mut a);

    let mut b = serve(&dir);
    when_back(&client, &b, &format!("/api/matches/{id}"), None).await;
    assert_eq!(
        policy_names(&client, &b).await,
        [
            ("kept".to_string(), false, 4),
            ("learned".to_string(), true, 2)
        ]
    );
    assert_eq!(reading(&client, &b, &id, &token).await, before);
    // The name stays taken, and the owner token (kept as a hash) still owns it: a stranger
    // is refused, the owner is told it is in use.
    assert_eq!(upload_policy(&client, &b, "kept").await.0, 409);
    let delete = |token: String| {
        let (client, b) = (&client, &b);
        async move {
            send(
                client,
                reqwest::Method::DELETE,
                b,
                "/api/policies/kept",
                Some(&token),
                None,
            )
            .await
            .0
        }
    };
    assert_eq!(delete("0123456789abcdef0123456789abcdef".into()).await, 403);
    assert_eq!(delete(owner.clone()).await, 409);
    // The policy drives the match on as it would have had nothing happened: its twin,
    // started afresh on this server, is the witness.
    let (twin, twin_token) = create(&client, &b, body).await;
    step(&client, &b, &twin, &twin_token, 101).await;
    for ticks in [1, 60] {
        let one = step(&client, &b, &id, &token, ticks).await;
        let other = step(&client, &b, &twin, &twin_token, ticks).await;
        assert_eq!(one["robots"], other["robots"], "after {ticks} more ticks");
    }
    assert_ne!(
        reading(&client, &b, &id, &token).await["state"]["robots"],
        before["state"]["robots"],
        "its robots moved by the policy"
    );
    // Played to their ends, the matches let it go; removed, it stays gone after a restart.
    for (id, token) in [(&id, &token), (&twin, &twin_token)] {
        let end = step(&client, &b, id, token, 1200).await;
        assert_eq!(end["status"], "finished");
    }
    assert_eq!(delete(owner).await, 204);
    stored().await;
    kill(&mut b);
    let c = serve(&dir);
    assert_eq!(
        policy_names(&client, &c).await,
        [("learned".to_string(), true, 2)]
    );
}
