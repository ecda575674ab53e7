//! A person plays the shipped learned team (`"difficulty": "learned"`, `policy:learned`) from
//! the lobby in headless Chromium: the Play door offers it, its robots move by the policy,
//! the team's belief shows when asked for, and the match's replay plays back.
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
use serde_json::json;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_person_plays_the_learned_team_from_the_lobby_and_replays_it() {
    // A server that keeps names: a rated match rates only a kept name.
    let s = TestServer::start_stored(&common::temp_dir("learned")).await;
    let mut b = Browser::launch().await;
    let base = format!("http://{}", s.addr);
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
