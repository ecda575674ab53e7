//! The web client in headless Chromium against a real server: spectate the showcase and check
//! the canvas's pixels; play with the keyboard; tag a robot; get tagged and see the end; play
//! through a proxy with a slow network's round trip; and watch finished matches again: the
//! history, the replay viewer's timeline (the belief drawn follows it), the player's view.
//!
//! Needs Chromium (`bash tests/run.sh` installs Debian's package when it is missing). With
//! `LASERTAG_SCREENSHOTS=<dir>` set, the test also saves its screenshots there (that is how
//! the ones in `docs/` were taken); otherwise it writes nothing outside a temporary profile.

#[path = "common/cdp.rs"]
#[allow(dead_code)] // the phone's helpers
mod cdp;
mod common;
#[path = "common/netem.rs"]
mod netem;

use std::time::Duration;

use cdp::Browser;
use common::TestServer;
use serde_json::{Value, json};

/// Counts the canvas's pixels of each kind the renderer draws (colours of `web/render.js`):
/// walls, robots, opponents, belief particles (any role colour at 60% over the floor).
const PIXELS: &str = r#"(() => {
  const c = document.getElementById('arena');
  const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  const hex = (h) => [1, 3, 5].map((i) => parseInt(h.slice(i, i + 2), 16));
  const floor = hex('#161c25');
  const near = (r, g, b, t, tol) => Math.abs(r - t[0]) + Math.abs(g - t[1]) + Math.abs(b - t[2]) <= tol;
  // Role colours over the floor at each confidence state's opacity (web/render.js STATE_ALPHA).
  const palette = ['#ffb000', '#00e0ff', '#ff5fd2', '#7dff6b', '#b48cff', '#ff8a3d', '#3de0c0', '#fff06a']
    .map(hex).flatMap((p) => [0.4, 0.55, 0.75].map((a) => p.map((v, i) => a * v + (1 - a) * floor[i])));
  const wall = hex('#3a4556'), robot = hex('#58a6ff'), frozen = hex('#9fb3c8'), opp = hex('#ff4d6d'), you = hex('#ffd166');
  const n = { wall: 0, robot: 0, opponent: 0, you: 0, particles: 0 };
  for (let i = 0; i < d.length; i += 4) {
    const r = d[i], g = d[i + 1], b = d[i + 2];
    if (near(r, g, b, wall, 6)) n.wall++;
    else if (near(r, g, b, robot, 12) || near(r, g, b, frozen, 12)) n.robot++;
    else if (near(r, g, b, opp, 12)) n.opponent++;
    else if (near(r, g, b, you, 12)) n.you++;
    else if (palette.some((p) => near(r, g, b, p, 24))) n.particles++;
  }
  return n;
})()"#;

async fn state(s: &TestServer, id: &str) -> Value {
    let r = s.get(&format!("/api/matches/{id}")).await;
    assert_eq!(r.status, 200, "{}", r.body);
    r.body
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn play_and_spectate_in_headless_chromium() {
    let s = TestServer::start().await;
    tokio::spawn(lasertag::game::showcase::keep_running(s.registry.clone()));
    let mut b = Browser::launch().await;
    let base = format!("http://{}", s.addr);

    // 1. The lobby shows the showcase; one click spectates it.
    b.navigate(&format!("{base}/")).await;
    b.wait_for("!document.getElementById('showcase').hidden", 20)
        .await;
    let rows = b
        .wait_for(
            "document.querySelectorAll('#matches tbody tr[data-id]').length",
            10,
        )
        .await;
    // The showcase (and, should one have ended live, the next one beside it while the
    // first's end is still held back from spectators).
    assert!(
        (1..=2).contains(&rows.as_u64().unwrap_or(0)),
        "{rows}: {}",
        s.get("/api/matches").await.body
    );
    b.eval("document.getElementById('name').value = 'tester'")
        .await;
    b.save("lobby.png").await;
    b.eval("document.getElementById('showcase-watch').click()")
        .await;
    // People may play the showcase, so spectators see it 30 s late (its first frame, this
    // early on), and the page says so.
    b.wait_for(
        "__lasertag.role === 'spectator' && __lasertag.snapshots > 0 && __lasertag.drawn.particles > 0",
        20,
    )
    .await;
    assert_eq!(b.eval("__lasertag.delay").await, json!(30));
    let hud = b
        .eval("document.getElementById('hud-match').textContent")
        .await;
    assert!(hud.as_str().unwrap().contains("delayed 30 s"), "{hud}");
    let drawn = b.eval("__lasertag.drawn").await;
    assert!(drawn["walls"].as_u64().unwrap() > 10, "{drawn}");
    assert_eq!(drawn["robots"], 2, "{drawn}");
    assert_eq!(drawn["opponents"], 5, "{drawn}");
    assert!(drawn["fans"].as_u64().unwrap() >= 1, "{drawn}");
    // Each robot's localisation cloud is drawn: a sample of its particles.
    assert!(drawn["localisation"].as_u64().unwrap() >= 20, "{drawn}");
    let px = b.eval(PIXELS).await;
    assert!(px["wall"].as_u64().unwrap() > 2000, "walls drawn: {px}");
    assert!(px["robot"].as_u64().unwrap() > 30, "robots drawn: {px}");
    assert!(
        px["opponent"].as_u64().unwrap() > 30,
        "opponents drawn: {px}"
    );
    assert!(
        px["particles"].as_u64().unwrap() > 100,
        "belief drawn: {px}"
    );
    b.save("spectator.png").await;
    // B switches the belief off: no particle is drawn any more.
    b.tap("KeyB", Duration::from_millis(50)).await;
    b.wait_for(
        "__lasertag.belief === false && __lasertag.drawn.particles === 0 && __lasertag.drawn.localisation === 0",
        5,
    )
    .await;
    tokio::time::sleep(Duration::from_millis(200)).await;
    let px = b.eval(PIXELS).await;
    assert!(
        px["particles"].as_u64().unwrap() < 20,
        "belief hidden: {px}"
    );

    // One more click from the lobby takes over one of the showcase's bots.
    b.navigate(&format!("{base}/#/")).await;
    b.wait_for("__lasertag.page === 'lobby' && !document.getElementById('showcase').hidden && !document.getElementById('showcase-play').disabled", 20)
        .await;
    b.eval("document.getElementById('showcase-play').click()")
        .await;
    b.wait_for(
        "__lasertag.role === 'player' && __lasertag.snapshots > 3",
        20,
    )
    .await;
    let listed = s.get("/api/matches").await.body;
    assert!(
        listed.as_array().unwrap().iter().any(|m| m["id"]
            .as_str()
            .unwrap()
            .starts_with("showcase-")
            && m["players"] == 1),
        "nobody plays a showcase: {listed}"
    );

    // 2. Play: a robot idles in the corridor in front of the player's opponent.
    let id = s.create_match(common::corridor_duel()).await;
    b.navigate(&format!("{base}/#/play/{id}")).await;
    // Wait for *this* match: until the page has fetched its token, `__lasertag` still
    // describes the showcase game it was playing (a race seen in CI).
    b.wait_for(
        &format!("__lasertag.matchId === '{id}' && __lasertag.role === 'player' && __lasertag.snapshots > 5 && __lasertag.drawn"),
        20,
    )
    .await;
    let controls = b
        .eval("document.getElementById('controls').textContent")
        .await;
    assert!(controls.as_str().unwrap().contains("Space"), "{controls}");
    // The robot in front is in sight, the one in a far room is not.
    let drawn = b.eval("__lasertag.drawn").await;
    assert_eq!(drawn["robots"], 1, "{drawn}");
    let px = b.eval(PIXELS).await;
    assert!(
        px["you"].as_u64().unwrap() > 30,
        "the player's own opponent: {px}"
    );
    // Space fires at the robot in front: the tag feed says so.
    b.tap("Space", Duration::from_millis(150)).await;
    let feed = b
        .wait_for(
            "[...document.querySelectorAll('#feed li.robot_tagged')].map((li) => li.textContent).join('|')",
            10,
        )
        .await;
    assert!(feed.as_str().unwrap().contains("r0"), "{feed}");
    b.wait_for("__lasertag.feed.some((f) => f.kind === 'robot_tagged')", 2)
        .await;
    // W drives forward: the server's state shows the opponent moved.
    let before = state(&s, &id).await["opponents"][0].clone();
    b.key("KeyW", true).await;
    tokio::time::sleep(Duration::from_millis(500)).await;
    b.save("player.png").await;
    tokio::time::sleep(Duration::from_millis(300)).await;
    b.key("KeyW", false).await;
    tokio::time::sleep(Duration::from_millis(200)).await;
    let after = state(&s, &id).await["opponents"][0].clone();
    let moved = after["x"].as_f64().unwrap() - before["x"].as_f64().unwrap();
    assert!(moved > 0.2, "moved {moved} m: {before} -> {after}");
    // The page numbers its inputs and predicts its own disc; the server's answers land
    // where the page had put it (corrections are what prediction got wrong, in metres).
    let p = b
        .eval("({sent: __lasertag.sent, ack: __lasertag.ack, own: __lasertag.own, worst: Math.max(0, ...(__lasertag.corrections || []))})")
        .await;
    assert!(
        p["sent"].as_u64() > Some(10) && p["ack"].as_u64() > Some(10),
        "{p}"
    );
    assert!(p["own"]["x"].as_f64().unwrap() > 3.2, "{p}");
    assert!(p["worst"].as_f64().unwrap() < 0.05, "{p}");
    // A turns it.
    b.tap("KeyA", Duration::from_millis(400)).await;
    tokio::time::sleep(Duration::from_millis(200)).await;
    let turned = state(&s, &id).await["opponents"][0]["theta"]
        .as_f64()
        .unwrap();
    assert!(turned > 0.3, "theta {turned}");

    // 3. Get tagged: a coordinated robot 9 m down the corridor, facing away, searches, finds
    // the player standing still and tags it (within seconds: the corridor behind it is the
    // nearest unseen space). A random (baseline) searcher made this depend on the seed.
    // Should a robot ever tag the empty slot before the page has joined, try another match
    // (people may join it: the server chooses its secret seed).
    let mut ended = None;
    for _ in 0..4 {
        let id = s
            .create_match(json!({"map": "office", "robots": 1, "opponents": 1,
                "opponent_control": "human", "planner": "coordinated", "time_limit_s": 120,
                "robot_starts": [[12.0, 8.0, 0.0]],
                "opponent_starts": [[3.0, 8.0]]}))
            .await;
        b.navigate(&format!("{base}/#/play/{id}")).await;
        let got = b
            .wait_for(
                &format!("(__lasertag.matchId === '{id}' && __lasertag.snapshots > 0) || __lasertag.joinError"),
                20,
            )
            .await;
        if got.is_string() {
            b.eval("delete __lasertag.joinError").await;
            continue;
        }
        // The secret seed decides how long the search takes (seconds, mostly): wait for the
        // match's own end, its time limit at the latest, and then ask who won.
        b.wait_for(
            "__lasertag.ended && !document.getElementById('end').hidden",
            130,
        )
        .await;
        assert_eq!(state(&s, &id).await["winner"], "robots");
        ended = Some(id);
        break;
    }
    let ended = ended.expect("no seed let the page join before the robot's tag");
    let title = b
        .eval("document.getElementById('end-title').textContent")
        .await;
    assert!(
        title.as_str().unwrap().contains("robots win"),
        "end screen: {title}"
    );
    let text = b
        .eval("document.getElementById('end-text').textContent")
        .await;
    assert!(text.as_str().unwrap().contains("tagged"), "{text}");
    b.save("end.png").await;
    // The end screen copies a link to the replay's last moment, from the player's view.
    b.eval("document.getElementById('end-share').click()").await;
    let link = b.wait_for("__lasertag.sharedLink", 5).await;
    let link = link.as_str().unwrap();
    assert!(
        link.contains(&format!("#/replay/{ended}?t=")) && link.contains("pov=o0"),
        "{link}"
    );
    // The end screen opens the replay from the player's own view (tried again while the
    // match becomes a replay).
    b.eval("document.getElementById('end-watch').click()").await;
    b.wait_for(
        &format!("__lasertag.page === 'replay' && __lasertag.replayId === '{ended}' && __lasertag.view === 'o0' && __lasertag.snapView === 'player' && __lasertag.drawn"),
        20,
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn over_a_slow_network_a_key_moves_the_players_disc_at_once() {
    let s = TestServer::start().await;
    // 300 ms round trip: an input needs at least 150 ms to reach the server, and its
    // acknowledgement 150 ms more to come back.
    let net = netem::Netem::start(s.addr, netem::Conditions::rtt_ms(300)).await;
    let mut b = Browser::launch().await;
    let base = format!("http://{}", net.addr);
    let id = s
        .create_match(json!({"map": "office", "robots": 2, "opponents": 1,
            "opponent_control": "human", "planner": "idle", "time_limit_s": 120,
            "robot_starts": [[22.0, 1.5, 0.0], [22.0, 14.0, 0.0]],
            "opponent_starts": [[6.0, 8.0]]}))
        .await;
    b.navigate(&format!("{base}/#/play/{id}")).await;
    b.wait_for(
        &format!("__lasertag.matchId === '{id}' && __lasertag.role === 'player' && __lasertag.snapshots > 10 && __lasertag.own && __lasertag.ack > 0"),
        30,
    )
    .await;
    b.eval("window.__before = { sent: __lasertag.sent, x: __lasertag.own.x, y: __lasertag.own.y }")
        .await;
    b.key("KeyW", true).await;
    // The disc moves on the page before the server has applied any input sent after the
    // press: it is predicted, not waited for.
    let at_move = b
        .wait_for(
            "Math.hypot(__lasertag.own.x - __before.x, __lasertag.own.y - __before.y) > 0.01 && ({ack: __lasertag.ack, before: __before.sent})",
            5,
        )
        .await;
    assert!(
        at_move["ack"].as_u64() <= at_move["before"].as_u64(),
        "the disc waited for the server: {at_move}"
    );
    tokio::time::sleep(Duration::from_millis(600)).await;
    b.key("KeyW", false).await;
    // Once the server's answers are in (a round trip and a bit), they agree with where the
    // page had put it. An input that reaches the server after its tick (a busy machine
    // running three browsers) finds the last keys held for that tick, as the protocol says:
    // one tick of travel (1 m/s × 50 ms) is the most a correction may be.
    tokio::time::sleep(Duration::from_millis(800)).await;
    let worst = b
        .eval("Math.max(0, ...(__lasertag.corrections || []))")
        .await;
    assert!(
        worst.as_f64().unwrap() <= 0.05 + 1e-9,
        "corrections up to {worst} m"
    );
}

/// Counts the belief's pixels (the role colours, as in [`PIXELS`]) in each cell of a 12 × 8
/// grid over the canvas: where the belief is drawn, not only how much of it.
const BELIEF_GRID: &str = r#"(() => {
  const c = document.getElementById('arena');
  const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  const hex = (h) => [1, 3, 5].map((i) => parseInt(h.slice(i, i + 2), 16));
  const floor = hex('#161c25');
  const near = (r, g, b, t, tol) => Math.abs(r - t[0]) + Math.abs(g - t[1]) + Math.abs(b - t[2]) <= tol;
  const palette = ['#ffb000', '#00e0ff', '#ff5fd2', '#7dff6b', '#b48cff', '#ff8a3d', '#3de0c0', '#fff06a']
    .map(hex).flatMap((p) => [0.4, 0.55, 0.75].map((a) => p.map((v, i) => a * v + (1 - a) * floor[i])));
  const grid = new Array(96).fill(0);
  for (let y = 0; y < c.height; y += 2) {
    for (let x = 0; x < c.width; x += 2) {
      const i = (y * c.width + x) * 4;
      if (palette.some((p) => near(d[i], d[i + 1], d[i + 2], p, 24))) {
        grid[Math.floor((y * 8) / c.height) * 12 + Math.floor((x * 12) / c.width)]++;
      }
    }
  }
  return grid;
})()"#;

/// Moves the replay's timeline to `tick` as a person dragging it would (the range input's
/// `input` event), and waits for that tick's snapshot to be drawn.
async fn scrub(b: &mut Browser, tick: u64) -> Vec<f64> {
    b.eval(&format!(
        "(() => {{ const t = document.getElementById('replay-timeline'); t.value = '{tick}'; t.dispatchEvent(new Event('input', {{bubbles: true}})); }})()"
    ))
    .await;
    b.wait_for(&format!("__lasertag.lastTick === {tick}"), 10)
        .await;
    // A few frames, so the canvas shows it.
    tokio::time::sleep(Duration::from_millis(300)).await;
    let grid = b.eval(BELIEF_GRID).await;
    grid.as_array()
        .expect("a grid")
        .iter()
        .map(|v| v.as_f64().unwrap_or(0.0))
        .collect()
}

/// A manual match stepped to its end (or stopped after `ticks`); its id once it is a replay.
async fn finished(s: &TestServer, request: Value, ticks: u64, player: Option<&str>) -> String {
    let id = s.create_match(request).await;
    if let Some(name) = player {
        s.join(&id, name).await;
    }
    let end = s.step(&id, ticks).await;
    if end["status"] != "finished" {
        assert_eq!(s.delete(&format!("/api/matches/{id}")).await.status, 204);
    }
    for _ in 0..50 {
        if s.get(&format!("/api/replays/{id}")).await.status == 200 {
            return id;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    panic!("{id} never became a replay");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn history_and_replays_in_headless_chromium() {
    let s = TestServer::start().await;
    // A few finished matches for the history: one stopped, one held out to the time limit,
    // one with a person standing still, and bots hunted down (the one replayed below).
    finished(
        &s,
        json!({"map": "warehouse", "robots": 3, "opponents": 2, "clock": "manual", "seed": 2}),
        100,
        None,
    )
    .await;
    finished(
        &s,
        json!({"map": "hallway", "robots": 1, "opponents": 2, "clock": "manual",
            "planner": "idle", "time_limit_s": 15, "seed": 4}),
        400,
        None,
    )
    .await;
    finished(
        &s,
        json!({"map": "maze", "robots": 2, "opponents": 1, "clock": "manual",
            "opponent_control": "human", "time_limit_s": 60}),
        1200,
        Some("ada"),
    )
    .await;
    let id = finished(
        &s,
        json!({"map": "office", "robots": 2, "opponents": 3, "clock": "manual",
            "opponent_bot": "evade", "time_limit_s": 30, "seed": 3}),
        600,
        None,
    )
    .await;
    let mut b = Browser::launch().await;
    let base = format!("http://{}", s.addr);

    // The history lists them, newest first, and opens each one's replay.
    b.navigate(&format!("{base}/")).await;
    b.wait_for("__lasertag.page === 'lobby'", 20).await;
    b.eval("document.getElementById('lobby-history').click()")
        .await;
    let rows = b
        .wait_for(
            "__lasertag.page === 'history' && __lasertag.historyRows",
            10,
        )
        .await;
    assert_eq!(rows, json!(4));
    let first = b
        .eval("document.querySelector('#history-table tbody tr').dataset.id")
        .await;
    assert_eq!(first, json!(id));
    let names = b
        .eval("document.getElementById('history-table').textContent")
        .await;
    assert!(names.as_str().unwrap().contains("ada"), "{names}");
    b.save("history.png").await;
    b.eval("document.querySelector('#history-table tbody tr button.watch').click()")
        .await;

    // The replay plays from the start, with the match's events on its timeline.
    b.wait_for(
        &format!("__lasertag.page === 'replay' && __lasertag.replayId === '{id}' && __lasertag.playing === true && __lasertag.snapshots > 5 && __lasertag.drawn"),
        20,
    )
    .await;
    assert!(b.eval("__lasertag.markers").await.as_u64() > Some(0));
    let drawn = b.eval("__lasertag.drawn").await;
    assert_eq!(drawn["robots"], 2, "{drawn}");
    assert!(drawn["particles"].as_u64() > Some(50), "{drawn}");
    b.eval("document.getElementById('replay-play').click()")
        .await;
    b.wait_for("__lasertag.playing === false", 5).await;

    // Scrubbed, the belief drawn is that tick's: everywhere unseen at the start, on the
    // opponents the robots have found later.
    let start = scrub(&mut b, 0).await;
    let later = scrub(&mut b, 260).await;
    let total = |g: &[f64]| g.iter().sum::<f64>();
    assert!(
        total(&start) > 100.0 && total(&later) > 20.0,
        "{start:?} {later:?}"
    );
    let moved: f64 = start
        .iter()
        .zip(&later)
        .map(|(a, b)| (a / total(&start) - b / total(&later)).abs())
        .sum();
    assert!(
        moved > 0.3,
        "the belief drawn did not follow the timeline: {moved}"
    );
    // And back: the same tick draws the same belief.
    let again = scrub(&mut b, 0).await;
    assert_eq!(again, start);
    scrub(&mut b, 178).await;
    b.eval("document.querySelector('#replay-speeds [data-speed=\"2\"]').click()")
        .await;
    b.wait_for("__lasertag.speed === 2", 5).await;
    b.save("replay.png").await;
    // B hides the belief, as in the game.
    b.tap("KeyB", Duration::from_millis(50)).await;
    b.wait_for(
        "__lasertag.belief === false && __lasertag.drawn.particles === 0",
        5,
    )
    .await;

    // A player's view: fogged, and a switch to everyone's.
    let listed = s.get("/api/replays").await.body;
    assert_eq!(listed[1]["map"], "maze", "{listed}");
    let maze = listed[1]["id"].as_str().expect("an id").to_string();
    b.navigate(&format!("{base}/#/replay/{maze}?as=o0")).await;
    b.wait_for(
        &format!("__lasertag.replayId === '{maze}' && __lasertag.view === 'o0' && __lasertag.snapView === 'player' && __lasertag.drawn"),
        20,
    )
    .await;
    let label = b
        .eval("document.getElementById('replay-view').textContent")
        .await;
    assert_eq!(label, json!("full view"));
    b.eval("document.getElementById('replay-view').click()")
        .await;
    b.wait_for(
        "__lasertag.view === 'full' && __lasertag.snapView === 'spectator' && location.hash.includes('pov=full')",
        10,
    )
    .await;

    // A link to a moment: paused at tick 100 in the full view with the belief off, copied,
    // then opened from elsewhere, lands at that moment, paused, in that view, belief off.
    b.eval("document.getElementById('replay-play').click()")
        .await;
    b.wait_for("__lasertag.playing === false", 5).await;
    scrub(&mut b, 100).await;
    if b.eval("__lasertag.belief").await == json!(true) {
        b.tap("KeyB", Duration::from_millis(50)).await;
    }
    b.wait_for("__lasertag.belief === false", 5).await;
    b.eval("delete __lasertag.sharedLink").await;
    b.eval("document.getElementById('replay-share').click()")
        .await;
    let link = b.wait_for("__lasertag.sharedLink", 5).await;
    let link = link.as_str().unwrap().to_string();
    assert!(
        link.ends_with(&format!("#/replay/{maze}?t=5&pov=full&belief=0&as=o0")),
        "{link}"
    );
    b.navigate(&format!("{base}/#/history")).await;
    b.wait_for("__lasertag.page === 'history'", 10).await;
    b.navigate(&link).await;
    b.wait_for(
        &format!("__lasertag.page === 'replay' && __lasertag.replayId === '{maze}' && __lasertag.lastTick === 100 && __lasertag.playing === false && __lasertag.view === 'full' && __lasertag.belief === false && __lasertag.drawn"),
        20,
    )
    .await;
    // And from the player's view with the belief on, at 2.5 s.
    b.navigate(&format!("{base}/#/replay/{maze}?t=2.5&pov=o0&belief=1"))
        .await;
    b.wait_for(
        &format!("__lasertag.replayId === '{maze}' && __lasertag.lastTick === 50 && __lasertag.playing === false && __lasertag.view === 'o0' && __lasertag.snapView === 'player' && __lasertag.belief === true"),
        20,
    )
    .await;

    // The leaderboard says plainly when there are no statistics (yet).
    b.navigate(&format!("{base}/#/leaderboard")).await;
    let board = b
        .wait_for(
            "__lasertag.page === 'leaderboard' && __lasertag.leaderboard !== null && [__lasertag.leaderboard]",
            10,
        )
        .await;
    let board = board[0].clone();
    if board == json!("none") {
        let text = b
            .eval("document.getElementById('leaderboard-body').textContent")
            .await;
        assert!(
            text.as_str().unwrap().contains("No statistics yet"),
            "{text}"
        );
    }
    assert_ne!(board, json!("error"));
}
