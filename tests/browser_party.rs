//! Friends playing together, in three headless Chromium profiles against a real server: the
//! host opens *Play with friends*, two friends open the invite link (one on a 390 px phone,
//! on the robots' side), everyone readies, the host starts; all three play, each body moves,
//! a mark by one opponent shows on the other's screen and never on the hunter's; the end
//! card's *Again* brings all three back to the room.
//!
//! Needs Chromium, as `tests/browser.rs`. The time from *Start* to play is printed (a figure
//! for docs/browser.md, not a test: timing goals are not tested).

#[path = "common/cdp.rs"]
#[allow(dead_code)]
mod cdp;
mod common;

use std::time::{Duration, Instant};

use cdp::Browser;
use common::{ADMIN, TestServer};
use serde_json::Value;

/// Sets a text field's value as typing would, so the page's listeners hear it.
async fn type_into(b: &mut Browser, id: &str, text: &str) {
    b.eval(&format!(
        "(() => {{ const e = document.getElementById({id:?}); e.value = {text:?};
          e.dispatchEvent(new Event('input', {{bubbles: true}})); return true; }})()"
    ))
    .await;
}

async fn click(b: &mut Browser, id: &str) {
    b.eval(&format!("document.getElementById({id:?}).click()"))
        .await;
}

/// A member's page, once it has joined the room named `code` under `name`.
async fn join_by_link(base: &str, code: &str, name: &str, phone: bool) -> Browser {
    let mut b = Browser::launch().await;
    if phone {
        b.phone().await;
    }
    b.navigate(&format!("{base}/#/party/{code}")).await;
    b.wait_for("!document.getElementById('party-join').hidden", 20)
        .await;
    type_into(&mut b, "party-join-name", name).await;
    click(&mut b, "party-join-button").await;
    // Joined is when the page's room holds this member: a view of the room from before the
    // join (the invite page's) lacks them, and their buttons act on the member the room
    // shows, so a click before then would do nothing.
    b.wait_for(
        &format!(
            "!!(window.__lasertag.partyConnected
               && (window.__lasertag.party?.members || []).some((m) =>
                    m.name === {name:?} && m.id === window.__lasertag.partyMember))"
        ),
        20,
    )
    .await;
    b
}

/// Where each of `agents` (`o0`, `r1`, …) stands, as the operator reads the match live.
async fn positions(s: &TestServer, id: &str, agents: &[String]) -> Vec<(f64, f64)> {
    let m = s
        .get_as(&format!("/api/matches/{id}"), Some(ADMIN))
        .await
        .body;
    agents
        .iter()
        .map(|agent| {
            let a = ["opponents", "robots"]
                .iter()
                .flat_map(|side| m[side].as_array().into_iter().flatten())
                .find(|a| a["id"] == agent.as_str())
                .unwrap_or_else(|| panic!("no {agent} in {m}"));
            (
                a["x"].as_f64().unwrap_or(0.0),
                a["y"].as_f64().unwrap_or(0.0),
            )
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn three_friends_gather_play_mark_and_come_back_for_another() {
    let s = TestServer::with_admin().await;
    let base = format!("http://{}", s.addr);

    // The host's door.
    let mut host = Browser::launch().await;
    host.navigate(&format!("{base}/")).await;
    // The page's module has set the lobby up (the door's button is in the HTML before it).
    host.wait_for("window.__lasertag?.page === 'lobby'", 20)
        .await;
    type_into(&mut host, "name", "hosta").await;
    click(&mut host, "door-party").await;
    let code = host
        .wait_for("window.__lasertag.partyCode || ''", 20)
        .await
        .as_str()
        .unwrap_or_default()
        .to_string();
    assert_eq!(code.len(), 6, "{code}");
    host.wait_for("!!window.__lasertag.partyConnected", 20)
        .await;

    // Two friends by the invite link; bob on a phone, hunting with the robots.
    let mut ann = join_by_link(&base, &code, "ann", false).await;
    let mut bob = join_by_link(&base, &code, "bob", true).await;
    bob.eval(
        "(() => { const s = document.getElementById('party-side'); s.value = 'robots';
           s.dispatchEvent(new Event('change', {bubbles: true})); return true; })()",
    )
    .await;
    // On the phone the room fits its width and the QR code is drawn.
    let fits = bob
        .wait_for(
            "document.documentElement.scrollWidth <= 390
             && document.getElementById('party-qr').complete
             && document.getElementById('party-qr').naturalWidth > 0
             && document.getElementById('party-qr').getBoundingClientRect().width > 0",
            20,
        )
        .await;
    assert_eq!(fits, Value::Bool(true));
    bob.save("party-phone.png").await;

    for b in [&mut host, &mut ann, &mut bob] {
        click(b, "party-ready").await;
    }
    // Each sees themselves ready (on failure, that page's own state is shown).
    for b in [&mut host, &mut ann, &mut bob] {
        b.wait_for(
            "!!(window.__lasertag.party?.members || []).find((m) =>
                m.id === window.__lasertag.partyMember)?.ready",
            20,
        )
        .await;
    }
    host.wait_for(
        "(window.__lasertag.party?.members || []).length === 3
         && window.__lasertag.party.members.every((m) => m.ready)
         && window.__lasertag.party.members.some((m) => m.side === 'robots')",
        20,
    )
    .await;
    host.save("party-room.png").await;

    let clicked = Instant::now();
    click(&mut host, "party-start").await;
    let mut playing = Vec::new();
    for b in [&mut host, &mut ann, &mut bob] {
        b.wait_for(
            "window.__lasertag.page === 'game' && !!window.__lasertag.role",
            30,
        )
        .await;
        playing.push(clicked.elapsed());
    }
    println!("start to playing, each of three pages: {playing:?}");
    let id = s.get("/api/matches").await.body[0]["id"]
        .as_str()
        .unwrap_or_default()
        .to_string();
    assert!(!id.is_empty());

    // Each body moves under its own keys.
    let mut agents = Vec::new();
    for b in [&mut host, &mut ann, &mut bob] {
        agents.push(
            b.eval("window.__lasertag.you")
                .await
                .as_str()
                .unwrap_or_default()
                .to_string(),
        );
    }
    assert!(
        agents[0].starts_with('o') && agents[1].starts_with('o'),
        "{agents:?}"
    );
    assert!(agents[2].starts_with('r'), "{agents:?}");
    let before = positions(&s, &id, &agents).await;
    for b in [&mut host, &mut ann, &mut bob] {
        b.key("KeyW", true).await;
    }
    tokio::time::sleep(Duration::from_millis(1500)).await;
    for b in [&mut host, &mut ann, &mut bob] {
        b.key("KeyW", false).await;
    }
    let after = positions(&s, &id, &agents).await;
    for ((a, b), agent) in before.iter().zip(&after).zip(&agents) {
        let moved = ((a.0 - b.0).powi(2) + (a.1 - b.1).powi(2)).sqrt();
        assert!(moved > 0.1, "{agent} did not move: {a:?} -> {b:?}");
    }

    // The host marks; ann, on the host's side, sees it; bob, a hunter, never does.
    host.tap("KeyQ", Duration::from_millis(50)).await;
    ann.wait_for(
        "[...document.querySelectorAll('#marks-layer .mark')].some((m) => m.dataset.by === 'hosta')",
        10,
    )
    .await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let bob_saw = bob
        .eval("document.querySelectorAll('#marks-layer .mark').length + (window.__lasertag.marksReceived || 0)")
        .await;
    assert_eq!(bob_saw, Value::from(0), "a hunter saw the opponents' mark");
    ann.save("party-mark.png").await;

    // The match ends; *Again* brings everyone back to the room, the same sides.
    let r = s
        .delete_as(&format!("/api/matches/{id}"), Some(ADMIN))
        .await;
    assert!(r.status < 300, "{}", r.body);
    for b in [&mut host, &mut ann, &mut bob] {
        b.wait_for("!document.getElementById('end-again').hidden", 30)
            .await;
        click(b, "end-again").await;
    }
    for b in [&mut host, &mut ann, &mut bob] {
        b.wait_for(
            &format!(
                "window.__lasertag.page === 'party' && window.__lasertag.partyCode === {code:?}
                 && window.__lasertag.party?.status === 'waiting'"
            ),
            30,
        )
        .await;
    }
    let sides = host
        .eval("window.__lasertag.party.members.map((m) => m.name + ':' + m.side).join(',')")
        .await;
    assert_eq!(
        sides,
        Value::from("hosta:opponents,ann:opponents,bob:robots")
    );
}
