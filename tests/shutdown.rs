//! Graceful shutdown of the real binary: on SIGTERM it stops accepting, suspends every
//! running match into its store (the next server on the same store resumes it), closes
//! every socket with a close frame (1012, "restarting", for a running match: come back),
//! and exits within 5 s of the signal; the next server seats the player again.

#![cfg(unix)]

mod common;
#[path = "common/process.rs"]
mod process;

use process::Server;

use std::net::SocketAddr;
use std::process::Command;
use std::time::{Duration, Instant};

use common::{Got, Ws};
use serde_json::{Value, json};

fn start() -> Server {
    let data = common::temp_dir("shutdown");
    Server::start(&["--no-showcase", "--data-dir", &data.display().to_string()])
}

async fn post(client: &reqwest::Client, addr: SocketAddr, path: &str, body: Value) -> Value {
    let r = client
        .post(format!("http://{addr}{path}"))
        .json(&body)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 201);
    r.json().await.unwrap()
}

async fn ws(addr: SocketAddr, path: &str) -> Ws {
    let (stream, _) = tokio_tungstenite::connect_async(format!("ws://{addr}{path}"))
        .await
        .expect("WebSocket handshake");
    Ws { stream }
}

/// Reads until the close: the `finished` message seen (if any) and the close frame. Then
/// reads on until the server ends the connection, as a browser does: that sends the reply
/// to the close, which the server waits for before it lets go of the socket.
async fn until_close(ws: &mut Ws) -> (Option<Value>, Got) {
    use futures_util::StreamExt;
    let mut finished = None;
    loop {
        match ws.next().await {
            Got::Json(v) if v["type"] == "finished" => finished = Some(v),
            Got::Json(_) => {}
            other => {
                let _ = tokio::time::timeout(Duration::from_secs(5), async {
                    while ws.stream.next().await.is_some() {}
                })
                .await;
                return (finished, other);
            }
        }
    }
}

// Regression test for a shutdown race: in 2 to 7 runs of 30, `serve` returned as soon
// as axum's server future finished (it has no HTTP request to wait for) instead of waiting
// for the WebSockets, and the runtime then dropped their tasks mid-close: a client read a bare
// EOF (`ResetWithoutClosingHandshake`) instead of `finished` and its close frame.
#[tokio::test]
async fn sigterm_tells_every_client_closes_cleanly_and_exits_within_5_s() {
    let data = common::temp_dir("shutdown");
    let mut server = Server::start(&["--no-showcase", "--data-dir", &data.display().to_string()]);
    let addr = server.addr;
    let client = reqwest::Client::new();
    // A running real-time match with a player and a spectator; a finished manual match with
    // a spectator still on its end screen.
    let live = post(
        &client,
        addr,
        "/api/matches",
        json!({"map": "office", "opponent_control": "human", "planner": "idle",
            "spectator_delay_s": 0}),
    )
    .await["id"]
        .as_str()
        .unwrap()
        .to_string();
    let joined = post(
        &client,
        addr,
        &format!("/api/matches/{live}/players"),
        json!({"name": "alice"}),
    )
    .await;
    let token = joined["token"].as_str().unwrap();
    let created = post(
        &client,
        addr,
        "/api/matches",
        json!({"map": "office", "clock": "manual", "time_limit_s": 1}),
    )
    .await;
    let done = created["id"].as_str().unwrap().to_string();
    let r = client
        .post(format!("http://{addr}/api/matches/{done}/step"))
        .bearer_auth(created["owner_token"].as_str().unwrap())
        .json(&json!({"ticks": 100}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    let mut player = ws(addr, &format!("/ws/matches/{live}?token={token}")).await;
    let mut spectator = ws(addr, &format!("/ws/matches/{live}")).await;
    let mut late = ws(addr, &format!("/ws/matches/{done}")).await;
    player.next_of("snapshot").await;
    spectator.next_of("snapshot").await;
    assert_eq!(late.next_of("finished").await["reason"], "time_limit");

    let signalled = Instant::now();
    let status = Command::new("kill")
        .args(["-TERM", &server.child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());

    // All three are read at once, as real clients read: the server waits only 1 s for each
    // client's reply to its close frame, and read one after another on a loaded machine the
    // last client answered too late and its close was lost with the reset connection.
    let (p, s, l) = tokio::join!(
        until_close(&mut player),
        until_close(&mut spectator),
        until_close(&mut late)
    );
    for (who, (finished, closed)) in [("player", p), ("spectator", s)] {
        // The match goes on in the next server: no `finished`, a close that says come back.
        assert!(finished.is_none(), "{who}: {finished:?}");
        assert!(
            matches!(&closed, Got::Closed { code: 1012, reason } if reason.contains("restarting")),
            "{who}: {closed:?}"
        );
    }
    // The client of the finished match had its `finished` already; it gets the close.
    let (again, closed) = l;
    assert!(again.is_none(), "{again:?}");
    assert!(
        matches!(&closed, Got::Closed { code: 1001, .. }),
        "{closed:?}"
    );

    // The process exits, successfully, within 5 s of the signal.
    let exit = loop {
        if let Some(status) = server.child.try_wait().unwrap() {
            break status;
        }
        assert!(
            signalled.elapsed() < Duration::from_secs(5),
            "still running 5 s after SIGTERM"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    let took = signalled.elapsed();
    assert!(exit.success(), "{exit}");
    assert!(
        took < Duration::from_secs(5),
        "exited {took:?} after SIGTERM"
    );
    eprintln!("exited {took:?} after SIGTERM");
    // Nothing listens any more.
    assert!(
        tokio::net::TcpStream::connect(addr).await.is_err(),
        "still accepting after shutdown"
    );

    // The next server on the same store has the match running, the player's seat kept.
    let next = Server::start(&["--no-showcase", "--data-dir", &data.display().to_string()]);
    let state = loop {
        let r = client
            .get(format!("http://{}/api/matches/{live}", next.addr))
            .send()
            .await
            .unwrap();
        if r.status() == 503 {
            assert!(
                r.headers().contains_key("retry-after"),
                "503 without Retry-After"
            );
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        }
        assert_eq!(r.status(), 200);
        break r.json::<Value>().await.unwrap();
    };
    assert_eq!(state["status"], "running", "{state}");
    let mut back = ws(next.addr, &format!("/ws/matches/{live}?token={token}")).await;
    let welcome = back.next_of("welcome").await;
    assert_eq!(
        (welcome["name"].as_str(), welcome["you"].as_str()),
        (Some("alice"), Some("o0")),
        "{welcome}"
    );
}

/// `lasertag healthcheck` (the container's HEALTHCHECK) passes against a live server, also
/// when given the listen-everywhere address, and fails once the server is gone.
#[test]
fn healthcheck_subcommand_tells_a_live_server_from_a_dead_one() {
    let check = |addr: &str| {
        Command::new(env!("CARGO_BIN_EXE_lasertag"))
            .args(["healthcheck", "--addr", addr, "--timeout-s", "5"])
            .env_remove("LASERTAG_ADDR")
            .output()
            .expect("the lasertag binary runs")
    };
    let mut server = start();
    let addr = server.addr;
    let out = check(&addr.to_string());
    assert!(out.status.success(), "{out:?}");
    let out = check(&format!("0.0.0.0:{}", addr.port()));
    assert!(out.status.success(), "{out:?}");
    let _ = server.child.kill();
    let _ = server.child.wait();
    let out = check(&addr.to_string());
    assert!(!out.status.success(), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("unhealthy: cannot connect"), "{err}");
}

/// With an open files limit too low to serve (soft and hard), the server does not start:
/// it exits with an error that names the limit and how to raise it, and listens nowhere.
#[test]
fn too_few_open_files_stops_the_start_with_a_clear_error() {
    let out = Command::new("sh")
        .arg("-c")
        .arg(r#"ulimit -n 60 && exec "$0" serve --addr 127.0.0.1:0 --no-showcase"#)
        .arg(env!("CARGO_BIN_EXE_lasertag"))
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("NO_COLOR", "1")
        .output()
        .expect("sh runs");
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("open files limit (60)"), "{stderr}");
    assert!(stderr.contains("ulimit"), "{stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(!stdout.contains("serving http://"), "{stdout}");
}
