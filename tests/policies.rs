//! Trained robot teams over HTTP (docs/api.md, "Trained robot teams"): the shipped policy is
//! listed from the start and drives a match by `"planner": "policy:<name>"`; an uploaded one
//! drives a match too; bad uploads are refused naming the problem and change nothing; a
//! policy in use cannot be deleted; a replay plays back without the model.

mod common;

use common::{
    POLICY_OBSERVATION as OBSERVATION, TestServer, policy_layer as layer, small_policy, test_config,
};
use lasertag::config::Config;
use lasertag_policy::testing::model;
use serde_json::{Value, json};

async fn upload(s: &TestServer, name: &str, bytes: Vec<u8>) -> common::Reply {
    s.post_raw(&format!("/api/policies?name={name}"), bytes)
        .await
}

async fn names(s: &TestServer) -> Vec<String> {
    let r = s.get("/api/policies").await;
    assert_eq!(r.status, 200);
    r.body
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap().to_string())
        .collect()
}

fn positions(state: &Value) -> Vec<(f64, f64)> {
    state["robots"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| (r["x"].as_f64().unwrap(), r["y"].as_f64().unwrap()))
        .collect()
}

#[tokio::test]
async fn the_shipped_policy_is_listed_and_drives_a_match() {
    let s = TestServer::start().await;
    let r = s.get("/api/policies").await;
    let learned = r.body.as_array().unwrap()[0].clone();
    assert_eq!(learned["name"], "learned");
    assert_eq!(learned["shipped"], true);
    assert_eq!(learned["observation_size"], OBSERVATION);
    assert_eq!(learned["action_size"], 3);
    assert!(learned["inference_us"].as_f64().unwrap() > 0.0);
    let run = |seed: u64| {
        let s = &s;
        async move {
            let id = s
                .create_match(json!({"map": "office", "planner": "policy:learned",
                    "clock": "manual", "seed": seed}))
                .await;
            let start = positions(&s.get(&format!("/api/matches/{id}")).await.body);
            let after = s.step(&id, 100).await;
            assert_eq!(after["policy"], "learned");
            assert_eq!(after["robot_planners"], json!(["policy", "policy"]));
            (start, positions(&after))
        }
    };
    let (start, after) = run(3).await;
    assert_ne!(start, after, "the policy's robots moved");
    // The match stays a function of its settings and seed.
    assert_eq!(run(3).await.1, after);
    // The lobby's preset plays the same team.
    let r = s
        .post(
            "/api/matches",
            &json!({"map": "office", "difficulty": "learned"}),
        )
        .await;
    assert_eq!(r.status, 201, "{}", r.body);
    assert_eq!(r.body["policy"], "learned");
    assert_eq!(r.body["robots"], 2);
}

#[tokio::test]
async fn an_uploaded_policy_drives_a_match_and_is_removed_only_when_unused() {
    let s = TestServer::start().await;
    let r = upload(&s, "mine", small_policy()).await;
    assert_eq!(r.status, 201, "{}", r.body);
    assert_eq!(r.body["name"], "mine");
    assert_eq!(r.body["observation_size"], OBSERVATION);
    assert_eq!(r.body["action_size"], 3);
    assert_eq!(r.body["decide_every"], 2, "the default");
    let token = r.body["owner_token"].as_str().unwrap().to_string();
    assert_eq!(names(&s).await, ["learned", "mine"]);
    // A policy trained at another step decides at it.
    let r = upload(&s, "at-four&decide_every=4", small_policy()).await;
    assert_eq!(r.status, 201, "{}", r.body);
    assert_eq!(r.body["decide_every"], 4);
    let listed = s.get("/api/policies").await.body;
    let every: Vec<_> = listed
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            (
                p["name"].as_str().unwrap(),
                p["decide_every"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(every, [("at-four", 4), ("learned", 2), ("mine", 2)]);
    // The same model deciding half as often drives the same match elsewhere.
    let mut after = Vec::new();
    for name in ["mine", "at-four"] {
        let id = s
            .create_match(json!({"map": "office", "planner": format!("policy:{name}"),
                "clock": "manual", "seed": 5}))
            .await;
        after.push(positions(&s.step(&id, 41).await));
        assert_eq!(s.delete(&format!("/api/matches/{id}")).await.status, 204);
    }
    assert_ne!(after[0], after[1]);
    let r = s
        .delete_as(
            "/api/policies/at-four",
            Some(r.body["owner_token"].as_str().unwrap()),
        )
        .await;
    assert_eq!(r.status, 204, "{}", r.body);
    // Taken names are refused.
    assert_eq!(upload(&s, "mine", small_policy()).await.status, 409);
    let id = s
        .create_match(
            json!({"map": "office", "planner": "policy:mine", "clock": "manual",
            "time_limit_s": 5}),
        )
        .await;
    let start = positions(&s.get(&format!("/api/matches/{id}")).await.body);
    let mid = s.step(&id, 40).await;
    assert_ne!(positions(&mid), start);
    // In use: neither the owner nor anyone else removes it; a stranger is refused first.
    assert_eq!(
        s.delete_as("/api/policies/mine", Some("wrong"))
            .await
            .status,
        403
    );
    let r = s.delete_as("/api/policies/mine", Some(&token)).await;
    assert_eq!(r.status, 409, "{}", r.body);
    // Played to its end, the match no longer holds it, and its replay needs no model.
    let end = s.step(&id, 200).await;
    assert_eq!(end["status"], "finished");
    let r = s.delete_as("/api/policies/mine", Some(&token)).await;
    assert_eq!(r.status, 204, "{}", r.body);
    assert_eq!(names(&s).await, ["learned"]);
    let replayed = s.get(&format!("/api/replays/{id}/state?tick=40")).await;
    assert_eq!(replayed.status, 200, "{}", replayed.body);
    assert_eq!(positions(&replayed.body), positions(&mid));
    // The shipped one stays.
    assert_eq!(
        s.delete_as("/api/policies/learned", Some(&token))
            .await
            .status,
        403
    );
}

#[tokio::test]
async fn bad_uploads_are_refused_naming_the_problem_and_change_nothing() {
    let s = TestServer::start_with(Config {
        max_policy_bytes: 1 << 20,
        ..test_config()
    })
    .await;
    let before = names(&s).await;
    let refused = |status: u16, needle: &'static str| {
        move |r: common::Reply| {
            assert_eq!(r.status, status, "{}", r.body);
            let message = r.body["error"].as_str().unwrap().to_string();
            assert!(message.contains(needle), "{message:?} names {needle:?}");
        }
    };
    let random: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    refused(400, "not a readable ONNX model")(upload(&s, "random", random).await);
    refused(400, "no robot observation")(
        upload(&s, "narrow", model(10, &[layer(3, 10, 0.1, "")])).await,
    );
    refused(400, "operator Softmax is not supported")(
        upload(
            &s,
            "softmax",
            model(OBSERVATION, &[layer(3, OBSERVATION, 0.1, "Softmax")]),
        )
        .await,
    );
    refused(400, "a robot's action is 3")(
        upload(
            &s,
            "wide",
            model(OBSERVATION, &[layer(5, OBSERVATION, 0.1, "")]),
        )
        .await,
    );
    refused(400, "name")(upload(&s, "no%20spaces", small_policy()).await);
    for every in ["0", "21", "x", "-1"] {
        refused(400, "decide_every")(
            upload(
                &s,
                &format!("every{every}&decide_every={every}"),
                small_policy(),
            )
            .await,
        );
    }
    refused(413, "limit")(upload(&s, "huge", vec![0u8; 64 << 20]).await);
    assert_eq!(names(&s).await, before);
    // A match naming a policy the server does not hold, or one for another team size.
    let r = s
        .post(
            "/api/matches",
            &json!({"map": "office", "planner": "policy:nope"}),
        )
        .await;
    refused(400, "no policy \"nope\"")(r);
    let r = s
        .post(
            "/api/matches",
            &json!({"map": "office", "planner": "policy:learned", "robots": 3}),
        )
        .await;
    refused(400, "another team size")(r);
}

#[tokio::test]
async fn an_inference_over_the_servers_limit_is_refused() {
    let s = TestServer::start_with(Config {
        max_policy_inference_us: 1,
        ..test_config()
    })
    .await;
    let big = model(
        OBSERVATION,
        &[
            layer(256, OBSERVATION, 0.01, "Relu"),
            layer(256, 256, 0.01, "Relu"),
            layer(3, 256, 0.01, ""),
        ],
    );
    let r = upload(&s, "slow", big).await;
    assert_eq!(r.status, 400, "{}", r.body);
    assert!(
        r.body["error"]
            .as_str()
            .unwrap()
            .contains("over its limit of 1 µs"),
        "{}",
        r.body
    );
    assert_eq!(names(&s).await, ["learned"]);
}

/// A model of about `kb` kilobytes (a hidden layer of floats sized to it).
fn model_of_kb(kb: usize) -> Vec<u8> {
    let hidden = kb * 1000 / (4 * OBSERVATION);
    model(
        OBSERVATION,
        &[
            layer(hidden, OBSERVATION, 0.01, "Tanh"),
            layer(3, hidden, 0.01, ""),
        ],
    )
}

#[tokio::test]
async fn kept_policies_load_within_max_policies_and_their_bytes_take_the_disk_budget() {
    let dir = common::temp_dir("policies-kept");
    let stored = |config: Config| {
        let retention = lasertag::store::Retention {
            max_matches: 10_000,
            max_bytes: 1 << 30,
        };
        let store = lasertag::store::Store::open(&dir, retention).expect("the store opens");
        TestServer::start_with_history(config, lasertag::game::replay::History::with_store(store))
    };
    // A server whose disk budget (2 MB) holds one model of 1.2 MB and not two: the store
    // keeps each model as uploaded.
    let config = Config {
        disk_budget_mb: 2,
        max_policy_inference_us: 10_000_000,
        ..test_config()
    };
    let s = stored(config.clone()).await;
    let r = upload(&s, "first", model_of_kb(1200)).await;
    assert_eq!(r.status, 201, "{}", r.body);
    let r = upload(&s, "second", model_of_kb(1200)).await;
    assert_eq!(r.status, 503, "{}", r.body);
    let said = r.body["error"].as_str().unwrap_or_default();
    assert!(said.contains("disk budget"), "{said}");
    assert!(upload(&s, "small", small_policy()).await.status == 201);
    s.flush_history();
    drop(s);

    // Another server on the store, holding one policy besides the shipped one: it loads the
    // oldest kept one and leaves the other in the store.
    let s = stored(Config {
        max_policies: 2,
        ..config
    })
    .await;
    let loaded = lasertag::game::resume::restore_policies(&s.registry);
    assert_eq!(loaded, 1);
    assert_eq!(names(&s).await, ["first", "learned"]);
    // As an upload would find it: full.
    let r = upload(&s, "third", small_policy()).await;
    assert_eq!(r.status, 503, "{}", r.body);
}
