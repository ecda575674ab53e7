//! The Agones lifecycle of the real binary (the `agones` feature, on by default) against a
//! stand-in for the SDK sidecar's HTTP gateway that records what it is told: Ready once
//! serving, Health again and again, the `matches` counter as matches come, Allocated when a
//! person joins, and Shutdown after SIGTERM, last. (Agones' own local SDK server is a Go
//! program; this machine builds no Go, so the stand-in answers as its REST gateway does.)

#![cfg(all(unix, feature = "agones"))]

mod common;
#[path = "common/process.rs"]
mod process;

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::{Path, State};
use axum::http::{Method, Uri};
use axum::routing::{patch, post};
use process::Server;
use serde_json::{Value, json};

/// Every call the sidecar received: method, path and body.
type Calls = Arc<Mutex<Vec<(Method, String, String)>>>;

async fn record(
    State(calls): State<Calls>,
    method: Method,
    uri: Uri,
    body: String,
) -> &'static str {
    calls
        .lock()
        .unwrap()
        .push((method, uri.path().to_owned(), body));
    "{}"
}

async fn counter(
    State(calls): State<Calls>,
    Path(name): Path<String>,
    method: Method,
    uri: Uri,
    body: String,
) -> String {
    calls
        .lock()
        .unwrap()
        .push((method, uri.path().to_owned(), body.clone()));
    let count: Value = serde_json::from_str(&body).unwrap_or(Value::Null);
    json!({"name": name, "count": count["count"], "capacity": "100"}).to_string()
}

/// The sidecar stand-in on an ephemeral port.
async fn sidecar() -> (u16, Calls) {
    let calls: Calls = Arc::default();
    let app = Router::new()
        .route("/ready", post(record))
        .route("/health", post(record))
        .route("/allocate", post(record))
        .route("/shutdown", post(record))
        .route("/v1beta1/counters/{name}", patch(counter))
        .with_state(calls.clone());
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let port = listener.local_addr().unwrap().port();
    tokio::spawn(async move { axum::serve(listener, app).await });
    (port, calls)
}

fn paths(calls: &Calls) -> Vec<String> {
    calls.lock().unwrap().iter().map(|c| c.1.clone()).collect()
}

async fn until(calls: &Calls, what: &str, seen: impl Fn(&[(Method, String, String)]) -> bool) {
    let deadline = Instant::now() + Duration::from_secs(30);
    while !seen(&calls.lock().unwrap()) {
        assert!(
            Instant::now() < deadline,
            "the sidecar never saw {what}: {:?}",
            paths(calls)
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::test]
async fn the_server_goes_ready_counts_matches_allocates_for_people_and_shuts_down_last() {
    let (port, calls) = sidecar().await;
    let data = common::temp_dir("agones");
    let mut server = Server::start_with_env(
        &["--no-showcase", "--data-dir", &data.display().to_string()],
        &[("AGONES_SDK_HTTP_PORT", &port.to_string())],
    );
    until(&calls, "Ready", |c| c.iter().any(|c| c.1 == "/ready")).await;
    until(&calls, "Health twice", |c| {
        c.iter().filter(|c| c.1 == "/health").count() >= 2
    })
    .await;
    let counted = |n: &str| {
        let n = n.to_owned();
        move |c: &[(Method, String, String)]| {
            c.iter().any(|c| {
                c.0 == Method::PATCH
                    && c.1 == "/v1beta1/counters/matches"
                    && serde_json::from_str::<Value>(&c.2).is_ok_and(|v| v["count"] == n)
            })
        }
    };
    until(&calls, "matches = 0", counted("0")).await;
    assert!(
        !paths(&calls).contains(&"/allocate".to_owned()),
        "allocated before anyone played"
    );

    // A match a person plays: counted, and the server is allocated.
    let http = reqwest::Client::new();
    let created: Value = http
        .post(server.url("/api/matches"))
        .json(&json!({"map": "office", "opponent_control": "human", "planner": "idle"}))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let id = created["id"].as_str().expect("a match id");
    until(&calls, "matches = 1", counted("1")).await;
    let joined = http
        .post(server.url(&format!("/api/matches/{id}/players")))
        .json(&json!({"name": "alice"}))
        .send()
        .await
        .unwrap();
    assert!(joined.status().is_success(), "{:?}", joined.text().await);
    until(&calls, "Allocate", |c| c.iter().any(|c| c.1 == "/allocate")).await;

    // SIGTERM: the matches end, then the server hands itself back with Shutdown and exits.
    let status = std::process::Command::new("kill")
        .args(["-TERM", &server.child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
    let deadline = Instant::now() + Duration::from_secs(10);
    let exit = loop {
        if let Some(exit) = server.child.try_wait().unwrap() {
            break exit;
        }
        assert!(
            Instant::now() < deadline,
            "still running 10 s after SIGTERM"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    assert!(exit.success(), "exited with {exit}");
    let seen = paths(&calls);
    assert_eq!(
        seen.iter().filter(|p| *p == "/shutdown").count(),
        1,
        "{seen:?}"
    );
    assert_eq!(
        seen.last().map(String::as_str),
        Some("/shutdown"),
        "{seen:?}"
    );
    assert_eq!(
        seen.iter().filter(|p| *p == "/ready").count(),
        1,
        "Ready once: {seen:?}"
    );
}
