//! Accessibility of the pages in headless Chromium: axe-core (from npm) finds no serious or
//! critical violation on the lobby, the play page (live and with its end card), a finished
//! match's replay, and the party's waiting room once the server has parties; and the lobby's
//! controls are reached with the Tab key alone, each showing where the focus is, and its Play
//! door is pressed with Enter.
//!
//! Needs Chromium, as `tests/browser.rs`, and axe-core's `axe.min.js`: `LASERTAG_AXE` names it,
//! else `target/axe/node_modules/axe-core/axe.min.js` (where `bash tests/run.sh` installs the
//! pinned version). The figures and Lighthouse's scores are in docs/browser.md.

#[path = "common/cdp.rs"]
#[allow(dead_code)] // the phone's helpers
mod cdp;
mod common;

use std::path::PathBuf;

use cdp::Browser;
use common::TestServer;
use serde_json::{Value, json};

/// axe-core's script: `$LASERTAG_AXE`, else where tests/run.sh installs it.
fn axe_source() -> String {
    let path = std::env::var_os("LASERTAG_AXE").map_or_else(
        || {
            PathBuf::from(env!("CARGO_MANIFEST_DIR"))
                .join("target/axe/node_modules/axe-core/axe.min.js")
        },
        PathBuf::from,
    );
    std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "axe-core is not at {} ({e}): run `bash tests/run.sh` (it installs axe-core from \
             npm into target/axe), or `npm install --prefix target/axe axe-core@4.14.1`, or set \
             LASERTAG_AXE to an axe.min.js",
            path.display()
        )
    })
}

/// Loads axe-core into the page (its script's own value, whatever it is, is not returned).
async fn inject(b: &mut Browser, source: &str) {
    b.eval(&format!("{source}\n;0")).await;
}

/// Runs axe-core over the whole document as it is now and returns its violations (each rule
/// with its impact and the selectors of the elements that break it).
async fn axe(b: &mut Browser, source: &str) -> Value {
    // A hash route changes the page without reloading it: axe stays loaded once injected.
    if b.eval("typeof window.axe === 'undefined'").await == json!(true) {
        inject(b, source).await;
    }
    let found = b
        .eval(
            "axe.run(document, {resultTypes: ['violations']}).then((r) => ({
               ran: r.passes.length + r.violations.length + r.incomplete.length,
               contrast: [...r.passes, ...r.violations, ...r.incomplete].some((x) => x.id === 'color-contrast'),
               violations: r.violations.map((v) => ({id: v.id, impact: v.impact, help: v.help,
                 targets: v.nodes.map((n) => n.target.join(' '))})),
             }))",
        )
        .await;
    // An audit of an empty page would pass: the rules that check what is drawn ran.
    assert!(
        found["ran"].as_u64() > Some(10) && found["contrast"] == true,
        "axe-core ran no audit: {found}"
    );
    found["violations"].clone()
}

/// Audits the page as `page`, prints each violation, and adds a line to `failures` for each
/// serious or critical one.
async fn audit(b: &mut Browser, source: &str, page: &str, failures: &mut Vec<String>) {
    let violations = axe(b, source).await;
    for v in violations.as_array().expect("violations") {
        let line = format!(
            "{page}: {} ({}): {} at {}",
            v["id"].as_str().unwrap_or("?"),
            v["impact"].as_str().unwrap_or("?"),
            v["help"].as_str().unwrap_or(""),
            v["targets"]
        );
        // Printed as found: a later failure must not hide it.
        println!("{line}");
        if matches!(v["impact"].as_str(), Some("serious" | "critical")) {
            failures.push(line);
        }
    }
    println!(
        "{page}: audited, {} violation(s)",
        violations.as_array().map_or(0, Vec::len)
    );
}

/// Presses `key` (`Tab` or `Enter`) as a keyboard would.
async fn press(b: &mut Browser, key: &str) {
    let (vk, text) = match key {
        "Tab" => (9, ""),
        "Enter" => (13, "\r"),
        other => panic!("no key {other}"),
    };
    for kind in ["keyDown", "keyUp"] {
        let mut event = json!({"type": kind, "key": key, "code": key, "windowsVirtualKeyCode": vk});
        if kind == "keyDown" && !text.is_empty() {
            event["text"] = json!(text);
        }
        b.call("Input.dispatchKeyEvent", event).await;
    }
}

/// The element that has the focus: its id (or tag), and whether a ring shows it (an outline
/// or a box shadow drawn because it is focused).
const FOCUSED: &str = r#"(() => {
  const el = document.activeElement;
  if (!el || el === document.body) return null;
  const s = getComputedStyle(el);
  const ring = (s.outlineStyle !== 'none' && parseFloat(s.outlineWidth) > 0) || s.boxShadow !== 'none';
  return { id: el.id || el.name || el.tagName.toLowerCase(), visible: el.matches(':focus-visible') && ring };
})()"#;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn axe_finds_no_serious_violation_and_the_lobby_works_with_the_keyboard() {
    let source = axe_source();
    let s = TestServer::start().await;
    tokio::spawn(lasertag::game::showcase::keep_running(s.registry.clone()));
    let mut b = Browser::launch().await;
    let base = format!("http://{}", s.addr);
    let mut failures = Vec::new();
    let version = {
        b.navigate(&format!("{base}/")).await;
        b.wait_for("__lasertag.page === 'lobby'", 20).await;
        inject(&mut b, &source).await;
        b.eval("axe.version").await
    };
    println!("axe-core {version}");

    // 1. The lobby, once the showcase, the list and the robot teams are in.
    b.wait_for(
        "!document.getElementById('showcase').hidden \
         && document.querySelectorAll('#matches tbody tr[data-id]').length > 0 \
         && document.getElementById('door-difficulty').options.length > 0 \
         && document.getElementById('difficulty-note').textContent",
        20,
    )
    .await;
    audit(&mut b, &source, "lobby", &mut failures).await;

    // Tab from the top reaches every control of the lobby, each with a visible ring.
    b.eval("document.activeElement && document.activeElement.blur()")
        .await;
    let mut reached = Vec::new();
    for _ in 0..60 {
        press(&mut b, "Tab").await;
        let focused = b.eval(FOCUSED).await;
        if focused.is_null() {
            continue;
        }
        let id = focused["id"].as_str().unwrap_or("?").to_string();
        assert_eq!(focused["visible"], true, "no visible focus on {id}");
        if reached.contains(&id) && id == "name" {
            break; // round again
        }
        reached.push(id);
    }
    for control in [
        "name",
        "lobby-history",
        "lobby-leaderboard",
        "door-difficulty",
        "door-play",
        "door-hunt",
        "showcase-watch",
        "showcase-play",
        "map",
        "difficulty",
        "mode",
        "control",
    ] {
        assert!(
            reached.iter().any(|r| r == control),
            "Tab never reaches {control}: {reached:?}"
        );
    }
    // A row's button keeps the focus while the list is drawn anew (every second).
    let row = b
        .eval(
            "(() => { const button = document.querySelector('#matches tbody tr[data-id] button'); \
             button.focus(); window.__row = button.closest('tr'); \
             return [button.closest('tr').dataset.id, button.textContent]; })()",
        )
        .await;
    let kept = b
        .wait_for(
            "document.querySelector('#matches tbody tr[data-id]') !== window.__row \
             && [document.activeElement.closest('tr[data-id]')?.dataset.id, document.activeElement.textContent]",
            10,
        )
        .await;
    assert_eq!(
        kept, row,
        "the focus left the list's row when it was redrawn"
    );
    // The Play door, with Enter from the keyboard, makes a match and seats the page in it.
    b.eval("document.getElementById('door-play').focus()").await;
    press(&mut b, "Enter").await;
    b.wait_for(
        "__lasertag.role === 'player' && location.hash.startsWith('#/play/')",
        20,
    )
    .await;

    // 2. Playing: a seat in a match with a human slot, as the lobby's Play opens it (the page
    // joins the match itself), on a manual clock so that it ends when stepped.
    let id = s
        .create_match(json!({"map": "office", "robots": 2, "opponents": 1,
            "opponent_control": "human", "planner": "idle", "clock": "manual",
            "time_limit_s": 10}))
        .await;
    b.navigate(&format!("{base}/#/play/{id}")).await;
    b.wait_for(
        &format!("__lasertag.matchId === '{id}' && __lasertag.role === 'player' && __lasertag.snapshots > 0"),
        20,
    )
    .await;
    s.step(&id, 20).await;
    b.wait_for("__lasertag.lastTick >= 20 && __lasertag.drawn", 10)
        .await;
    audit(&mut b, &source, "play", &mut failures).await;
    // And its end card.
    let end = s.step(&id, 180).await;
    assert_eq!(end["status"], "finished", "{end}");
    b.wait_for(
        "__lasertag.ended && !document.getElementById('end').hidden",
        20,
    )
    .await;
    audit(&mut b, &source, "play, the end card", &mut failures).await;

    // 3. A finished match's replay (tags on its timeline), paused.
    let replay = s
        .create_match(
            json!({"map": "office", "robots": 2, "opponents": 3, "clock": "manual",
            "opponent_bot": "evade", "time_limit_s": 30, "seed": 3}),
        )
        .await;
    assert_eq!(s.step(&replay, 600).await["status"], "finished");
    // The history stores it a moment after its end.
    let mut stored = false;
    for _ in 0..50 {
        stored = s.get(&format!("/api/replays/{replay}")).await.status == 200;
        if stored {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    }
    assert!(stored, "{replay} never became a replay");
    b.navigate(&format!("{base}/#/replay/{replay}?t=5")).await;
    b.wait_for(
        &format!("__lasertag.page === 'replay' && __lasertag.replayId === '{replay}' && __lasertag.lastTick === 100 && __lasertag.markers > 0 && __lasertag.drawn"),
        20,
    )
    .await;
    audit(&mut b, &source, "replay", &mut failures).await;

    // 4. The party's waiting room: the host's, made from the lobby's door (members, sides,
    // settings, the invite and its QR code), then the form a friend's invite link opens.
    b.navigate(&format!("{base}/#/")).await;
    b.wait_for("!!document.getElementById('door-party')", 20)
        .await;
    b.eval(
        "(() => { const e = document.getElementById('name'); e.value = 'host';
           e.dispatchEvent(new Event('input', {bubbles: true}));
           document.getElementById('door-party').click(); return true; })()",
    )
    .await;
    let code = b
        .wait_for(
            "__lasertag.page === 'party' && __lasertag.partyConnected && __lasertag.partyCode",
            20,
        )
        .await;
    let code = code.as_str().expect("a party code").to_string();
    audit(&mut b, &source, "party (host)", &mut failures).await;
    let other = s.post("/api/parties", &json!({"name": "other"})).await;
    assert_eq!(other.status, 201, "{}", other.body);
    let invited = other.body["code"].as_str().expect("a party code");
    assert_ne!(invited, code);
    b.navigate(&format!("{base}/#/party/{invited}")).await;
    b.wait_for("!document.getElementById('party-join').hidden", 20)
        .await;
    audit(&mut b, &source, "party (invited)", &mut failures).await;

    assert!(
        failures.is_empty(),
        "serious or critical accessibility violations (axe-core {version}):\n{}",
        failures.join("\n")
    );
}
