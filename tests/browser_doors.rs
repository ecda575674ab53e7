//! The lobby's doors in headless Chromium when the person cannot be seated or their name
//! cannot be kept: a refused *Play* leaves no match behind and no name claimed, and says why
//! in a player's words; a name past its address's kept names plays, and the HUD calls the
//! match unrated from the start. The page's socket fetches `/api/transport` once and sends
//! one close for a session.
//!
//! Needs Chromium (`bash tests/run.sh` installs Debian's package when it is missing).

#[path = "common/cdp.rs"]
#[allow(dead_code)] // the helpers these tests do not need
mod cdp;
mod common;

use cdp::Browser;
use common::{TestServer, test_config};
use lasertag::config::Config;
use serde_json::{Value, json};

/// A server that keeps names (a store in a temporary directory) with `config`.
async fn keeping_names(config: Config) -> TestServer {
    let dir = common::temp_dir("browser-doors");
    let retention = lasertag::store::Retention {
        max_matches: 1000,
        max_bytes: 1 << 30,
    };
    let store = lasertag::store::Store::open(&dir, retention).expect("the store opens");
    let history = lasertag::game::replay::History::with_store(store);
    TestServer::start_with_history(config, history).await
}

/// The ids of the matches the server lists.
async fn listed(s: &TestServer) -> Vec<String> {
    let r = s.get("/api/matches").await;
    assert_eq!(r.status, 200, "{}", r.body);
    let mut ids: Vec<String> = r
        .body
        .as_array()
        .expect("a list")
        .iter()
        .map(|m| m["id"].as_str().expect("an id").to_string())
        .collect();
    ids.sort();
    ids
}

/// The lobby at `s`, its teams loaded, with `name` typed.
async fn lobby(b: &mut Browser, s: &TestServer, name: &str) {
    b.navigate(&format!("http://{}/", s.addr)).await;
    b.wait_for(
        "__lasertag.page === 'lobby' && document.getElementById('door-difficulty').options.length > 1",
        20,
    )
    .await;
    b.eval(&format!(
        "document.getElementById('name').value = {}",
        json!(name)
    ))
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_refused_play_leaves_no_match_and_no_name_claimed() {
    // Two seats an address, the server's default; the test's own client (127.0.0.1, the
    // browser's address too) takes both, as tabs closed a moment ago still hold theirs.
    let s = keeping_names(Config {
        max_seats_per_address: 2,
        ..test_config()
    })
    .await;
    for _ in 0..2 {
        let id = s
            .create_match(json!({"map": "office", "opponents": 1, "opponent_control": "human"}))
            .await;
        s.join(&id, "earlier tab").await;
    }
    let before = listed(&s).await;
    assert_eq!(before.len(), 2);

    let mut b = Browser::launch().await;
    lobby(&mut b, &s, "ada").await;
    b.eval("document.getElementById('door-play').click()").await;
    let said = b
        .wait_for(
            "document.getElementById('lobby-error').textContent || false",
            20,
        )
        .await;
    let said = said.as_str().unwrap_or_default().to_string();
    assert!(
        said.contains("as many seats as one address may") && said.contains("closed"),
        "the player's words: {said}"
    );
    assert_eq!(b.eval("__lasertag.page").await, json!("lobby"));
    // The match made for the seat is gone, and the name is nobody's.
    let undone = b.eval("__lasertag.undoneMatch || null").await;
    assert!(undone.is_string(), "a match was made and undone: {undone}");
    assert_eq!(listed(&s).await, before, "no match left behind");
    assert_eq!(
        b.eval("JSON.stringify(JSON.parse(localStorage.getItem('lasertag.names') || '{}'))")
            .await,
        json!("{}")
    );
    let claim = s.post("/api/names", &json!({"name": "ada"})).await;
    assert_eq!(claim.status, 201, "ada is free: {}", claim.body);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_name_past_the_addresss_kept_names_plays_unrated_and_says_so() {
    let s = keeping_names(Config {
        max_names_per_address: 5,
        ..test_config()
    })
    .await;
    for i in 0..5 {
        let r = s
            .post("/api/names", &json!({"name": format!("kept {i}")}))
            .await;
        assert_eq!(r.status, 201, "{}", r.body);
    }
    let mut b = Browser::launch().await;
    lobby(&mut b, &s, "grace").await;
    b.eval("document.getElementById('door-play').click()").await;
    b.wait_for(
        "__lasertag.role === 'player' && __lasertag.snapshots > 0",
        20,
    )
    .await;
    assert_eq!(b.eval("__lasertag.rated").await, json!(false));
    let hud = b
        .eval("document.getElementById('hud-match').textContent")
        .await;
    let hud = hud.as_str().unwrap_or_default();
    assert!(
        hud.contains("unrated") && hud.contains("keeps as many names") && !hud.contains("· rated"),
        "{hud}"
    );
    // The match itself is rated: only this player's name is not.
    let id = b.eval("__lasertag.matchId").await;
    let list = s.get("/api/matches").await;
    let m = list
        .body
        .as_array()
        .and_then(|l| l.iter().find(|m| m["id"] == id))
        .cloned()
        .unwrap_or_default();
    assert_eq!(m["rated"], json!(true), "{}", list.body);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_play_session_fetches_the_transport_once_and_closes_once() {
    let s = TestServer::with_webtransport(test_config()).await;
    let id = s
        .create_match(json!({"map": "office", "opponents": 1, "opponent_control": "human"}))
        .await;
    let mut b = Browser::launch().await;
    b.navigate(&format!("http://{}/#/play/{id}", s.addr)).await;
    b.wait_for(
        "__lasertag.role === 'player' && __lasertag.snapshots > 20",
        20,
    )
    .await;
    let carrier = b.eval("__lasertag.transport").await;
    assert_eq!(
        b.eval("[__lasertag.transportFetches, __lasertag.closesSent || 0]")
            .await,
        json!([1, 0]),
        "over {carrier}"
    );
    // Back to the lobby: the session's one close.
    b.eval("location.hash = '#/'").await;
    b.wait_for("__lasertag.page === 'lobby'", 10).await;
    let sent: Value = b.wait_for("__lasertag.closesSent || false", 10).await;
    assert_eq!(sent, json!(1), "over {carrier}");
    assert_eq!(b.eval("__lasertag.transportFetches").await, json!(1));
}
