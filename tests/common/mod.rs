//! A real server on an ephemeral port, and helpers to drive it over HTTP.
#![allow(dead_code)]

use std::net::SocketAddr;
use std::path::Path;

use lasertag::game::Registry;
use lasertag::maps::MapStore;
use serde_json::{Value, json};

pub struct TestServer {
    pub addr: SocketAddr,
    pub client: reqwest::Client,
}

pub struct Reply {
    pub status: u16,
    pub body: Value,
}

impl TestServer {
    /// The app of `lasertag::http::app` with the shipped maps, on 127.0.0.1:0, without a showcase.
    pub async fn start() -> TestServer {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let maps = MapStore::load_dir(&root.join("maps")).expect("shipped maps load");
        let registry = Registry::new(maps);
        let app = lasertag::http::app(registry, root.join("web"));
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        tokio::spawn(async move { axum::serve(listener, app).await });
        TestServer {
            addr,
            client: reqwest::Client::new(),
        }
    }

    pub fn url(&self, path: &str) -> String {
        format!("http://{}{}", self.addr, path)
    }

    async fn reply(r: reqwest::Response) -> Reply {
        let status = r.status().as_u16();
        let text = r.text().await.unwrap();
        let body = if text.is_empty() {
            Value::Null
        } else {
            serde_json::from_str(&text).unwrap_or_else(|_| panic!("not JSON ({status}): {text}"))
        };
        Reply { status, body }
    }

    pub async fn get(&self, path: &str) -> Reply {
        Self::reply(self.client.get(self.url(path)).send().await.unwrap()).await
    }

    pub async fn delete(&self, path: &str) -> Reply {
        Self::reply(self.client.delete(self.url(path)).send().await.unwrap()).await
    }

    pub async fn post(&self, path: &str, body: &Value) -> Reply {
        self.post_raw(path, serde_json::to_vec(body).unwrap()).await
    }

    pub async fn post_raw(&self, path: &str, body: impl Into<reqwest::Body>) -> Reply {
        let r = self
            .client
            .post(self.url(path))
            .header("content-type", "application/json")
            .body(body)
            .send()
            .await
            .unwrap();
        Self::reply(r).await
    }

    /// Creates a match and returns its id (panics unless 201).
    pub async fn create_match(&self, body: Value) -> String {
        let r = self.post("/api/matches", &body).await;
        assert_eq!(r.status, 201, "{}", r.body);
        r.body["id"].as_str().unwrap().to_string()
    }

    pub async fn step(&self, id: &str, ticks: u64) -> Value {
        let r = self
            .post(&format!("/api/matches/{id}/step"), &json!({"ticks": ticks}))
            .await;
        assert_eq!(r.status, 200, "{}", r.body);
        r.body
    }

    pub async fn command(&self, id: &str, oid: &str, body: Value) -> Reply {
        self.post(&format!("/api/matches/{id}/opponents/{oid}/command"), &body)
            .await
    }

    pub async fn events(&self, id: &str) -> Vec<Value> {
        let r = self.get(&format!("/api/matches/{id}/events")).await;
        assert_eq!(r.status, 200);
        r.body["events"].as_array().unwrap().clone()
    }
}

/// A 14 m × 8 m room with a pillar: small enough to reason about in a test.
pub fn duel_map() -> Value {
    json!({
        "name": "duel",
        "width": 14.0,
        "height": 8.0,
        "obstacles": [[[6.5, 5.5], [7.5, 5.5], [7.5, 6.5], [6.5, 6.5]]],
        "robot_spawns": [[1.0, 4.0, 0.0], [1.0, 2.0, 0.0]],
        "opponent_spawns": [[13.0, 7.0], [13.0, 1.0]],
        "landmarks": [[7.0, 1.0]]
    })
}

/// 16 m × 10 m; a room in the top-right corner (x > 10.2, y > 6.2) whose only door is a
/// 1.4 m gap at x ∈ [12, 13.4] in its south wall.
pub fn one_door_room() -> Value {
    json!({
        "name": "one-door",
        "width": 16.0,
        "height": 10.0,
        "obstacles": [
            [[10.0, 6.0], [12.0, 6.0], [12.0, 6.2], [10.0, 6.2]],
            [[13.4, 6.0], [16.0, 6.0], [16.0, 6.2], [13.4, 6.2]],
            [[10.0, 6.2], [10.2, 6.2], [10.2, 10.0], [10.0, 10.0]]
        ],
        "robot_spawns": [[7.0, 3.0, 0.485]],
        "opponent_spawns": [[2.0, 8.0]]
    })
}
