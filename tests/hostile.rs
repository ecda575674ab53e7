//! A hostile visitor's battery: requests and connections chosen to be expensive or to take
//! what is not theirs. Each test asserts the refusal, that a match running beside it kept
//! ticking, and that the server's resident memory stayed under a bound.

mod common;

use std::time::Duration;

use common::{TestServer, assert_error, test_config};
use lasertag::config::Config;
use serde_json::json;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

/// Resident memory of this process (the server runs in it), in MiB.
fn resident_mib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .map_or(0, |kib| kib / 1024)
}

/// The most this test process may hold: the server, its matches and the test's clients.
const RESIDENT_BOUND_MIB: u64 = 1024;

/// A real-time match with idle robots (it runs to its time limit) to watch for starvation.
async fn bystander(s: &TestServer) -> String {
    s.create_match(json!({"map": "office", "planner": "idle"}))
        .await
}

async fn tick_of(s: &TestServer, id: &str) -> u64 {
    let r = s.get(&format!("/api/matches/{id}")).await;
    assert_eq!(r.status, 200, "{}", r.body);
    r.body["tick"].as_u64().unwrap()
}

/// The bystander has moved past `since`, the server answers, and memory is bounded.
async fn unharmed(s: &TestServer, id: &str, since: u64) {
    let mut tick = since;
    for _ in 0..200 {
        tick = tick_of(s, id).await;
        if tick > since {
            break;
        }
        tokio::time::sleep(Duration::from_millis(25)).await;
    }
    assert!(tick > since, "the bystander match is stuck at tick {tick}");
    assert_eq!(s.get("/api/health").await.status, 200);
    let rss = resident_mib();
    assert!(rss < RESIDENT_BOUND_MIB, "resident memory {rss} MiB");
}

/// Creates cheap manual matches until one is refused: how many were admitted, and the
/// refusal.
async fn until_refused(s: &TestServer) -> (usize, common::Reply) {
    for admitted in 0..30 {
        let r = s
            .post("/api/matches", &json!({"map": "office", "clock": "manual"}))
            .await;
        if r.status != 201 {
            return (admitted, r);
        }
    }
    panic!("30 matches admitted: no budget ran out");
}

/// Reads until the server closes the connection; false if it is still open after `wait`.
async fn closed_within(stream: &mut TcpStream, wait: Duration) -> bool {
    let mut buf = [0u8; 1024];
    let deadline = tokio::time::Instant::now() + wait;
    loop {
        match tokio::time::timeout_at(deadline, stream.read(&mut buf)).await {
            Err(_) => return false,
            Ok(Ok(0)) | Ok(Err(_)) => return true,
            Ok(Ok(_)) => {} // a 408 or similar before the close
        }
    }
}

#[tokio::test]
async fn a_slow_client_is_cut_off_and_the_connection_cap_holds() {
    let s = TestServer::start_with(Config {
        header_read_timeout: Duration::from_millis(300),
        max_connections: Some(8),
        ..test_config()
    })
    .await;
    let live = bystander(&s).await;
    let t0 = tick_of(&s, &live).await;
    // Half a header, then nothing: closed once the header read timeout has passed (the
    // wait is generous; the point is that it closes at all).
    let mut slow = TcpStream::connect(s.addr).await.unwrap();
    slow.write_all(b"GET /api/health HTTP/1.1\r\nHost: x\r\n")
        .await
        .unwrap();
    assert!(
        closed_within(&mut slow, Duration::from_secs(10)).await,
        "a half-sent header held its connection"
    );
    // An idle keep-alive connection goes the same way.
    let mut idle = TcpStream::connect(s.addr).await.unwrap();
    idle.write_all(b"GET /api/health HTTP/1.1\r\nHost: x\r\n\r\n")
        .await
        .unwrap();
    assert!(closed_within(&mut idle, Duration::from_secs(10)).await);

    // Far more half-open connections than the cap (the rest wait in the backlog): the
    // server serves again once the header timeout has cut them off.
    let mut hogs = Vec::new();
    for _ in 0..40 {
        if let Ok(mut c) = TcpStream::connect(s.addr).await {
            let _ = c.write_all(b"GET / HTTP/1.1\r\n").await;
            hogs.push(c);
        }
    }
    unharmed(&s, &live, t0).await;
    drop(hogs);
}

#[tokio::test]
async fn the_lobby_answers_while_a_match_steps_a_long_way() {
    let s = TestServer::start().await;
    let live = bystander(&s).await;
    let t0 = tick_of(&s, &live).await;
    let busy = s
        .create_match(json!({"map": "warehouse", "clock": "manual", "robots": 8, "opponents": 8, "time_limit_s": 3600}))
        .await;
    let token = s.owner_token(&format!("/api/matches/{busy}")).unwrap();
    let stepper = {
        let client = s.client.clone();
        let url = s.url(&format!("/api/matches/{busy}/step"));
        tokio::spawn(async move {
            client
                .post(url)
                .bearer_auth(token)
                .json(&json!({"ticks": 20000}))
                .send()
                .await
                .map(|r| r.status().as_u16())
        })
    };
    // The listing reads published summaries: it answers while the task is stepping (the
    // step request itself is still running when the listing comes back).
    tokio::time::sleep(Duration::from_millis(200)).await;
    let listing = s.get("/api/matches").await;
    assert_eq!(listing.status, 200);
    let ids: Vec<&str> = listing
        .body
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|m| m["id"].as_str())
        .collect();
    assert!(ids.contains(&busy.as_str()) && ids.contains(&live.as_str()));
    assert!(
        !stepper.is_finished(),
        "the step was too short to show anything"
    );
    unharmed(&s, &live, t0).await;
    stepper.abort();
}

#[tokio::test]
async fn a_stranger_cannot_end_someone_elses_match() {
    let s = TestServer::start().await;
    let live = bystander(&s).await;
    let t0 = tick_of(&s, &live).await;
    let path = format!("/api/matches/{live}");
    assert_error(&s.delete_as(&path, None).await, 401, "owner_token");
    assert_error(
        &s.delete_as(&path, Some("0123456789abcdef0123456789abcdef"))
            .await,
        403,
        "owner_token",
    );
    unharmed(&s, &live, t0).await;
}

/// A 500 m map whose thin obstacles run corner to corner: a small body whose long
/// diagonal walls were the costliest thing to build.
fn diagonal_slivers(n: usize) -> serde_json::Value {
    let obstacles: Vec<_> = (0..n)
        .map(|k| {
            let y = 20.0 + k as f64 * 0.02;
            json!([[10.0, y], [470.0, y + 460.0], [470.5, y + 460.0], [10.5, y]])
        })
        .collect();
    json!({"name": "slivers", "width": 500.0, "height": 500.0, "obstacles": obstacles,
           "robot_spawns": [[2.0, 2.0, 0.0]], "opponent_spawns": [[498.0, 2.0]]})
}

#[tokio::test]
async fn expensive_maps_are_priced_and_refused_before_they_are_built() {
    let s = TestServer::start().await;
    let live = bystander(&s).await;
    let t0 = tick_of(&s, &live).await;
    let before = resident_mib();
    // A 3 KB body that would take seconds of CPU to build (and, with the old segment
    // index, hundreds of megabytes).
    let r = s.post("/api/maps", &diagonal_slivers(64)).await;
    assert_error(&r, 400, "s of CPU to build");
    assert_eq!(s.get("/api/maps/slivers").await.status, 404);
    // The same inside a match.
    let r = s
        .post("/api/matches", &json!({"map": diagonal_slivers(64)}))
        .await;
    assert_error(&r, 400, "limit of 2 s");
    // Counts that drove validation or ticks are bounded by the format.
    let mut m = common::duel_map();
    m["landmarks"] = json!(vec![[5.0, 2.0]; 300]);
    assert_error(&s.post("/api/maps", &m).await, 400, "limit is 256");
    let mut m = common::duel_map();
    m["opponent_spawns"] = json!(vec![[12.0, 2.0]; 65]);
    assert_error(&s.post("/api/maps", &m).await, 400, "limit is 64");
    unharmed(&s, &live, t0).await;
    assert!(
        resident_mib() < before + 200,
        "memory grew by more than 200 MiB"
    );
}

#[tokio::test]
async fn an_expensive_match_is_priced_and_refused_before_it_is_built() {
    let s = TestServer::start().await;
    let live = bystander(&s).await;
    let t0 = tick_of(&s, &live).await;
    let before = resident_mib();
    // 335 bytes that held 1.5 GB: a big empty map, eight robots each with its own tracker
    // behind a lossy radio, and a fine merge grid.
    let big = json!({"name": "big", "width": 500.0, "height": 500.0, "obstacles": [],
                     "robot_spawns": [[2.0, 2.0, 0.0]], "opponent_spawns": [[498.0, 498.0]]});
    let r = s
        .post(
            "/api/matches",
            &json!({"map": big, "robots": 8, "opponents": 8,
                    "radio": {"loss": 0.5}, "tracker": {"grid_cell": 0.1}}),
        )
        .await;
    assert_error(&r, 400, "limit of 512 MB per request");
    // Eight robots on a big map, each with its own tracker of 40,000 particles behind a
    // lossy radio: cheap in memory, too slow a tick.
    let r = s
        .post(
            "/api/matches",
            &json!({"map": big, "robots": 8, "opponents": 8, "radio": {"loss": 0.5},
                    "tracker": {"particles_per_role": 5000}}),
        )
        .await;
    assert_error(&r, 400, "ms per match");
    unharmed(&s, &live, t0).await;
    assert!(
        resident_mib() < before + 200,
        "memory grew by more than 200 MiB"
    );
}

#[tokio::test]
async fn the_servers_budget_refuses_what_it_cannot_hold() {
    let s = TestServer::start_with(Config {
        memory_budget_mb: 60,
        ..test_config()
    })
    .await;
    let live = bystander(&s).await;
    let t0 = tick_of(&s, &live).await;
    let (_, r) = until_refused(&s).await;
    assert_error(&r, 503, "memory budget of 60 MB");
    unharmed(&s, &live, t0).await;
}

#[tokio::test]
async fn one_client_holds_at_most_its_share_of_the_budget() {
    let s = TestServer::start_with(Config {
        memory_budget_mb: 60,
        client_budget_share: 0.5,
        ..test_config()
    })
    .await;
    let live = bystander(&s).await;
    let t0 = tick_of(&s, &live).await;
    // Refused as a client (429, naming its share), long before the server's budget is gone.
    let (admitted, r) = until_refused(&s).await;
    assert_error(&r, 429, "past the share one client may hold (30 MB");
    assert!(admitted >= 1, "{admitted}");
    unharmed(&s, &live, t0).await;
}

/// Every setting that changes what a tick costs enters the match's price: a `search`
/// planner looking six poses deep over twelve branches each turn (seconds a tick) is refused
/// at its price, as is one choosing every tick four deep; the default search is let in.
#[tokio::test]
async fn a_deep_wide_search_planner_is_refused_at_its_price() {
    let s = TestServer::start().await;
    let live = bystander(&s).await;
    let t0 = tick_of(&s, &live).await;
    for coordination in [
        json!({"search_depth": 6, "search_branching": 12, "round_ticks": 1}),
        json!({"search_depth": 6, "search_branching": 12}),
        json!({"search_depth": 5, "search_branching": 12}),
    ] {
        let r = s
            .post(
                "/api/matches",
                &json!({"map": "office", "planner": "search", "coordination": coordination}),
            )
            .await;
        assert_error(&r, 400, "ms of CPU");
    }
    let r = s
        .post(
            "/api/matches",
            &json!({"map": "office", "planner": "search"}),
        )
        .await;
    assert_eq!(r.status, 201, "{}", r.body);
    unharmed(&s, &live, t0).await;
}

#[tokio::test]
async fn a_big_belief_is_thinned_on_request_and_its_reader_priced() {
    let s = TestServer::start_with(Config {
        belief_mb_per_s: 4.0,
        belief_mb_per_s_all: 1000.0,
        ..test_config()
    })
    .await;
    let live = bystander(&s).await;
    let t0 = tick_of(&s, &live).await;
    let id = s
        .create_match(
            json!({"map": "office", "clock": "manual", "robots": 1, "opponents": 1,
            "tracker": {"particles_per_role": 100000}}),
        )
        .await;
    s.step(&id, 1).await;
    let path = format!("/api/matches/{id}/belief");

    // Thinned: every role at most the particles asked for, weights still summing to one.
    let thin = s.get(&format!("{path}?particles=50")).await;
    assert_eq!(thin.status, 200, "{}", thin.body);
    for role in thin.body["roles"].as_array().unwrap() {
        let n = role["particles"].as_array().unwrap().len();
        assert!((1..=50).contains(&n), "{n} particles");
        let total: f64 = role["weights"]
            .as_array()
            .unwrap()
            .iter()
            .map(|w| w.as_f64().unwrap())
            .sum();
        assert!((total - 1.0).abs() < 1e-6, "weights sum to {total}");
    }
    for bad in ["0", "100001", "many", "-3"] {
        assert_error(
            &s.get(&format!("{path}?particles={bad}")).await,
            400,
            "particles",
        );
    }

    // The whole cloud, as fast as one address can ask: a few reads, then 429 saying when
    // to come back and how to read less.
    let reader = reqwest::Client::new();
    let mut full = 0;
    let refusal = loop {
        let r = reader.get(s.url(&path)).send().await.unwrap();
        if r.status() != 200 {
            break r;
        }
        let body: serde_json::Value = r.json().await.unwrap();
        assert_eq!(
            body["roles"][0]["particles"].as_array().unwrap().len(),
            100_000
        );
        full += 1;
        assert!(
            full < 10,
            "{full} full reads of a 100,000-particle belief, no 429"
        );
    };
    assert!(full >= 1, "the first read of a full belief goes through");
    assert_eq!(refusal.status(), 429);
    let wait: u64 = refusal.headers()["retry-after"]
        .to_str()
        .unwrap()
        .parse()
        .unwrap();
    assert!(wait >= 1, "Retry-After: {wait}");
    let text = refusal.text().await.unwrap();
    assert!(text.contains("?particles=N"), "{text}");

    // Another address is not charged for it.
    let other = reqwest::Client::builder()
        .local_address(std::net::IpAddr::V4(std::net::Ipv4Addr::new(127, 0, 0, 23)))
        .build()
        .unwrap();
    let r = other
        .get(s.url(&format!("{path}?particles=1000")))
        .header("accept-encoding", "gzip")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["content-encoding"], "gzip");
    let body = r.bytes().await.unwrap();
    assert_eq!(&body[..2], &[0x1f, 0x8b], "a gzip stream");
    unharmed(&s, &live, t0).await;
}

#[tokio::test]
async fn a_match_that_keeps_overrunning_its_ticks_is_ended() {
    // Every tick overruns a budget of a microsecond: the match is ended after 100 of them,
    // whatever its time limit, and the overruns are counted.
    let s = TestServer::start_with(Config {
        tick_overrun_ms: 0.001,
        ..test_config()
    })
    .await;
    let id = s
        .create_match(json!({"map": "office", "clock": "manual"}))
        .await;
    let state = s.step(&id, 1000).await;
    assert_eq!(state["status"], "finished");
    assert_eq!(state["tick"], 100, "ended at the hundredth overrun");
    let events = s.events(&id).await;
    let finished = events.last().unwrap();
    assert_eq!(finished["kind"], "finished");
    assert_eq!(finished["reason"], "overloaded");
    assert_eq!(finished["winner"], serde_json::Value::Null);
    let metrics = s.client.get(s.url("/metrics")).send().await.unwrap();
    let text = metrics.text().await.unwrap();
    assert!(text.contains("lasertag_tick_overruns_total 100"), "{text}");
}

#[tokio::test]
async fn a_match_people_play_shows_its_truth_late_to_all_but_its_owner() {
    let s = TestServer::start().await;
    let bots = bystander(&s).await;
    let t0 = tick_of(&s, &bots).await;
    // The default delay (30 s) is longer than this test: nothing after the first frame may
    // reach anyone but the owner and the player's own fogged socket.
    let created = s
        .post(
            "/api/matches",
            &json!({"map": "office", "robots": 2, "opponent_control": "human"}),
        )
        .await;
    assert_eq!(created.status, 201, "{}", created.body);
    assert_eq!(created.body["spectator_delay_s"], 30.0);
    let id = created.body["id"].as_str().unwrap().to_string();
    let (_, token) = s.join(&id, "mallory").await;
    let mut player = s.ws(&id, Some(&token)).await.unwrap();
    let welcome = player.json().await;
    assert_eq!(welcome["spectator_delay_s"], 30.0);
    while tick_of(&s, &id).await < 40 {
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // The same person in a second tab: state, belief, events and a spectator socket.
    let path = format!("/api/matches/{id}");
    let state = s.get_as(&path, None).await;
    assert_eq!(
        state.body["tick"], 0,
        "the public state is live: {}",
        state.body
    );
    let belief = s.get_as(&format!("{path}/belief"), None).await;
    assert_eq!(belief.body["tick"], 0);
    let robot = s.get_as(&format!("{path}/belief?robot=r1"), None).await;
    assert_eq!(robot.body["tick"], 0);
    let public: Vec<String> = s.get_as(&format!("{path}/events"), None).await.body["events"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["kind"].as_str().unwrap().to_owned())
        .collect();
    assert!(public.is_empty(), "events shown live: {public:?}");
    let mut spectator = s.ws(&id, None).await.unwrap();
    let welcome = spectator.json().await;
    assert_eq!(welcome["spectator_delay_s"], 30.0);
    assert_eq!(spectator.next_of("snapshot").await["tick"], 0);
    // The player's own socket stays live (and fogged); the owner sees everything live.
    let mut mine = 0;
    while mine < 40 {
        mine = player.next_of("snapshot").await["tick"].as_u64().unwrap();
    }
    assert!(s.get(&format!("{path}/belief")).await.body["tick"].as_u64() > Some(0));
    let owned = s.events(&id).await;
    assert!(
        owned.iter().any(|e| e["kind"] == "player_joined"),
        "{owned:?}"
    );
    // A token that is not the owner's (the player's own, say) opens nothing.
    assert_error(&s.get_as(&path, Some(&token)).await, 403, "owner_token");
    // A match nobody plays is live for everyone.
    let headless = s.post("/api/matches", &json!({"map": "office"})).await;
    assert_eq!(headless.body["spectator_delay_s"], 0.0);
    let headless = headless.body["id"].as_str().unwrap().to_string();
    let mut tick = 0;
    while tick == 0 {
        tokio::time::sleep(Duration::from_millis(50)).await;
        tick = s
            .get_as(&format!("/api/matches/{headless}"), None)
            .await
            .body["tick"]
            .as_u64()
            .unwrap();
    }
    unharmed(&s, &bots, t0).await;
}

#[tokio::test]
async fn spectators_follow_a_held_back_match_to_its_end() {
    let s = TestServer::start().await;
    // Held back half a second (10 ticks), over in two.
    let id = s
        .create_match(
            json!({"map": "office", "opponent_control": "human", "planner": "idle",
            "time_limit_s": 2, "spectator_delay_s": 0.5}),
        )
        .await;
    let path = format!("/api/matches/{id}");
    let mut spectator = s.ws(&id, None).await.unwrap();
    assert_eq!(spectator.json().await["spectator_delay_s"], 0.5);
    let mut checked = 0;
    loop {
        let before = tick_of(&s, &id).await;
        let public = s.get_as(&path, None).await.body;
        let after = tick_of(&s, &id).await;
        let shown = public["tick"].as_u64().unwrap();
        if public["status"] == "finished" {
            // Over: nothing is left to hide.
            assert_eq!(shown, 40);
            break;
        }
        // Released once 10 ticks old, and not before (the first frame is shown from the
        // start).
        assert!(
            (shown == 0 || shown + 10 <= after) && (before < 10 || shown + 10 >= before),
            "shown {shown}, live {before}..{after}"
        );
        checked += 1;
        tokio::time::sleep(Duration::from_millis(30)).await;
    }
    assert!(checked > 5, "{checked} reads while running");
    // The spectator sees every tick's frame in order, up to the last, then `finished`.
    let mut last = 0;
    loop {
        let m = spectator.json().await;
        match m["type"].as_str() {
            Some("snapshot") => {
                let tick = m["tick"].as_u64().unwrap();
                assert!(tick >= last, "tick {tick} after {last}");
                last = tick;
            }
            Some("finished") => break,
            _ => {}
        }
    }
    assert_eq!(last, 40, "the spectator saw the match's last tick");
}
