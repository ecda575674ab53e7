//! A person plays the shipped learned team (`"difficulty": "learned"`, `policy:learned`) from
//! the lobby in headless Chromium: the Play door offers it, its robots move by the policy,
//! the team's belief shows when asked for, and the match's replay plays back. And a person
//! who walks a little and then hides, still, to the end of the match never sees one of its
//! robots stand still for 10 s (`lasertag_policy::unpark`).
//!
//! Needs Chromium, as `tests/browser.rs`.

#[path = "common/cdp.rs"]
#[allow(dead_code)]
mod cdp;
mod common;

use cdp::Browser;
use common::TestServer;
use lasertag::game::Sight;
use lasertag::protocol;
use lasertag_core::sim::TICK_HZ;
use lasertag_core::sim::still::LongestStill;
use nalgebra::Point2;
use serde_json::json;
use std::time::{Duration, Instant};

/// Opens the lobby at `base`, picks the learned team at the Play door and waits until the
/// page plays the match as its opponent.
async fn play_the_learned_team_from_the_lobby(b: &mut Browser, base: &str) {
    b.navigate(&format!("{base}/")).await;
    b.wait_for(
        "__lasertag.page === 'lobby' && [...document.getElementById('door-difficulty').options].some((o) => o.value === 'learned')",
        20,
    )
    .await;
    b.eval("document.getElementById('door-difficulty').value = 'learned'")
        .await;
    b.eval("document.getElementById('door-play').click()").await;
    b.wait_for(
        "__lasertag.role === 'player' && __lasertag.team === 'opponents' && __lasertag.snapshots > 0",
        20,
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_person_plays_the_learned_team_from_the_lobby_and_replays_it() {
    // A server that keeps names: a rated match rates only a kept name.
    let s = TestServer::start_stored(&common::temp_dir("learned")).await;
    let mut b = Browser::launch().await;
    let base = format!("http://{}", s.addr);
    play_the_learned_team_from_the_lobby(&mut b, &base).await;
    assert_eq!(b.eval("__lasertag.rated").await, json!(true));
    let id = b.eval("__lasertag.matchId").await;
    let id = id.as_str().unwrap().to_string();
    // The match is the learned team's, and its robots move by the policy.
    let handle = s.registry.get(&id).expect("the match runs here");
    let read = || async {
        handle
            .read(Sight::Live, protocol::read_state)
            .await
            .unwrap()
    };
    let first = serde_json::to_value(read().await).unwrap();
    assert_eq!(first["policy"], "learned");
    assert_eq!(first["robot_planners"], json!(["policy", "policy"]));
    b.wait_for("__lasertag.lastTick > 100", 30).await;
    let later = serde_json::to_value(read().await).unwrap();
    assert_ne!(
        first["robots"], later["robots"],
        "the policy's robots moved"
    );
    // B shows the team's belief: it arrives with the snapshots.
    b.key("KeyB", true).await;
    b.key("KeyB", false).await;
    b.wait_for(
        "__lasertag.belief === true && __lasertag.beliefRoles > 0",
        20,
    )
    .await;
    // Ended, the match replays: its robots' recorded orders play back without the model.
    assert!(s.registry.remove(&id).await);
    b.navigate(&format!("{base}/#/replay/{id}?t=5&pov=full&belief=1"))
        .await;
    b.wait_for("__lasertag.lastTick === 100", 30).await;
    let replayed = s.get(&format!("/api/replays/{id}/state?tick=100")).await;
    assert_eq!(replayed.status, 200, "{}", replayed.body);
    assert_eq!(replayed.body["policy"], "learned");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_learned_team_never_stands_still_for_10_s_while_a_person_hides() {
    let s = TestServer::start().await;
    let mut b = Browser::launch().await;
    play_the_learned_team_from_the_lobby(&mut b, &format!("http://{}", s.addr)).await;
    let id = b.eval("__lasertag.matchId").await;
    let handle = s
        .registry
        .get(id.as_str().expect("a match id"))
        .expect("the match runs here");
    // The person walks for two seconds, then hides where they are until the match ends.
    b.key("KeyW", true).await;
    tokio::time::sleep(Duration::from_secs(2)).await;
    b.key("KeyW", false).await;
    // The robots' true places, read from the match as it runs, four times a second.
    let mut still = LongestStill::default();
    let (mut ended, mut last_tick) = (None, 0);
    let give_up = Instant::now() + Duration::from_secs(200);
    while ended.is_none() && Instant::now() < give_up {
        let state = handle
            .read(Sight::Live, protocol::read_state)
            .await
            .expect("the match reads");
        let state = serde_json::to_value(state).expect("a state");
        last_tick = state["tick"].as_u64().expect("a tick");
        for (i, r) in state["robots"]
            .as_array()
            .expect("robots")
            .iter()
            .enumerate()
        {
            if r["frozen"] == json!(true) {
                still.pause(i);
            } else {
                let at = Point2::new(
                    r["x"].as_f64().unwrap_or(0.0),
                    r["y"].as_f64().unwrap_or(0.0),
                );
                still.push(i, at.cast::<f32>(), last_tick);
            }
        }
        if state["status"] == "finished" {
            ended = Some((state["winner"].clone(), state["time_s"].clone()));
        }
        tokio::time::sleep(Duration::from_millis(250)).await;
    }
    let (winner, time_s) = ended.expect("the match ended within its 2 minutes");
    let longest_s = still.longest_ticks() as f64 / TICK_HZ as f64;
    eprintln!("winner {winner}, at {time_s} s; the longest a robot stood still: {longest_s} s");
    // Reading every quarter second can stretch a spell by one reading.
    assert!(
        longest_s <= 10.0 - 0.25,
        "a robot stood still for {longest_s} s while the person hid (match over at tick {last_tick})"
    );
    // The page saw the same ending.
    b.wait_for(
        "__lasertag.ended && !document.getElementById('end').hidden",
        20,
    )
    .await;
}
