//! Nodes of a fleet for the tests: real `lasertag` processes sharing a real `redis-server`
//! directory, with a short heartbeat so that the tests need not wait long.
#![allow(dead_code)]

use std::time::Duration;

use serde_json::Value;

use crate::process::Server;
use crate::redis_server::RedisServer;

/// The timing the nodes run with: a dead node leaves the listings within their sum.
pub const HEARTBEAT_S: f64 = 0.5;
pub const TTL_S: f64 = 1.5;
/// What a loaded 2-core machine may add to that bound: a late timer, a slow round trip.
pub const SLACK: Duration = Duration::from_millis(1500);

pub fn node(redis: &RedisServer, id: &str, extra: &[&str]) -> Server {
    let data = crate::common::temp_dir(&format!("fleet-{id}"));
    let data = data.display().to_string();
    let url = redis.url();
    let (heartbeat, ttl) = (HEARTBEAT_S.to_string(), TTL_S.to_string());
    let mut args = vec![
        "--no-showcase",
        "--data-dir",
        &data,
        "--fleet",
        &url,
        "--node-id",
        id,
        "--fleet-heartbeat-s",
        &heartbeat,
        "--fleet-ttl-s",
        &ttl,
    ];
    args.extend_from_slice(extra);
    Server::start(&args)
}

/// A client that does not follow redirects, to see them.
pub fn no_redirects() -> reqwest::Client {
    reqwest::Client::builder()
        .redirect(reqwest::redirect::Policy::none())
        .build()
        .expect("a client")
}

/// `POST /api/matches?place=local` on `server`: the created match.
pub async fn create_here(client: &reqwest::Client, server: &Server, body: Value) -> Value {
    let r = client
        .post(server.url("/api/matches?place=local"))
        .json(&body)
        .send()
        .await
        .expect("the server answers");
    assert_eq!(r.status(), 201);
    r.json().await.expect("JSON")
}
