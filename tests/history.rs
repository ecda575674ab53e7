//! The history survives the process: a server killed with SIGKILL in the middle of a match
//! restarts with every earlier replay intact, and the interrupted match resumed where the
//! store last heard of it; once it ends, its replay is complete, the ticks before the kill
//! as they were played.

#![cfg(unix)]

mod common;
#[path = "common/process.rs"]
mod process;

use std::time::Duration;

use process::{Server, create, get, step};
use serde_json::Value;

#[tokio::test]
async fn a_killed_server_keeps_its_history_and_the_match_it_was_playing() {
    let dir = common::temp_dir("killed");
    let data = dir.display().to_string();
    let args = ["--no-showcase", "--data-dir", data.as_str()];
    let client = reqwest::Client::new();
    let mut s = Server::start(&args);

    // A match that ends before the kill.
    let (done, token) = create(&client, &s, 1).await;
    let mut done_states = Vec::new();
    for _ in 0..3 {
        done_states.push(step(&client, &s, &done, &token, 100).await);
    }
    let r = client
        .delete(s.url(&format!("/api/matches/{done}")))
        .bearer_auth(&token)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 204);

    // One that is in the middle of play when the process dies.
    let (cut, token) = create(&client, &s, 2).await;
    let mut cut_states = Vec::new();
    for _ in 0..3 {
        cut_states.push(step(&client, &s, &cut, &token, 100).await);
    }
    // The match task sends its inputs and tick to the store about once a second.
    tokio::time::sleep(Duration::from_secs(3)).await;
    step(&client, &s, &cut, &token, 50).await;
    s.child.kill().expect("SIGKILL");
    s.child.wait().expect("the server dies");

    let s = Server::start(&args);
    // The cut match is running again, from the last tick the store had.
    let resumed = loop {
        let r = client
            .get(s.url(&format!("/api/matches/{cut}")))
            .send()
            .await
            .unwrap();
        if r.status() == 503 {
            tokio::time::sleep(Duration::from_millis(100)).await;
            continue;
        }
        assert_eq!(r.status(), 200);
        break r.json::<Value>().await.unwrap();
    };
    assert_eq!(resumed["status"], "running", "{resumed}");
    let last = resumed["tick"].as_u64().unwrap();
    assert!((300..=350).contains(&last), "resumed at tick {last}");
    step(&client, &s, &cut, &token, 20).await;
    let r = client
        .delete(s.url(&format!("/api/matches/{cut}")))
        .bearer_auth(&token)
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 204);
    // The end reaches the store from the match's task a moment later.
    let listed = loop {
        let (status, listed) = get(&client, &s, "/api/replays").await;
        assert_eq!(status, 200);
        if listed
            .as_array()
            .unwrap()
            .iter()
            .any(|r| r["id"] == cut.as_str())
        {
            break listed;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    let row = |id: &str| {
        listed
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["id"] == id)
            .cloned()
            .unwrap_or_else(|| panic!("{id} listed in {listed}"))
    };
    assert_eq!(row(&done)["complete"], true);
    assert_eq!(row(&done)["reason"], "stopped");
    let cut_row = row(&cut);
    assert_eq!(cut_row["complete"], true, "{cut_row}");
    assert_eq!(cut_row["reason"], "stopped", "{cut_row}");
    assert_eq!(cut_row["ticks"].as_u64(), Some(last + 20), "{cut_row}");

    for (id, states) in [(&done, &done_states), (&cut, &cut_states)] {
        for live in states {
            let tick = live["tick"].as_u64().unwrap();
            let (status, replayed) =
                get(&client, &s, &format!("/api/replays/{id}/state?tick={tick}")).await;
            assert_eq!(status, 200, "{replayed}");
            // A match deleted at its last tick read "running" live then; its end is an
            // input applied after that read.
            let (mut replayed, mut live) = (replayed, live.clone());
            for v in [&mut replayed, &mut live] {
                v["status"] = Value::Null;
                v["winner"] = Value::Null;
            }
            assert_eq!(replayed, live, "{id} at tick {tick}");
        }
    }
}
