//! Matches driven over real HTTP: tagging, the baseline team's hunt, determinism.

mod common;

use common::{TestServer, duel_map};
use serde_json::json;

#[tokio::test]
async fn a_robot_tags_an_api_opponent_steered_into_its_view() {
    let server = TestServer::start().await;
    let id = server
        .create_match(json!({"map": duel_map(), "clock": "manual", "robots": 1,
                             "opponent_control": "api", "planner": "baseline", "seed": 7}))
        .await;
    // The opponent starts behind the pillar's corner, out of the robot's way; bring it in front.
    let r = server
        .command(&id, "o0", json!({"waypoints": [[9.0, 6.8], [5.0, 4.0]]}))
        .await;
    assert_eq!(r.status, 204, "{}", r.body);
    let state = server.step(&id, 2_000).await;
    assert_eq!(state["status"], "finished", "{state}");
    assert_eq!(state["winner"], "robots");
    assert_eq!(state["opponents"][0]["tagged"], true);
    let events = server.events(&id).await;
    let tag = events
        .iter()
        .find(|e| e["kind"] == "tag")
        .expect("a tag event");
    assert_eq!(tag["by"], "r0");
    assert_eq!(tag["target"], "o0");
    let fin = events
        .iter()
        .find(|e| e["kind"] == "finished")
        .expect("a finished event");
    assert_eq!(fin["winner"], "robots");
    assert!(fin["seq"].as_u64() > tag["seq"].as_u64());
    // Events since a seq are only the later ones.
    let since = tag["seq"].as_u64().unwrap();
    let later = server
        .get(&format!("/api/matches/{id}/events?since={since}"))
        .await;
    assert!(
        later.body["events"]
            .as_array()
            .unwrap()
            .iter()
            .all(|e| e["seq"].as_u64().unwrap() > since)
    );
}

#[tokio::test]
async fn an_api_opponent_freezes_a_robot_it_faces() {
    let server = TestServer::start().await;
    let id = server
        .create_match(json!({"map": duel_map(), "clock": "manual", "robots": 1,
                             "opponent_control": "api", "planner": "idle",
                             "opponent_starts": [[4.0, 4.0]]}))
        .await;
    // o0 faces the arena's centre (to its right); walk it left of the robot and turn it round.
    server
        .command(&id, "o0", json!({"waypoints": [[3.0, 4.0], [2.99, 4.0]]}))
        .await;
    server.step(&id, 60).await;
    let r = server.command(&id, "o0", json!({"tag": true})).await;
    assert_eq!(r.status, 204);
    let state = server.step(&id, 1).await;
    assert_eq!(state["robots"][0]["frozen"], true, "{state}");
    // The scan of the tick it was hit was taken before the hit; from the next one it is blind.
    let state = server.step(&id, 1).await;
    assert_eq!(state["robots"][0]["scan"].as_array().unwrap().len(), 0);
    let events = server.events(&id).await;
    assert!(
        events
            .iter()
            .any(|e| e["kind"] == "robot_tagged" && e["target"] == "r0" && e["by"] == "o0")
    );
    let state = server.step(&id, 200).await;
    assert_eq!(state["robots"][0]["frozen"], false, "thawed after 10 s");
}

/// The acceptance figure of the arena issue: a baseline team finds and tags a wandering bot
/// on `office` in most of 20 seeded matches from random starts (the rate is printed for the note).
#[tokio::test]
async fn a_baseline_team_catches_a_wander_bot_on_office_in_most_matches() {
    let server = TestServer::start().await;
    let mut ids = Vec::new();
    for seed in 0..20 {
        ids.push(
            server
                .create_match(json!({"map": "office", "clock": "manual", "planner": "baseline",
                                     "opponent_bot": "wander", "placement": "random", "seed": seed}))
                .await,
        );
    }
    let mut caught = 0;
    let mut times = Vec::new();
    for id in &ids {
        let state = server.step(id, 6_000).await;
        if state["winner"] == "robots" {
            caught += 1;
            times.push(state["time_s"].as_f64().unwrap());
        }
    }
    times.sort_by(f64::total_cmp);
    println!("baseline vs wander on office: {caught}/20 caught; capture times {times:?}");
    assert!(caught >= 11, "only {caught}/20 caught");
}

#[tokio::test]
async fn the_same_seed_gives_the_same_match_tick_for_tick() {
    let server = TestServer::start().await;
    let body = json!({"map": "office", "clock": "manual", "planner": "baseline", "robots": 3,
                      "opponents": 3, "opponent_bot": "evade", "seed": 42});
    let a = server.create_match(body.clone()).await;
    let b = server.create_match(body).await;
    let c = server
        .create_match(
            json!({"map": "office", "clock": "manual", "planner": "baseline", "robots": 3,
                             "opponents": 3, "opponent_bot": "evade", "seed": 43}),
        )
        .await;
    let mut sa = server.step(&a, 1_000).await;
    let mut sb = server.step(&b, 1_000).await;
    let sc = server.step(&c, 1_000).await;
    for s in [&mut sa, &mut sb] {
        s.as_object_mut().unwrap().remove("id");
    }
    assert_eq!(sa, sb);
    assert_ne!(
        sa["robots"], sc["robots"],
        "a different seed plays differently"
    );
    assert_eq!(server.events(&a).await, server.events(&b).await);
}

#[tokio::test]
async fn coordination_weights_are_taken_and_echoed_with_defaults_filled_in() {
    let server = TestServer::start().await;
    let r = server
        .post(
            "/api/matches",
            &json!({"map": "office", "clock": "manual", "planner": "coordinated",
                    "coordination": {"travel_weight": 0.02, "round_ticks": 40}}),
        )
        .await;
    assert_eq!(r.status, 201, "{}", r.body);
    let c = &r.body["coordination"];
    assert_eq!(c["travel_weight"].as_f64().unwrap() as f32, 0.02);
    assert_eq!(c["round_ticks"], 40);
    assert_eq!(
        c["claim_keep"].as_f64().unwrap() as f32,
        0.2,
        "default filled in"
    );
    assert_eq!(r.body["planner_active"], "coordinated");
    assert_eq!(r.body["notes"], json!([]));
    assert_eq!(r.body["localisation"], true, "robots localise by default");
}

/// World-model confidence: every role in `belief` carries its confidence and what
/// it makes of it; a prior over the whole map is a guess.
#[tokio::test]
async fn belief_roles_carry_confidence_and_state() {
    let server = TestServer::start().await;
    let id = server
        .create_match(json!({"map": "office", "clock": "manual", "opponents": 2,
                             "robot_starts": [[2.0, 8.0, 3.0], [3.0, 8.0, 3.0]],
                             "opponent_starts": [[22.0, 1.5], [22.8, 15.2]]}))
        .await;
    server.step(&id, 1).await;
    let belief = server.get(&format!("/api/matches/{id}/belief")).await.body;
    let roles = belief["roles"].as_array().unwrap();
    assert!(!roles.is_empty());
    for r in roles {
        assert_eq!(r["state"], "invalid", "{}", r["id"]);
        assert_eq!(r["confidence"], 0.0);
    }
}

/// The role of `belief` that stands for an opponent seen where `at` is, if any: a valid
/// role whose weighted mean is within a metre of it.
fn role_near(belief: &serde_json::Value, at: [f64; 2]) -> bool {
    belief["roles"].as_array().unwrap().iter().any(|r| {
        let (ps, ws) = (
            r["particles"].as_array().unwrap(),
            r["weights"].as_array().unwrap(),
        );
        let (mut x, mut y) = (0.0, 0.0);
        for (p, w) in ps.iter().zip(ws) {
            let w = w.as_f64().unwrap();
            x += p[0].as_f64().unwrap() * w;
            y += p[1].as_f64().unwrap() * w;
        }
        r["state"] == "valid" && (x - at[0]).hypot(y - at[1]) < 1.0
    })
}

/// Team radio: `radio` is echoed with defaults filled in; with a latency, each
/// robot keeps its own belief, `belief?robot=r1` shows it, and r1 learns of an opponent only
/// r0 sees exactly `latency_ticks` later.
#[tokio::test]
async fn a_robot_learns_what_its_teammate_sees_over_the_radio_after_the_latency() {
    let server = TestServer::start().await;
    let r = server
        .post(
            "/api/matches",
            &json!({"map": "office", "clock": "manual", "planner": "idle",
                    "opponent_control": "api",
                    "robot_starts": [[2.0, 8.0, 0.0], [1.0, 4.5, 3.0]],
                    "opponent_starts": [[8.0, 8.0]],
                    "radio": {"latency_ticks": 5}}),
        )
        .await;
    assert_eq!(r.status, 201, "{}", r.body);
    assert_eq!(r.body["radio"], json!({"latency_ticks": 5, "loss": 0.0}));
    let id = r.body["id"].as_str().unwrap().to_string();
    let opponent = [8.0, 8.0];
    let belief = |robot: &'static str| {
        let (server, id) = (&server, id.clone());
        async move {
            let path = match robot {
                "" => format!("/api/matches/{id}/belief"),
                r => format!("/api/matches/{id}/belief?robot={r}"),
            };
            let reply = server.get(&path).await;
            assert_eq!(reply.status, 200, "{}", reply.body);
            reply.body
        }
    };
    // Robots sense (and broadcast) at tick 0, when the match is created.
    let r0 = belief("r0").await;
    assert_eq!(r0["robot"], "r0");
    assert!(
        role_near(&r0, opponent),
        "r0 sees the opponent: {}",
        r0["roles"]
    );
    // r1 faces a wall in another room: what r0 saw is still in flight for 5 ticks.
    for tick in 0..5 {
        assert!(
            !role_near(&belief("r1").await, opponent),
            "tick {tick}: too early"
        );
        server.step(&id, 1).await;
    }
    assert!(
        role_near(&belief("r1").await, opponent),
        "r1 heard of o0 at tick 5"
    );
    let merged = belief("").await;
    assert!(merged.get("robot").is_none(), "the team's merged view");
    let untagged: u64 = merged["roles"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["tagged"] == false)
        .map(|r| r["count"].as_u64().unwrap())
        .sum();
    assert_eq!(untagged, 1, "counts add up in the merged view");
    let unknown = server
        .get(&format!("/api/matches/{id}/belief?robot=r2"))
        .await;
    assert_eq!(unknown.status, 404, "{}", unknown.body);
    assert!(unknown.body["error"].as_str().unwrap().contains("r2"));
    let bad = server
        .get(&format!("/api/matches/{id}/belief?robot=o0"))
        .await;
    assert_eq!(bad.status, 404, "{}", bad.body);
    assert!(bad.body["error"].as_str().unwrap().contains("\"o0\""));
}

/// With the default (perfect) radio every robot's view is the team's one shared belief.
#[tokio::test]
async fn with_a_perfect_radio_each_robots_belief_is_the_teams() {
    let server = TestServer::start().await;
    let r = server
        .post(
            "/api/matches",
            &json!({"map": "office", "clock": "manual", "planner": "idle",
                    "robot_starts": [[2.0, 8.0, 0.0], [1.0, 4.5, 3.0]],
                    "opponent_starts": [[8.0, 8.0]]}),
        )
        .await;
    assert_eq!(r.body["radio"], json!({"latency_ticks": 0, "loss": 0.0}));
    let id = r.body["id"].as_str().unwrap();
    server.step(id, 3).await;
    let team = server.get(&format!("/api/matches/{id}/belief")).await.body;
    let r1 = server
        .get(&format!("/api/matches/{id}/belief?robot=r1"))
        .await
        .body;
    assert_eq!(team["roles"], r1["roles"]);
    assert!(role_near(&r1, [8.0, 8.0]), "r1 shares what r0 sees at once");
}

/// game-rules.md: odometry noise is "configurable". `odometry` is echoed with defaults filled
/// in and refused by name when out of range. Robots without a localiser dead-reckon: with
/// noiseless wheels they know their pose exactly, with noisy ones they drift and their
/// `spread` says by about how much.
#[tokio::test]
async fn odometry_noise_is_a_match_setting_and_dead_reckoning_knows_its_spread() {
    let server = TestServer::start().await;
    let r = server
        .post("/api/matches", &json!({"map": "office", "clock": "manual"}))
        .await;
    assert_eq!(
        r.body["odometry"],
        json!({"distance": 0.05, "heading_deg_per_m": 2.0, "turn": 0.02})
    );
    // Echoed as asked (not 30.000002 after a trip through radians).
    let r = server
        .post(
            "/api/matches",
            &json!({"map": "office", "clock": "manual", "localisation": false,
                    "odometry": {"heading_deg_per_m": 30}}),
        )
        .await;
    assert_eq!(r.body["odometry"]["heading_deg_per_m"], json!(30.0));
    // A weight that cannot act is accepted, and the summary says so.
    let notes = r.body["notes"].to_string();
    assert!(notes.contains("landmark_weight has no effect"), "{notes}");
    let r = server
        .post(
            "/api/matches",
            &json!({"map": "office", "odometry": {"heading_deg_per_m": 90}}),
        )
        .await;
    assert_eq!(r.status, 400, "{}", r.body);
    let error = r.body["error"].as_str().unwrap();
    assert!(
        error.starts_with("odometry.heading_deg_per_m: 90"),
        "{error}"
    );

    let run = |odometry: serde_json::Value| {
        let server = &server;
        async move {
            let r = server
                .post(
                    "/api/matches",
                    &json!({"map": "office", "clock": "manual", "planner": "baseline",
                            "localisation": false, "odometry": odometry, "seed": 3,
                            "opponent_bot": "idle", "opponent_starts": [[1.0, 1.0]],
                            "time_limit_s": 60}),
                )
                .await;
            assert_eq!(r.status, 201, "{}", r.body);
            assert_eq!(r.body["odometry"], odometry);
            let id = r.body["id"].as_str().unwrap().to_string();
            server.step(&id, 600).await
        }
    };
    let exact = run(json!({"distance": 0.0, "heading_deg_per_m": 0.0, "turn": 0.0})).await;
    let noisy = run(json!({"distance": 0.2, "heading_deg_per_m": 10.0, "turn": 0.1})).await;
    let error = |state: &serde_json::Value, i: usize| {
        let r = &state["robots"][i];
        let e = &r["estimate"];
        (
            (r["x"].as_f64().unwrap() - e["x"].as_f64().unwrap())
                .hypot(r["y"].as_f64().unwrap() - e["y"].as_f64().unwrap()),
            r["spread"].as_f64().unwrap(),
        )
    };
    for i in 0..2 {
        let (e, spread) = error(&exact, i);
        assert!(
            e < 1e-3 && spread == 0.0,
            "r{i}: off by {e} m, spread {spread}"
        );
    }
    let (e0, s0) = error(&noisy, 0);
    let (e1, s1) = error(&noisy, 1);
    assert!(
        s0 > 0.1 && s1 > 0.1,
        "spreads {s0}, {s1} after 30 s of noisy driving"
    );
    assert!(e0.max(e1) > 0.05, "noisy wheels drift: {e0}, {e1}");
    // The spread is a standard deviation, so an error of many spreads means it is wrong.
    assert!(e0 < 4.0 * s0 && e1 < 4.0 * s1, "{e0} vs {s0}, {e1} vs {s1}");
}

/// The uncertainty experiment's weak robot can be had over the API too: `localiser.beams`
/// (0 = landmarks and odometry alone) is echoed, checked by name, and such a match runs.
#[tokio::test]
async fn a_match_of_robots_that_localise_from_landmarks_alone() {
    let server = TestServer::start().await;
    let r = server
        .post("/api/matches", &json!({"map": "office", "clock": "manual"}))
        .await;
    assert_eq!(r.body["localiser"], json!({"beams": 30}));
    let r = server
        .post(
            "/api/matches",
            &json!({"map": "office", "localiser": {"beams": 200}}),
        )
        .await;
    assert_eq!(r.status, 400, "{}", r.body);
    assert_eq!(r.body["error"], "localiser.beams: 200 must be in 0..=181");
    let r = server
        .post(
            "/api/matches",
            &json!({"map": "office", "clock": "manual", "localiser": {"beams": 0},
                    "odometry": {"distance": 0.2, "heading_deg_per_m": 8.0, "turn": 0.08}}),
        )
        .await;
    assert_eq!(r.status, 201, "{}", r.body);
    assert_eq!(r.body["localiser"], json!({"beams": 0}));
    let id = r.body["id"].as_str().unwrap();
    let blind = server.step(id, 400).await;
    // The same match with the laser: the beams are what keeps the spread at centimetres.
    let r = server
        .post(
            "/api/matches",
            &json!({"map": "office", "clock": "manual",
                    "odometry": {"distance": 0.2, "heading_deg_per_m": 8.0, "turn": 0.08}}),
        )
        .await;
    let id = r.body["id"].as_str().unwrap();
    let sighted = server.step(id, 400).await;
    let spreads = |state: &serde_json::Value| -> Vec<f64> {
        state["robots"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["spread"].as_f64().unwrap())
            .collect()
    };
    let (blind, sighted) = (spreads(&blind), spreads(&sighted));
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    assert!(blind.iter().all(|s| s.is_finite() && *s > 0.0), "{blind:?}");
    assert!(
        mean(&blind) > 2.0 * mean(&sighted),
        "landmarks alone {blind:?}, with 30 beams {sighted:?}"
    );
}

/// A preset fills in the team, the planner and the clock (what the request gives wins), and
/// the presets are listed with their measured figures.
#[tokio::test]
async fn a_difficulty_preset_sets_the_team_unless_the_request_does() {
    let s = TestServer::start().await;
    let listed = s.get("/api/difficulties").await;
    assert_eq!(listed.status, 200, "{}", listed.body);
    let names: Vec<&str> = listed
        .body
        .as_array()
        .unwrap()
        .iter()
        .map(|d| d["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["recruit", "veteran", "elite", "learned"]);
    assert_eq!(listed.body[3]["policy"], "learned");
    assert_eq!(listed.body[0]["default"], true);
    assert!(
        listed.body[2]["measured"][1]["robots_win_rate"]
            .as_f64()
            .unwrap()
            > 0.9
    );

    let r = s
        .post(
            "/api/matches",
            &json!({"map": "office", "difficulty": "recruit", "clock": "manual"}),
        )
        .await;
    assert_eq!(r.status, 201, "{}", r.body);
    assert_eq!(r.body["difficulty"], "recruit");
    assert_eq!(r.body["robots"], 1);
    assert_eq!(r.body["planner"], "baseline");
    assert_eq!(r.body["time_limit_s"], 120.0);
    let r = s
        .post(
            "/api/matches",
            &json!({"map": "office", "difficulty": "elite", "robots": 3,
            "time_limit_s": 60, "clock": "manual"}),
        )
        .await;
    assert_eq!(r.status, 201, "{}", r.body);
    assert_eq!(
        (r.body["robots"].as_u64(), r.body["planner"].as_str()),
        (Some(3), Some("coordinated"))
    );
    assert_eq!(r.body["time_limit_s"], 60.0);
    let r = s
        .post(
            "/api/matches",
            &json!({"map": "office", "difficulty": "impossible"}),
        )
        .await;
    assert_eq!(r.status, 400, "{}", r.body);
    assert!(
        r.body["error"].as_str().unwrap().contains("difficulty"),
        "{}",
        r.body
    );
}
