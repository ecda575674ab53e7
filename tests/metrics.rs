//! `GET /metrics`: every family is there in the Prometheus text format, and the
//! numbers move with what the server does.

mod common;

use std::collections::HashMap;
use std::time::Duration;

use common::{TestServer, test_config};
use serde_json::json;

/// `name{labels} value` lines of the exposition, keyed by everything before the value.
async fn scrape(s: &TestServer) -> (String, HashMap<String, f64>) {
    let r = s.client.get(s.url("/metrics")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let ct = r
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default()
        .to_string();
    assert!(ct.starts_with("text/plain; version=0.0.4"), "{ct}");
    let text = r.text().await.unwrap();
    let values = text
        .lines()
        .filter(|l| !l.starts_with('#') && !l.is_empty())
        .filter_map(|l| {
            let (k, v) = l.rsplit_once(' ')?;
            Some((k.to_string(), v.parse().ok()?))
        })
        .collect();
    (text, values)
}

fn get(values: &HashMap<String, f64>, key: &str) -> f64 {
    *values
        .get(key)
        .unwrap_or_else(|| panic!("no series {key} in {:?}", values.keys()))
}

#[tokio::test]
async fn metrics_expose_every_family_and_they_move() {
    let s = TestServer::start().await;
    let (text, before) = scrape(&s).await;
    for family in [
        "lasertag_matches",
        "lasertag_clients",
        "lasertag_tick_seconds",
        "lasertag_snapshot_bytes_total",
        "lasertag_refused_total",
        "lasertag_planner_seconds",
        "lasertag_tracker_seconds",
        "lasertag_matches_removed_total",
    ] {
        assert!(
            text.contains(&format!("# TYPE {family} ")),
            "{family} missing:\n{text}"
        );
    }
    assert_eq!(get(&before, "lasertag_matches{state=\"running\"}"), 0.0);
    assert_eq!(get(&before, "lasertag_clients{role=\"spectator\"}"), 0.0);

    // A real-time coordinated match with a spectator and a player, a manual one stepped.
    let live = s
        .create_match(
            json!({"map": "office", "opponent_control": "human", "planner": "coordinated",
                "spectator_delay_s": 0}),
        )
        .await;
    let manual = s
        .create_match(json!({"map": "office", "clock": "manual", "planner": "baseline"}))
        .await;
    s.step(&manual, 40).await;
    let (_, token) = s.join(&live, "alice").await;
    let mut player = s.ws(&live, Some(&token)).await.unwrap();
    let mut spectator = s.ws(&live, None).await.unwrap();
    for _ in 0..10 {
        spectator.next_of("snapshot").await;
        player.next_of("snapshot").await;
    }
    // Two refusals: a junk message and a bad match.
    spectator.send_text("junk".into()).await.unwrap();
    spectator.next_of("error").await;
    let r = s
        .post("/api/matches", &json!({"map": "office", "robots": 30}))
        .await;
    assert_eq!(r.status, 400);

    // Ten snapshots are not ten ticks: a frame is also published when a player connects, and
    // a tick's duration is recorded just after its frame goes out. The match keeps ticking,
    // so wait (a bounded while) for the tenth tick to be counted.
    let realtime = "{clock=\"realtime\",kind=\"coordinated\"}";
    let mut mid = scrape(&s).await.1;
    for _ in 0..100 {
        if get(&mid, &format!("lasertag_tick_seconds_count{realtime}")) >= 10.0 {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
        mid = scrape(&s).await.1;
    }
    assert_eq!(get(&mid, "lasertag_matches{state=\"running\"}"), 2.0);
    assert_eq!(get(&mid, "lasertag_clients{role=\"spectator\"}"), 1.0);
    assert_eq!(get(&mid, "lasertag_clients{role=\"player\"}"), 1.0);
    assert_eq!(
        get(&mid, "lasertag_refused_total{reason=\"message_invalid\"}"),
        1.0
    );
    let ticks = get(&mid, &format!("lasertag_tick_seconds_count{realtime}"));
    assert!(ticks >= 10.0, "{ticks} real-time ticks counted");
    assert_eq!(
        get(
            &mid,
            "lasertag_tick_seconds_count{clock=\"manual\",kind=\"baseline\"}"
        ),
        40.0
    );
    assert!(get(&mid, "lasertag_tracker_seconds_count{kind=\"baseline\"}") >= 40.0);
    assert!(get(&mid, "lasertag_planner_seconds_count{kind=\"coordinated\"}") >= 10.0);
    assert!(get(&mid, "lasertag_planner_seconds_sum{kind=\"coordinated\"}") > 0.0);
    let spectator_bytes = get(&mid, "lasertag_snapshot_bytes_total{role=\"spectator\"}");
    assert!(spectator_bytes > 10.0 * 1000.0, "{spectator_bytes} bytes");
    assert!(get(&mid, "lasertag_snapshot_bytes_total{role=\"player\"}") > 0.0);

    // Later: more ticks and bytes; clients leave, a match is deleted and the other finishes.
    for _ in 0..10 {
        spectator.next_of("snapshot").await;
    }
    drop(player);
    drop(spectator);
    assert_eq!(
        s.delete(&format!("/api/matches/{manual}")).await.status,
        204
    );
    let mut after = HashMap::new();
    for _ in 0..50 {
        tokio::time::sleep(Duration::from_millis(50)).await;
        after = scrape(&s).await.1;
        if get(&after, "lasertag_clients{role=\"spectator\"}") == 0.0
            && get(&after, "lasertag_clients{role=\"player\"}") == 0.0
        {
            break;
        }
    }
    assert_eq!(get(&after, "lasertag_clients{role=\"spectator\"}"), 0.0);
    assert_eq!(get(&after, "lasertag_clients{role=\"player\"}"), 0.0);
    assert_eq!(get(&after, "lasertag_matches{state=\"running\"}"), 1.0);
    assert_eq!(
        get(&after, "lasertag_matches_removed_total{reason=\"deleted\"}"),
        1.0
    );
    assert!(get(&after, &format!("lasertag_tick_seconds_count{realtime}")) > ticks);
    assert!(get(&after, "lasertag_snapshot_bytes_total{role=\"spectator\"}") > spectator_bytes);
    assert_eq!(
        get(&after, "lasertag_refused_total{reason=\"too_many_agents\"}"),
        0.0,
        "30 robots is out of the API's own range (400 before any limit)"
    );
}

#[tokio::test]
async fn a_config_with_limits_counts_each_refusal_by_reason() {
    let s = TestServer::start_with(lasertag::config::Config {
        max_agents_per_match: 3,
        max_matches: 1,
        ..test_config()
    })
    .await;
    let r = s
        .post(
            "/api/matches",
            &json!({"map": "office", "robots": 2, "opponents": 2}),
        )
        .await;
    assert_eq!(r.status, 400);
    s.create_match(json!({"map": "office", "clock": "manual"}))
        .await;
    let r = s
        .post("/api/matches", &json!({"map": "office", "clock": "manual"}))
        .await;
    assert_eq!(r.status, 503);
    let (_, m) = scrape(&s).await;
    assert_eq!(
        get(&m, "lasertag_refused_total{reason=\"too_many_agents\"}"),
        1.0
    );
    assert_eq!(
        get(&m, "lasertag_refused_total{reason=\"matches_full\"}"),
        1.0
    );
    assert_eq!(
        get(&m, "lasertag_refused_total{reason=\"rate_limited\"}"),
        0.0
    );
}
