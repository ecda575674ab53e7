//! A person playing in headless Chromium when the server is killed with SIGKILL: the page
//! says it is reconnecting, and once a server is back on the same store and address it takes
//! its seat again by itself (the token it kept), and the match goes on from where it was;
//! the HUD's jitter is the new connection's, so a loopback link never reads as poor.
//!
//! Needs Chromium (`bash tests/run.sh` installs Debian's package when it is missing).

#![cfg(unix)]

#[path = "common/cdp.rs"]
#[allow(dead_code)] // the helpers this test does not need
mod cdp;
mod common;
#[path = "common/process.rs"]
mod process;

use std::time::Duration;

use cdp::Browser;
use process::Server;
use serde_json::{Value, json};

fn free_addr() -> String {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("a free port");
    l.local_addr().expect("its address").to_string()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_reconnects_by_itself_after_the_server_is_killed_and_resumed() {
    let dir = common::temp_dir("browser-resume");
    let data = dir.display().to_string();
    let addr = free_addr();
    let args = ["--no-showcase", "--data-dir", data.as_str()];
    let mut server = Server::start_at(&addr, &args, &[]);
    let client = reqwest::Client::new();
    let created: Value = client
        .post(server.url("/api/matches"))
        .json(
            &json!({"map": "office", "opponent_control": "human", "opponents": 1,
            "planner": "idle"}),
        )
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let id = created["id"].as_str().unwrap().to_string();

    let mut b = Browser::launch().await;
    b.navigate(&format!("http://{addr}/#/play/{id}")).await;
    b.wait_for(
        "__lasertag.role === 'player' && __lasertag.snapshots > 5",
        20,
    )
    .await;
    // Walk a little, so that the body's place says whether the match went on.
    b.key("KeyW", true).await;
    tokio::time::sleep(Duration::from_millis(1500)).await;
    b.key("KeyW", false).await;
    tokio::time::sleep(Duration::from_millis(1600)).await; // the store has it all
    let before = b.eval("__lasertag.lastTick").await.as_u64().unwrap_or(0);
    assert!(before > 40, "the match ran: tick {before}");

    // Every line the HUD's ping shows from here on, with the reconnects so far.
    b.eval(
        "window.__hud = []; new MutationObserver(() => { const el = document.getElementById('hud-ping'); \
         __hud.push({ text: el.textContent, quality: el.dataset.quality, reconnects: __lasertag.reconnects || 0 }); }) \
         .observe(document.getElementById('hud-ping'), { childList: true, characterData: true, subtree: true })",
    )
    .await;
    server.child.kill().expect("SIGKILL");
    server.child.wait().expect("the server dies");
    let status = b
        .wait_for(
            "(!__lasertag.connected && document.getElementById('hud-status').textContent.includes('reconnecting')) && document.getElementById('hud-status').textContent",
            10,
        )
        .await;
    assert!(
        status.as_str().unwrap().contains("reconnecting"),
        "{status}"
    );
    b.save("reconnecting.png").await;
    // A few seconds down, as a crash and a supervisor's restart take.
    tokio::time::sleep(Duration::from_secs(2)).await;

    let _again = Server::start_at(&addr, &args, &[]);
    b.wait_for(
        "__lasertag.connected && __lasertag.reconnects >= 1 && __lasertag.role === 'player'",
        30,
    )
    .await;
    // Snapshots flow again, from at most a second before the kill onwards.
    let after = b
        .wait_for(
            &format!(
                "__lasertag.lastTick > {} && __lasertag.lastTick",
                before + 20
            ),
            15,
        )
        .await;
    assert!(after.as_u64().unwrap() > before, "{after} after {before}");
    let status = b
        .eval("document.getElementById('hud-status').textContent")
        .await;
    assert!(
        !status
            .as_str()
            .unwrap_or_default()
            .contains("connection lost"),
        "{status}"
    );
    assert_eq!(b.eval("__lasertag.joinError || null").await, Value::Null);
    // The seconds after the reconnect, when arrivals from before the outage would have read
    // as seconds of jitter: every line the HUD showed calls the loopback link good.
    tokio::time::sleep(Duration::from_secs(4)).await;
    let shown = b
        .eval("JSON.stringify(__hud.filter((h) => h.reconnects >= 1))")
        .await;
    let shown: Vec<Value> = serde_json::from_str(shown.as_str().unwrap_or("[]")).unwrap();
    assert!(
        shown.len() >= 3,
        "the HUD's ping after the reconnect: {shown:?}"
    );
    for line in &shown {
        assert_ne!(line["quality"], json!("poor"), "{line}: {shown:?}");
    }
    let jitter = b
        .eval("__lasertag.jitterMs")
        .await
        .as_f64()
        .unwrap_or(f64::MAX);
    assert!(jitter < 100.0, "jitter {jitter} ms on loopback");
    println!("after the reconnect the HUD showed: {shown:?}");
}
