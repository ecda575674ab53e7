//! Every error class of the spec, over real HTTP: each gets the right status and a JSON body
//! naming what is wrong, and none of them disturbs the server or a running match.

mod common;

use common::{TestServer, assert_error, duel_map};
use serde_json::{Value, json};

fn with(mut map: Value, f: impl FnOnce(&mut Value)) -> Value {
    f(&mut map);
    map
}

#[tokio::test]
async fn every_error_class_is_answered_and_nothing_running_is_disturbed() {
    let server = TestServer::start().await;
    // A real-time match that must keep running through all of this.
    let live = server
        .create_match(json!({"map": "office", "planner": "baseline"}))
        .await;
    let manual = server
        .create_match(json!({"map": duel_map(), "clock": "manual", "opponent_control": "api"}))
        .await;
    let bots = server
        .create_match(json!({"map": "office", "clock": "manual"}))
        .await;
    let before = server.get(&format!("/api/matches/{live}")).await.body["tick"]
        .as_u64()
        .unwrap();

    // Malformed JSON.
    assert_error(
        &server.post_raw("/api/matches", "{\"map\": ").await,
        400,
        "EOF",
    );
    assert_error(
        &server.post_raw("/api/matches", "not json").await,
        400,
        "body",
    );
    assert_error(&server.post_raw("/api/matches", "").await, 400, "body");
    // Wrong types.
    assert_error(
        &server
            .post("/api/matches", &json!({"map": "office", "robots": "two"}))
            .await,
        400,
        "robots",
    );
    assert_error(
        &server.post("/api/matches", &json!({"map": 7})).await,
        400,
        "map",
    );
    assert_error(
        &server
            .post("/api/matches", &json!({"map": "office", "clock": "fast"}))
            .await,
        400,
        "clock",
    );
    assert_error(
        &server
            .post(
                "/api/matches",
                &json!({"map": "office", "tracker": {"merge": "yes"}}),
            )
            .await,
        400,
        "tracker.merge",
    );
    assert_error(
        &server.post("/api/matches", &json!([1, 2])).await,
        400,
        "body",
    );
    // Unknown fields, at the top and nested.
    assert_error(
        &server
            .post("/api/matches", &json!({"map": "office", "robot": 2}))
            .await,
        400,
        "robot",
    );
    assert_error(
        &server
            .post(
                "/api/matches",
                &json!({"map": "office", "tracker": {"particles": 5}}),
            )
            .await,
        400,
        "tracker",
    );
    // Out of range, NaN and huge numbers.
    assert_error(
        &server
            .post("/api/matches", &json!({"map": "office", "robots": 0}))
            .await,
        400,
        "robots",
    );
    assert_error(
        &server
            .post("/api/matches", &json!({"map": "office", "opponents": 33}))
            .await,
        400,
        "opponents",
    );
    assert_error(
        &server
            .post("/api/matches", &json!({"map": "office", "robots": 1e300}))
            .await,
        400,
        "robots",
    );
    assert_error(
        &server
            .post_raw("/api/matches", r#"{"map": "office", "time_limit_s": NaN}"#)
            .await,
        400,
        "time_limit_s",
    );
    assert_error(
        &server
            .post_raw(
                "/api/matches",
                r#"{"map": "office", "time_limit_s": 1e999}"#,
            )
            .await,
        400,
        "time_limit_s",
    );
    assert_error(
        &server
            .post(
                "/api/matches",
                &json!({"map": "office", "time_limit_s": -1.0}),
            )
            .await,
        400,
        "time_limit_s",
    );
    assert_error(
        &server
            .post("/api/matches", &json!({"map": "office", "seed": -1}))
            .await,
        400,
        "seed",
    );
    assert_error(
        &server
            .post(
                "/api/matches",
                &json!({"map": "office", "tracker": {"kl_cutoff": 0.0}}),
            )
            .await,
        400,
        "tracker.kl_cutoff",
    );
    for (bad, field) in [
        (json!({"claim_keep": 1.5}), "coordination.claim_keep"),
        (json!({"round_ticks": 0}), "coordination.round_ticks"),
        (
            json!({"crowding_radius": 0.0}),
            "coordination.crowding_radius",
        ),
        (json!({"travel_weight": -1.0}), "coordination.travel_weight"),
        (
            json!({"uncertainty_spread": 0.0}),
            "coordination.uncertainty_spread",
        ),
        (
            json!({"landmark_weight": 2.0}),
            "coordination.landmark_weight",
        ),
        (json!({"narrow_weight": -0.1}), "coordination.narrow_weight"),
        (json!({"lookahead": 3.0}), "coordination.lookahead"),
        (json!({"claim": 0.5}), "coordination"),
    ] {
        assert_error(
            &server
                .post(
                    "/api/matches",
                    &json!({"map": "office", "coordination": bad}),
                )
                .await,
            400,
            field,
        );
    }
    for (bad, field) in [
        (json!({"latency_ticks": 101}), "radio.latency_ticks"),
        (json!({"latency_ticks": -1}), "radio.latency_ticks"),
        (json!({"loss": 1.5}), "radio.loss"),
        (json!({"loss": -0.1}), "radio.loss"),
        (json!({"loss": "some"}), "radio.loss"),
        (json!({"delay": 3}), "radio"),
    ] {
        assert_error(
            &server
                .post("/api/matches", &json!({"map": "office", "radio": bad}))
                .await,
            400,
            field,
        );
    }
    assert_error(
        &server
            .post(
                "/api/matches",
                &json!({"map": duel_map(), "robot_starts": [[1e30, 1.0, 0.0]]}),
            )
            .await,
        400,
        "robot_starts[0]",
    );
    assert_error(
        &server
            .post(
                "/api/matches",
                &json!({"map": duel_map(), "opponent_starts": [[7.0, 6.0]]}),
            )
            .await,
        400,
        "opponent_starts[0]",
    );
    // More starts than agents would be left over: refused, naming the field.
    assert_error(
        &server
            .post(
                "/api/matches",
                &json!({"map": "office", "robots": 1,
                    "robot_starts": [[2.0, 8.0, 0.0], [3.0, 8.0, 0.0]]}),
            )
            .await,
        400,
        "robot_starts: 2 starts for 1 robots",
    );
    assert_error(
        &server
            .post(
                "/api/matches",
                &json!({"map": "office", "opponents": 1,
                    "opponent_starts": [[2.0, 8.0], [3.0, 8.0]]}),
            )
            .await,
        400,
        "opponent_starts: 2 starts for 1 opponents",
    );

    // A bad map, each rule, inline and through POST /api/maps.
    let bad_maps: Vec<(Value, &str)> = vec![
        (with(duel_map(), |m| m["name"] = json!("Duel!")), "name"),
        (with(duel_map(), |m| m["width"] = json!(0)), "width"),
        (with(duel_map(), |m| m["height"] = json!(1000)), "height"),
        (
            with(duel_map(), |m| m["obstacles"][0] = json!([[1, 1], [2, 2]])),
            "obstacles[0]: polygon has 2 vertices, needs at least 3",
        ),
        (
            with(duel_map(), |m| m["obstacles"][0][1] = json!([99, 5.5])),
            "obstacles[0][1]",
        ),
        (
            with(duel_map(), |m| {
                m["obstacles"][0] = json!([[6.5, 5.5], [7.5, 6.5], [7.5, 5.5], [6.5, 6.5]])
            }),
            "obstacles[0]: polygon intersects itself",
        ),
        (
            with(duel_map(), |m| m["robot_spawns"] = json!([])),
            "robot_spawns",
        ),
        (
            with(duel_map(), |m| m["opponent_spawns"] = json!([])),
            "opponent_spawns",
        ),
        (
            with(duel_map(), |m| {
                m["robot_spawns"][1] = json!([7.0, 6.0, 0.0])
            }),
            "robot_spawns[1]: lies inside obstacles[0]",
        ),
        (
            with(duel_map(), |m| m["opponent_spawns"][1] = json!([6.4, 6.0])),
            "opponent_spawns[1]: is closer than 0.25 m to obstacles[0]",
        ),
        (
            with(duel_map(), |m| m["opponent_spawns"][0] = json!([13.9, 7.0])),
            "opponent_spawns[0]",
        ),
        (
            with(duel_map(), |m| m["landmarks"][0] = json!([20, 1])),
            "landmarks[0]",
        ),
        (with(duel_map(), |m| m["doors"] = json!([])), "doors"),
        (
            with(duel_map(), |m| {
                m.as_object_mut().unwrap().remove("width");
            }),
            "width",
        ),
        (
            with(duel_map(), |m| {
                m["obstacles"] = json!([(0..10_001)
                    .map(|k| {
                        let a = k as f64 / 10_001.0 * std::f64::consts::TAU;
                        [7.0 + 0.3 * a.cos(), 2.0 + 0.3 * a.sin()]
                    })
                    .collect::<Vec<_>>()])
            }),
            "obstacles: 10001 vertices",
        ),
    ];
    for (map, mention) in &bad_maps {
        assert_error(
            &server.post("/api/matches", &json!({"map": map})).await,
            400,
            mention,
        );
        assert_error(&server.post("/api/maps", map).await, 400, mention);
    }
    assert_error(
        &server
            .post(
                "/api/maps",
                &with(duel_map(), |m| m["name"] = json!("office")),
            )
            .await,
        409,
        "office",
    );

    // Unknown ids and routes.
    assert_error(&server.get("/api/matches/nope").await, 404, "nope");
    // That a match exists is public: an unknown one is a 404 before any token is asked for.
    assert_error(&server.delete("/api/matches/nope").await, 404, "nope");
    assert_error(&server.get("/api/matches/nope/belief").await, 404, "nope");
    assert_error(&server.get("/api/matches/nope/events").await, 404, "nope");
    assert_error(
        &server
            .post("/api/matches/nope/step", &json!({"ticks": 1}))
            .await,
        404,
        "nope",
    );
    assert_error(&server.get("/api/maps/nope").await, 404, "nope");
    assert_error(
        &server.post("/api/matches", &json!({"map": "nope"})).await,
        404,
        "nope",
    );
    assert_error(
        &server.command(&manual, "o9", json!({"stop": true})).await,
        404,
        "o9",
    );
    assert_error(
        &server.command(&manual, "r0", json!({"stop": true})).await,
        404,
        "r0",
    );
    assert_error(
        &server.get("/api/nothing/here").await,
        404,
        "/api/nothing/here",
    );
    assert_error(&server.delete("/api/health").await, 405, "DELETE");

    // Bad values on existing matches.
    assert_error(
        &server
            .post(&format!("/api/matches/{manual}/step"), &json!({"ticks": 0}))
            .await,
        400,
        "ticks",
    );
    assert_error(
        &server
            .post(
                &format!("/api/matches/{manual}/step"),
                &json!({"ticks": 100_001}),
            )
            .await,
        400,
        "ticks",
    );
    assert_error(
        &server
            .post(
                &format!("/api/matches/{manual}/step"),
                &json!({"ticks": "many"}),
            )
            .await,
        400,
        "ticks",
    );
    assert_error(
        &server
            .get(&format!("/api/matches/{manual}/events?since=-3"))
            .await,
        400,
        "since",
    );
    assert_error(
        &server
            .command(&manual, "o0", json!({"waypoints": [[99.0, 1.0]]}))
            .await,
        400,
        "waypoints[0]",
    );
    assert_error(
        &server
            .command(&manual, "o0", json!({"stop": true, "tag": true}))
            .await,
        400,
        "exactly one",
    );
    assert_error(
        &server.command(&manual, "o0", json!({"jump": true})).await,
        400,
        "jump",
    );

    // Requests that do not fit the match's state.
    assert_error(
        &server
            .post(&format!("/api/matches/{live}/step"), &json!({"ticks": 5}))
            .await,
        409,
        "real time",
    );
    assert_error(
        &server.command(&bots, "o0", json!({"stop": true})).await,
        409,
        "not API-controlled",
    );
    assert_error(
        &server
            .post(
                &format!("/api/matches/{bots}/players"),
                &json!({"name": "alice"}),
            )
            .await,
        409,
        "no free",
    );
    // A player's name is checked as sent: a control character at either end is refused,
    // not trimmed away (tests/names.rs has the rest of the rules).
    let seats = server
        .create_match(json!({"map": "office", "clock": "manual", "opponent_control": "human"}))
        .await;
    for name in ["alice\t", "\u{7f}bob", "\n", ""] {
        assert_error(
            &server
                .post(
                    &format!("/api/matches/{seats}/players"),
                    &json!({ "name": name }),
                )
                .await,
            400,
            "name",
        );
    }

    // A 2 MiB body.
    let huge = format!(
        "{{\"map\": \"office\", \"pad\": \"{}\"}}",
        "x".repeat(2 << 20)
    );
    assert_error(
        &server.post_raw("/api/matches", huge.clone()).await,
        413,
        "limit",
    );
    assert_error(&server.post_raw("/api/maps", huge).await, 413, "limit");

    // Nothing was disturbed: health answers, the real-time match still runs, the manual ones
    // did not move, and no stray match was created.
    let health = server.get("/api/health").await;
    assert_eq!(health.status, 200);
    assert_eq!(health.body["status"], "ok");
    tokio::time::sleep(std::time::Duration::from_millis(300)).await;
    let after = server.get(&format!("/api/matches/{live}")).await.body;
    assert_eq!(after["status"], "running");
    assert!(
        after["tick"].as_u64().unwrap() > before,
        "the real-time match kept ticking"
    );
    assert_eq!(
        server.get(&format!("/api/matches/{manual}")).await.body["tick"],
        0
    );
    assert_eq!(
        server
            .get("/api/matches")
            .await
            .body
            .as_array()
            .unwrap()
            .len(),
        4
    );
    assert_eq!(
        server.get("/api/maps").await.body.as_array().unwrap().len(),
        4
    );
}

#[tokio::test]
async fn maps_can_be_added_listed_and_read_back() {
    let server = TestServer::start().await;
    let r = server.post("/api/maps", &duel_map()).await;
    assert_eq!(r.status, 201, "{}", r.body);
    let names: Vec<String> = server
        .get("/api/maps")
        .await
        .body
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["name"].as_str().unwrap().to_string())
        .collect();
    assert!(names.contains(&"duel".to_string()), "{names:?}");
    let back = server.get("/api/maps/duel").await;
    assert_eq!(back.body, duel_map());
    assert_error(&server.post("/api/maps", &duel_map()).await, 409, "duel");
    let id = server
        .create_match(json!({"map": "duel", "clock": "manual"}))
        .await;
    assert_eq!(
        server.get(&format!("/api/matches/{id}")).await.body["map"],
        "duel"
    );
}

#[tokio::test]
async fn deleting_a_match_removes_it() {
    let server = TestServer::start().await;
    let id = server.create_match(json!({"map": "office"})).await;
    assert_eq!(
        server.delete(&format!("/api/matches/{id}")).await.status,
        204
    );
    assert_eq!(server.get(&format!("/api/matches/{id}")).await.status, 404);
    assert_eq!(server.get("/api/matches").await.body, json!([]));
}

#[tokio::test]
async fn the_openapi_document_lists_every_operation() {
    let server = TestServer::start().await;
    let doc = server.get("/api/openapi.json").await.body;
    let paths = doc["paths"].as_object().unwrap();
    for p in [
        "/api/health",
        "/api/maps",
        "/api/maps/{name}",
        "/api/matches",
        "/api/matches/{id}",
        "/api/matches/{id}/step",
        "/api/matches/{id}/belief",
        "/api/matches/{id}/events",
        "/api/matches/{id}/opponents/{oid}/command",
        "/api/matches/{id}/players",
        "/metrics",
    ] {
        assert!(paths.contains_key(p), "{p} is documented");
    }
}
