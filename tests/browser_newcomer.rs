//! What a new player hits, in headless Chromium: after being tagged the page watches on live
//! (the clock never goes back) and sends no more keys; a name typed while the page is still
//! loading over a slow link is kept; on a phone the lobby fits the screen, its buttons are a
//! thumb's size and the arena turns to the screen's long side; the lobby shows the showcase
//! moving and one's own rating; a replay's address follows its moment.
//!
//! Needs Chromium, as `tests/browser.rs`.

#[path = "common/cdp.rs"]
#[allow(dead_code)]
mod cdp;
mod common;
#[path = "common/netem.rs"]
mod netem;

use std::time::Duration;

use cdp::Browser;
use common::TestServer;
use serde_json::json;

/// o0 (the page) stands 2 m in front of a searching robot in a corridor, which tags it (a
/// match people play has a secret random seed, so the robot must not have to happen to
/// turn round); o1, in a far room, keeps the match going. The page then shows the teammates' view,
/// live, and its input counter stops. The match runs on a manual clock, stepped by the test
/// once the page has its seat, so that the robot cannot tag o0 before the page takes it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn after_the_tag_the_clock_never_goes_back_and_no_key_is_sent() {
    let s = TestServer::start().await;
    let id = s
        .create_match(json!({"map": "office", "robots": 1, "opponents": 2,
            "opponent_control": "human", "planner": "baseline", "time_limit_s": 120,
            "clock": "manual",
            "robot_starts": [[5.0, 8.0, std::f64::consts::PI]],
            "opponent_starts": [[3.0, 8.0], [22.0, 14.0]]}))
        .await;
    let mut b = Browser::launch().await;
    let base = format!("http://{}", s.addr);
    b.navigate(&format!("{base}/#/play/{id}")).await;
    b.wait_for(
        "__lasertag.role === 'player' && __lasertag.you === 'o0' && __lasertag.snapshots > 0",
        20,
    )
    .await;
    let mut tagged_at = None;
    for _ in 0..1200 {
        let truth = s.step(&id, 1).await;
        if truth["opponents"][0]["tagged"] == true {
            tagged_at = truth["tick"].as_u64();
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let tagged_at = tagged_at.expect("the robot tags o0");
    b.wait_for(
        &format!("__lasertag.view === 'teammates' && __lasertag.lastTick >= {tagged_at}"),
        10,
    )
    .await;
    let status = b
        .eval("document.getElementById('hud-status').textContent")
        .await;
    assert!(status.as_str().unwrap().contains("teammates"), "{status}");
    // Keys sent in the moment between the tag and the snapshot that shows it are refused
    // (in flight); none after.
    tokio::time::sleep(Duration::from_millis(300)).await;
    let (sent, errors) = (
        b.eval("__lasertag.sent").await,
        b.eval("__lasertag.errors.length").await,
    );
    // Keys held down drive nothing any more: nothing is sent, while the match goes on.
    b.key("KeyW", true).await;
    let mut now = tagged_at;
    let mut last = json!(null);
    for _ in 0..40 {
        last = s.step(&id, 1).await;
        now = last["tick"].as_u64().unwrap();
        if last["status"] == "finished" {
            break;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    b.key("KeyW", false).await;
    // Live: the page shows the tick the match is at.
    b.wait_for(&format!("__lasertag.lastTick === {now}"), 10)
        .await;
    assert_eq!(
        b.eval("__lasertag.sent").await,
        sent,
        "inputs after the tag"
    );
    assert_eq!(
        b.eval("__lasertag.clockWentBack || 0").await,
        json!(0),
        "the clock went back"
    );
    assert_eq!(
        b.eval("__lasertag.errors.length").await,
        errors,
        "the server refused keys after the tag"
    );
    // The end card comes when the match ends in what the page shows: live, not behind.
    while last["status"] != "finished" {
        last = s.step(&id, 200).await;
    }
    let end = last["tick"].as_u64().unwrap();
    b.wait_for("!document.getElementById('end').hidden", 10)
        .await;
    let shown = b.eval("__lasertag.lastTick").await.as_u64().unwrap();
    assert!(shown + 20 >= end, "the end card at tick {shown} of {end}");
}

/// Over a 150 ms link the page's modules wait for the rules; a name typed meanwhile is not
/// replaced by the one the page remembers.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_name_typed_while_the_page_loads_is_kept() {
    let s = TestServer::start().await;
    let net = netem::Netem::start(s.addr, netem::Conditions::rtt_ms(150)).await;
    let base = format!("http://{}", net.addr);
    let mut b = Browser::launch().await;
    b.navigate(&format!("{base}/")).await;
    b.wait_for("window.__lasertag && __lasertag.page === 'lobby'", 30)
        .await;
    b.eval("localStorage.setItem('lasertag.name', 'remembered')")
        .await;
    b.navigate(&format!("{base}/")).await;
    // As soon as the field is there, before the page has its rules.
    let typed = b
        .wait_for(
            "(() => { const n = document.getElementById('name'); if (!n) return false; \
              const early = !(window.__lasertag && __lasertag.page === 'lobby'); \
              n.value = 'typed-early'; return early ? 'early' : 'late'; })()",
            30,
        )
        .await;
    assert_eq!(
        typed,
        json!("early"),
        "the page loaded before the name was typed"
    );
    b.wait_for("window.__lasertag && __lasertag.page === 'lobby'", 30)
        .await;
    assert_eq!(
        b.eval("document.getElementById('name').value").await,
        json!("typed-early")
    );
}

/// At 390 × 844 the lobby is as wide as the screen (its matches are cards), every button on
/// it is at least 44 px each way, and no text is under 12 px.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn on_a_phone_the_lobby_fits_and_its_buttons_are_thumb_sized() {
    let s = TestServer::start().await;
    s.create_match(json!({"map": "office", "opponent_control": "human"}))
        .await;
    let mut b = Browser::launch().await;
    b.screen(390, 844).await;
    b.navigate(&format!("http://{}/", s.addr)).await;
    b.wait_for(
        "__lasertag.page === 'lobby' && document.querySelectorAll('#matches tr[data-id] button').length > 0",
        20,
    )
    .await;
    let fit = b
        .eval(
            "(() => { const buttons = [...document.querySelectorAll('#lobby button')]\
               .map((e) => e.getBoundingClientRect()).filter((r) => r.width > 0);\
             return {width: document.documentElement.scrollWidth, buttons: buttons.length,\
               smallest: Math.min(...buttons.map((r) => Math.min(r.width, r.height)))}; })()",
        )
        .await;
    assert!(fit["width"].as_f64().unwrap() <= 390.0, "{fit}");
    assert!(fit["buttons"].as_u64().unwrap() >= 2, "{fit}");
    assert!(fit["smallest"].as_f64().unwrap() >= 44.0, "{fit}");
    // Legible text (Lighthouse's rule): no visible words of the lobby under 12 px.
    let small = b
        .eval(
            "(() => [...document.querySelectorAll('#lobby *')].filter((e) =>\
               [...e.childNodes].some((n) => n.nodeType === 3 && n.textContent.trim()) &&\
               e.getBoundingClientRect().width > 0 &&\
               parseFloat(getComputedStyle(e).fontSize) < 12).map((e) => e.outerHTML.slice(0, 80)))()",
        )
        .await;
    assert_eq!(small, json!([]), "text under 12 px");
    b.save("lobby-phone.png").await;
}

/// On a phone held upright the office (24 × 16 m) is turned to the screen's long side, half
/// as large again as it would be upright, the page no wider than the screen, and a hint says
/// the arena is larger sideways.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn on_a_phone_the_arena_turns_to_fill_the_screen() {
    let s = TestServer::start().await;
    let id = s
        .create_match(json!({"map": "office", "opponent_control": "human"}))
        .await;
    let mut b = Browser::launch().await;
    b.phone().await;
    b.navigate(&format!("http://{}/#/play/{id}", s.addr)).await;
    b.wait_for(
        "__lasertag.role === 'player' && __lasertag.snapshots > 0 && __lasertag.fit",
        20,
    )
    .await;
    let fit = b.eval("__lasertag.fit").await;
    assert_eq!(fit["rot"], true, "{fit}");
    // Upright the office would be (390 - 2 * 15.6) / 24 = 14.95 px a metre.
    let scale = fit["s"].as_f64().unwrap();
    assert!(scale >= 1.4 * 14.95, "{fit}");
    let page = b
        .eval(
            "(() => ({width: document.documentElement.scrollWidth, touch: __lasertag.touch,\
               hint: getComputedStyle(document.getElementById('hud-hint')).display}))()",
        )
        .await;
    assert!(page["width"].as_f64().unwrap() <= 390.0, "{page}");
    assert_eq!(page["touch"], true, "{page}");
    assert_eq!(page["hint"], "block", "{page}");
    b.save("arena-phone.png").await;
    // Sideways, the office lies as it is, and no hint is shown.
    b.screen(844, 390).await;
    b.wait_for("__lasertag.fit.rot === false", 10).await;
    assert_eq!(
        b.eval("getComputedStyle(document.getElementById('hud-hint')).display")
            .await,
        "none"
    );
}

/// The lobby shows the showcase in a live thumbnail (a spectator's view, drawn), its words
/// count what that picture shows and say how late it is; leaving the lobby closes it.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_lobby_shows_the_showcase_live_and_says_what_it_shows() {
    let s = TestServer::start().await;
    tokio::spawn(lasertag::game::showcase::keep_running(s.registry.clone()));
    let mut b = Browser::launch().await;
    let base = format!("http://{}", s.addr);
    b.navigate(&format!("{base}/")).await;
    b.wait_for(
        "__lasertag.thumbnail && __lasertag.thumbnail.snapshots > 10 && __lasertag.thumbnail.view",
        30,
    )
    .await;
    let shown = b.eval("__lasertag.thumbnail").await;
    let view = &shown["view"];
    let text = b
        .eval("document.getElementById('showcase-text').textContent")
        .await;
    let words = format!(
        "{} robots hunt {} of {} opponents on {}, shown 30 s behind the players",
        view["robots"],
        view["alive"],
        view["opponents"],
        view["map"].as_str().unwrap()
    );
    assert!(text.as_str().unwrap().contains(&words), "{text} / {shown}");
    // The thumbnail is drawn: walls, on more than a tenth of its pixels.
    let drawn = b
        .eval(
            "(() => { const c = document.getElementById('showcase-view');\
               const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;\
               let wall = 0; for (let i = 0; i < d.length; i += 4)\
                 if (d[i] === 0x3a && d[i + 1] === 0x45 && d[i + 2] === 0x56) wall++;\
               return wall / (c.width * c.height); })()",
        )
        .await;
    assert!(drawn.as_f64().unwrap() > 0.05, "{drawn}");
    b.save("lobby.png").await;
    // Its socket is a spectator's; watching the showcase closes it (one spectator: the page).
    let id = shown["id"].as_str().unwrap().to_string();
    b.eval("document.getElementById('showcase-watch').click()")
        .await;
    b.wait_for(
        "__lasertag.role === 'spectator' && __lasertag.snapshots > 0",
        20,
    )
    .await;
    let mut spectators = 0;
    for _ in 0..50 {
        let listed = s.get("/api/matches").await.body;
        spectators = listed
            .as_array()
            .and_then(|l| l.iter().find(|m| m["id"] == id.as_str()))
            .and_then(|m| m["spectators"].as_u64())
            .unwrap_or(0);
        if spectators == 1 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert_eq!(spectators, 1);
}

/// The lobby says, under the name, what a name this browser keeps stands at (or that it
/// has no rating yet), and that a name nobody keeps here has none.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_lobby_names_ones_own_rating() {
    let s = TestServer::start_stored(&common::temp_dir("own-rating")).await;
    let r = s
        .post_as("/api/names", &json!({"name": "rita"}), None)
        .await;
    assert_eq!(r.status, 201, "{}", r.body);
    let token = r.body["name_token"].as_str().unwrap().to_string();
    let mut b = Browser::launch().await;
    let base = format!("http://{}", s.addr);
    b.navigate(&format!("{base}/")).await;
    b.wait_for("__lasertag.page === 'lobby'", 20).await;
    b.eval(&format!(
        "localStorage.setItem('lasertag.names', JSON.stringify({{rita: '{token}'}}));\
         localStorage.setItem('lasertag.name', 'rita')"
    ))
    .await;
    b.navigate(&format!("{base}/?again")).await;
    b.wait_for(
        "__lasertag.page === 'lobby' && document.getElementById('own-rating').textContent.includes('kept here')",
        20,
    )
    .await;
    b.eval(
        "(() => { const n = document.getElementById('name'); n.value = 'stranger';\
             n.dispatchEvent(new Event('input')); })()",
    )
    .await;
    b.wait_for(
        "document.getElementById('own-rating').textContent.includes('once it has played')",
        10,
    )
    .await;
}

/// The seconds `t` of the page's address (`…?t=12.5&…`).
fn address_seconds(address: &serde_json::Value) -> f64 {
    let a = address.as_str().unwrap_or_default();
    let t = a.split(['?', '&']).find_map(|p| p.strip_prefix("t="));
    t.and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("no t in {a}"))
}

/// A replay's address follows the moment shown: a link opens where it says and stays
/// there, a seek moves it, and so does playing.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_replays_address_follows_the_moment_it_shows() {
    let s = TestServer::start().await;
    let id = s
        .create_match(
            json!({"map": "office", "clock": "manual", "planner": "idle",
            "opponent_control": "api"}),
        )
        .await;
    s.step(&id, 600).await;
    assert_eq!(s.delete(&format!("/api/matches/{id}")).await.status, 204);
    let mut b = Browser::launch().await;
    let base = format!("http://{}", s.addr);
    // Opened at 20 s (paused there), the address keeps saying 20 s.
    b.navigate(&format!("{base}/#/replay/{id}?t=20&pov=full&belief=0"))
        .await;
    b.wait_for("__lasertag.lastTick === 400", 20).await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    let at = b.eval("location.hash").await;
    assert!((address_seconds(&at) - 20.0).abs() < 0.01, "{at}");
    // A seek to 5 s (tick 100): the address says 5 s.
    b.eval("(() => { const tl = document.getElementById('replay-timeline'); tl.value = '100'; tl.dispatchEvent(new Event('change')); })()")
        .await;
    b.wait_for("__lasertag.lastTick === 100", 10).await;
    b.wait_for("location.hash.includes('t=5&')", 5).await;
    // Played, the address keeps within a second of the moment shown.
    b.eval("document.getElementById('replay-play').click()")
        .await;
    tokio::time::sleep(Duration::from_secs(3)).await;
    let (shown, at) = (
        b.eval("__lasertag.lastTick").await.as_f64().unwrap() / 20.0,
        b.eval("location.hash").await,
    );
    assert!(shown > 6.0, "it plays: {shown} s");
    assert!(
        (address_seconds(&at) - shown).abs() <= 1.0,
        "shown {shown} s, address {at}"
    );
}

/// The lobby's doors: Play starts a rated match of one's own against the chosen team (and
/// remembers the team), Hunt seats the person on a robot of a co-op match.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_lobby_doors_start_a_rated_match_and_seat_a_hunter() {
    // A server that keeps names: a rated match rates only a kept name (else the HUD says
    // unrated, tests/browser_doors.rs).
    let s = TestServer::start_stored(&common::temp_dir("newcomer-doors")).await;
    let mut b = Browser::launch().await;
    let base = format!("http://{}", s.addr);
    b.navigate(&format!("{base}/")).await;
    b.wait_for(
        "__lasertag.page === 'lobby' && document.getElementById('door-difficulty').options.length > 1",
        20,
    )
    .await;
    let team = b
        .eval("(() => { const d = document.getElementById('door-difficulty'); d.selectedIndex = d.options.length - 1; return d.value; })()")
        .await;
    b.eval("document.getElementById('door-play').click()").await;
    b.wait_for(
        "__lasertag.role === 'player' && __lasertag.team === 'opponents' && __lasertag.snapshots > 0",
        20,
    )
    .await;
    assert_eq!(b.eval("__lasertag.rated").await, json!(true));
    assert_eq!(
        b.eval("localStorage.getItem('lasertag.difficulty')").await,
        team
    );
    // Back in the lobby, the team played last is offered first; Hunt seats a robot.
    b.navigate(&format!("{base}/#/")).await;
    b.wait_for(
        "__lasertag.page === 'lobby' && document.getElementById('door-difficulty').options.length > 1",
        20,
    )
    .await;
    assert_eq!(
        b.eval("document.getElementById('door-difficulty').value")
            .await,
        team
    );
    b.eval("document.getElementById('door-hunt').click()").await;
    b.wait_for(
        "__lasertag.role === 'player' && __lasertag.team === 'robots' && __lasertag.snapshots > 0",
        20,
    )
    .await;
}
