//! `GET /api/rules` over real HTTP: the constants are the simulation's own, the bounds are the
//! ones the server enforces and the OpenAPI document states, and the opponents' motion is
//! what the WebSocket's `welcome` says.

mod common;

use common::{TestServer, assert_error, duel_map};
use lasertag_core::sim::{AGENT_RADIUS, Physics, TICK_HZ};
use serde_json::{Value, json};

#[tokio::test]
async fn the_rules_are_the_simulations_constants() {
    let server = TestServer::start().await;
    let r = server.get("/api/rules").await;
    assert_eq!(r.status, 200, "{}", r.body);
    let rules = r.body;
    let physics = Physics::default();
    assert_eq!(rules["tick_hz"], TICK_HZ);
    assert_eq!(rules["agent_radius"], AGENT_RADIUS as f64);
    assert_eq!(rules["laser"]["beams"], physics.laser_beams);
    assert_eq!(rules["laser"]["range"], physics.laser_range as f64);
    assert_eq!(rules["laser"]["fov_deg"], 180.0);
    assert_eq!(rules["tag"]["range"], physics.tag_range as f64);
    assert_eq!(rules["tag"]["cooldown_ticks"], physics.tag_cooldown_ticks);
    assert_eq!(rules["freeze_ticks"], physics.freeze_ticks);

    // A robot's scan has the laser's beams, none past its reach.
    let id = server
        .create_match(json!({"map": duel_map(), "clock": "manual", "planner": "api"}))
        .await;
    let obs = server
        .get(&format!("/api/matches/{id}/robots/r0/observation"))
        .await
        .body;
    let scan = obs["scan"].as_array().unwrap();
    assert_eq!(scan.len() as u64, rules["laser"]["beams"].as_u64().unwrap());
    let reach = rules["laser"]["range"].as_f64().unwrap();
    assert!(scan.iter().all(|v| v.as_f64().unwrap() <= reach + 1e-6));

    // The opponents move as the welcome's kinematics say.
    let mut ws = server.ws(&id, None).await.expect("a spectator connects");
    let welcome = ws.next_of("welcome").await;
    let k = &welcome["kinematics"];
    assert_eq!(k["speed"], rules["opponent"]["speed"], "{welcome}");
    assert_eq!(k["turn_rate"], rules["opponent"]["turn_rate"]);
    assert_eq!(k["radius"], rules["agent_radius"]);
    assert_eq!(welcome["tick_hz"], rules["tick_hz"]);
}

fn bound(rules: &Value, field: &str) -> (i64, i64) {
    let b = &rules["bounds"][field];
    (
        b["minimum"].as_f64().unwrap() as i64,
        b["maximum"].as_f64().unwrap() as i64,
    )
}

#[tokio::test]
async fn the_bounds_are_what_the_server_enforces_and_documents() {
    let server = TestServer::start().await;
    let rules = server.get("/api/rules").await.body;
    let doc = server.get("/api/openapi.json").await.body;

    // The document describes the answer.
    let answer = &doc["paths"]["/api/rules"]["get"]["responses"]["200"]["content"]["application/json"]
        ["schema"]["$ref"];
    assert_eq!(answer, "#/components/schemas/Rules", "{doc}");
    let schemas = &doc["components"]["schemas"];
    for field in ["robots", "opponents"] {
        let (lo, hi) = bound(&rules, field);
        let property = &schemas["CreateMatch"]["properties"][field];
        assert_eq!(property["minimum"].as_f64(), Some(lo as f64), "{property}");
        assert_eq!(property["maximum"].as_f64(), Some(hi as f64), "{property}");
        // The edge is taken, one past it is refused naming the field and the range.
        let at = json!({"map": "office", "clock": "manual", field: hi});
        assert_eq!(server.post("/api/matches", &at).await.status, 201);
        let past = json!({"map": duel_map(), field: hi + 1});
        assert_error(
            &server.post("/api/matches", &past).await,
            400,
            &format!("{field}: {} must be in {lo}..={hi}", hi + 1),
        );
    }
    let starts = &schemas["CreateMatch"]["properties"]["robot_starts"]["maxItems"];
    assert_eq!(starts.as_i64(), Some(bound(&rules, "robots").1));

    let (lo, hi) = bound(&rules, "ticks");
    for request in ["StepRequest", "ActRequest"] {
        let ticks = &schemas[request]["properties"]["ticks"];
        assert_eq!(ticks["minimum"].as_f64(), Some(lo as f64), "{ticks}");
        assert_eq!(ticks["maximum"].as_f64(), Some(hi as f64), "{ticks}");
    }
    let id = server
        .create_match(json!({"map": duel_map(), "clock": "manual"}))
        .await;
    assert_error(
        &server
            .post(
                &format!("/api/matches/{id}/step"),
                &json!({"ticks": hi + 1}),
            )
            .await,
        400,
        &format!("ticks: {} must be in {lo}..={hi}", hi + 1),
    );

    let limit = &rules["bounds"]["time_limit_s"];
    let property = &schemas["CreateMatch"]["properties"]["time_limit_s"];
    assert_eq!(
        property["exclusiveMinimum"].as_f64(),
        limit["minimum"].as_f64(),
        "{property}"
    );
    assert_eq!(limit["exclusive_minimum"], true);
    assert_eq!(property["maximum"].as_f64(), limit["maximum"].as_f64());
}
