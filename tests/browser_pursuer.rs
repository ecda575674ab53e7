//! A person on the robot team in headless Chromium against a real server: they take a robot
//! from the lobby (co-op, beside a robot with the look-ahead `search` planner), and in a
//! staged match, over a network with a 150 ms round trip, they turn their robot round with
//! the keyboard, see the team's belief, split a role with
//! their own sighting and tag the opponent they found.
//!
//! Needs Chromium (`bash tests/run.sh` installs Debian's package when it is missing). With
//! `LASERTAG_SCREENSHOTS=<dir>` set, the test also saves its screenshot there.

#[path = "common/cdp.rs"]
#[allow(dead_code)] // the phone's helpers
mod cdp;
mod common;
#[path = "common/netem.rs"]
mod netem;

use std::time::Duration;

use cdp::Browser;
use common::{TestServer, duel_map};
use serde_json::json;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_person_hunts_with_the_robots_in_headless_chromium() {
    let s = TestServer::start().await;
    let mut b = Browser::launch().await;
    let base = format!("http://{}", s.addr);

    // 1. Co-op from the lobby: the new match gives its last robot to the person who made it.
    b.navigate(&format!("{base}/")).await;
    b.wait_for("__lasertag.page === 'lobby' && document.querySelector('#create select[name=map]').options.length > 0", 20)
        .await;
    b.eval(
        "document.getElementById('name').value = 'ada';
         const f = document.getElementById('create');
         f.elements.difficulty.value = 'custom'; f.elements.difficulty.dispatchEvent(new Event('change'));
         f.elements.mode.value = 'coop'; f.elements.mode.dispatchEvent(new Event('change'));
         f.elements.robots.value = 1; f.elements.planner.value = 'search';
         f.requestSubmit();",
    )
    .await;
    b.wait_for(
        "__lasertag.page === 'game' && __lasertag.team === 'robots' && __lasertag.snapshots > 3",
        20,
    )
    .await;
    assert_eq!(b.eval("__lasertag.you").await, json!("r1"));
    assert_eq!(b.eval("__lasertag.belief").await, json!(true));
    let listed = s.get("/api/matches").await.body;
    let m = &listed[0];
    assert_eq!(m["pursuer_slots"], 1, "{m}");
    assert_eq!(m["robot_planners"], json!(["search", "person"]), "{m}");
    assert_eq!(m["opponent_control"], "bot", "{m}");

    // 2. A staged hunt, over a network with a 150 ms round trip: r1 (the person's) at (1, 2)
    // faces west; o1 stands 4 m behind it, o0 far off; r0 stands still facing the east wall.
    // Nobody sees anybody yet.
    let net = netem::Netem::start(s.addr, netem::Conditions::rtt_ms(150)).await;
    let slow = format!("http://{}", net.addr);
    let id = s
        .create_match(json!({"map": duel_map(), "robots": 2, "opponents": 2,
            "opponent_control": "api", "planner": "idle", "pursuer_slots": 1,
            "time_limit_s": 120,
            "robot_starts": [[13.0, 1.0, 0.0], [1.0, 2.0, std::f64::consts::PI]],
            "opponent_starts": [[10.0, 7.0], [5.0, 2.0]]}))
        .await;
    b.navigate(&format!("{slow}/#/play/{id}?team=robots")).await;
    b.wait_for(
        &format!(
            "__lasertag.matchId === '{id}' && __lasertag.you === 'r1' && __lasertag.snapshots > 3"
        ),
        20,
    )
    .await;
    let hud = b
        .eval("document.getElementById('hud-match').textContent")
        .await;
    assert!(
        hud.as_str().unwrap().contains("hunting as robot r1"),
        "{hud}"
    );
    assert_eq!(b.eval("__lasertag.drawn.opponents").await, json!(0));
    // Turn left for 31 input ticks (0.1 rad each, from west): it faces east within its tag
    // cone (±5°: one input more or less is 5.7°). The page sends one input per 50 ms tick
    // with the keys held then (`sent` counts them); a hook in the page lets the key go the
    // moment the 31st has gone, as a person's finger would not but a test must: released
    // from outside, a busy machine let two or three more go first.
    b.eval(
        "(() => { const d = window.__lasertag; let sent = d.sent || 0, start = null; \
         addEventListener('keydown', (e) => { if (e.code === 'ArrowLeft' && start === null) start = sent; }, true); \
         Object.defineProperty(d, 'sent', { configurable: true, get: () => sent, set: (v) => { sent = v; \
           if (start !== null && v >= start + 31 && !d.turned) { d.turned = v - start; \
             dispatchEvent(new KeyboardEvent('keyup', { code: 'ArrowLeft', key: 'ArrowLeft' })); } } }); \
         return true; })()",
    )
    .await;
    b.key("ArrowLeft", true).await;
    let turned = b.wait_for("__lasertag.turned", 10).await;
    assert_eq!(turned, json!(31), "inputs sent with the key held");
    b.key("ArrowLeft", false).await;
    // (The inputs keep flowing, so `ack` stays a round trip behind `sent`: wait that out.)
    tokio::time::sleep(Duration::from_millis(500)).await;
    let theta = b.eval("__lasertag.own.theta").await.as_f64().unwrap();
    assert!(
        theta.abs() < 5f64.to_radians(),
        "faces {theta} rad, not east"
    );
    // Its laser has o1 now: drawn on the page, and the team's belief split a role for it.
    b.wait_for("__lasertag.drawn.opponents === 1", 5).await;
    b.wait_for(
        "__lasertag.feed.some((f) => f.kind === 'role_split') && __lasertag.drawn.particles > 0",
        5,
    )
    .await;
    let legend = b
        .eval("document.getElementById('legend').textContent")
        .await;
    assert!(
        legend.as_str().unwrap().starts_with("your team's belief"),
        "{legend}"
    );
    b.save("pursuer.png").await;
    b.tap("Space", Duration::from_millis(60)).await;
    let feed = b
        .wait_for(
            "__lasertag.feed.find((f) => f.kind === 'tag' && f.text === 'you tagged o?')",
            5,
        )
        .await;
    assert!(feed.is_object(), "{feed}");
    let state = s.get(&format!("/api/matches/{id}")).await.body;
    assert_eq!(state["opponents"][1]["tagged"], true, "{state}");
    assert_eq!(state["opponents"][0]["tagged"], false, "{state}");
}
