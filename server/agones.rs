//! Agones (agones.dev): the game-server lifecycle a Kubernetes fleet of lasertag servers
//! expects, spoken to the SDK sidecar Agones runs beside each server (built with the
//! `agones` cargo feature; without it the module does not exist).
//!
//! - **Ready** once the server listens (retried: the sidecar may start after us);
//! - **Health** every [`HEALTH_EVERY`], while the server's loop is alive (a wedged runtime
//!   stops the pings and Agones restarts the pod);
//! - the **`matches` counter** set to the matches the server holds, when it changes, so a
//!   `FleetAutoscaler` with a Counter policy scales on it (`deploy/agones/`);
//! - **Allocated** when the first person takes a seat: Agones then never scales this server
//!   away under them;
//! - **Shutdown** when the server has drained (SIGTERM), after its matches ended and its
//!   history was written.
//!
//! It talks to the sidecar's HTTP gateway (`AGONES_SDK_HTTP_PORT`, the documented REST form
//! of the same SDK) rather than through the `agones` crate's gRPC client: that crate needs
//! `protoc` at build time and a second gRPC stack (tonic) for five calls a few seconds apart,
//! and hyper's own client, already in the tree, speaks HTTP/1.1 to a loopback port in a
//! page of code. A connection per call: calls are seconds apart.

use std::sync::Arc;
use std::time::Duration;

use axum::body::Body;
use axum::http::{Method, Request, StatusCode};
use hyper_util::rt::TokioIo;

use crate::game::Registry;

/// How often Health is sent: Agones' default `health.periodSeconds` is 5 s with a failure
/// threshold of 3, so a ping every 2 s survives one lost call.
pub const HEALTH_EVERY: Duration = Duration::from_secs(2);
/// The counter the fleet's autoscaler reads (`deploy/agones/fleetautoscaler.yaml`).
pub const MATCHES_COUNTER: &str = "matches";
/// How long one call may take before it counts as failed.
const CALL_TIMEOUT: Duration = Duration::from_secs(2);

/// A failed call to the sidecar.
#[derive(Debug, thiserror::Error)]
pub enum AgonesError {
    #[error("cannot reach the Agones sidecar at {addr}: {message}")]
    Unreachable { addr: String, message: String },
    #[error("the Agones sidecar answered {status} to {method} {path}")]
    Refused {
        method: Method,
        path: String,
        status: StatusCode,
    },
    #[error("the Agones sidecar did not answer {method} {path} within {CALL_TIMEOUT:?}")]
    Timeout { method: Method, path: String },
}

/// The SDK sidecar's HTTP gateway.
#[derive(Debug, Clone)]
pub struct Sidecar {
    addr: String,
}

impl Sidecar {
    /// The sidecar Agones announces to its game server (`AGONES_SDK_HTTP_PORT`), if any.
    pub fn from_env() -> Option<Sidecar> {
        let port: u16 = std::env::var("AGONES_SDK_HTTP_PORT").ok()?.parse().ok()?;
        Some(Sidecar::at(format!("127.0.0.1:{port}")))
    }

    /// The sidecar at `addr` (`host:port`).
    pub fn at(addr: String) -> Sidecar {
        Sidecar { addr }
    }

    pub async fn ready(&self) -> Result<(), AgonesError> {
        self.call(Method::POST, "/ready", "{}".to_owned()).await
    }

    pub async fn health(&self) -> Result<(), AgonesError> {
        self.call(Method::POST, "/health", "{}".to_owned()).await
    }

    pub async fn allocate(&self) -> Result<(), AgonesError> {
        self.call(Method::POST, "/allocate", "{}".to_owned()).await
    }

    pub async fn shutdown(&self) -> Result<(), AgonesError> {
        self.call(Method::POST, "/shutdown", "{}".to_owned()).await
    }

    /// Sets counter `name` (declared in the GameServer's spec) to `count`. The gateway maps
    /// `Int64Value` to a JSON string, as protobuf's JSON mapping writes 64-bit integers.
    pub async fn set_counter(&self, name: &str, count: u64) -> Result<(), AgonesError> {
        let body = format!(r#"{{"name":"{name}","count":"{count}"}}"#);
        self.call(Method::PATCH, &format!("/v1beta1/counters/{name}"), body)
            .await
    }

    async fn call(&self, method: Method, path: &str, body: String) -> Result<(), AgonesError> {
        let call = async {
            let unreachable = |e: &dyn std::fmt::Display| AgonesError::Unreachable {
                addr: self.addr.clone(),
                message: e.to_string(),
            };
            let stream = tokio::net::TcpStream::connect(&self.addr)
                .await
                .map_err(|e| unreachable(&e))?;
            let (mut sender, connection) =
                hyper::client::conn::http1::handshake(TokioIo::new(stream))
                    .await
                    .map_err(|e| unreachable(&e))?;
            // The connection's driver: it ends when the answer is in and `sender` dropped.
            tokio::spawn(connection);
            let request = Request::builder()
                .method(method.clone())
                .uri(path)
                .header("host", &self.addr)
                .header("content-type", "application/json")
                .body(Body::from(body))
                .map_err(|e| unreachable(&e))?;
            let answer = sender
                .send_request(request)
                .await
                .map_err(|e| unreachable(&e))?;
            if answer.status().is_success() {
                Ok(())
            } else {
                Err(AgonesError::Refused {
                    method: method.clone(),
                    path: path.to_owned(),
                    status: answer.status(),
                })
            }
        };
        tokio::time::timeout(CALL_TIMEOUT, call)
            .await
            .unwrap_or_else(|_| {
                Err(AgonesError::Timeout {
                    method: method.clone(),
                    path: path.to_owned(),
                })
            })
    }
}

/// What the lifecycle reads off the server each round.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Load {
    matches: u64,
    people: u64,
}

fn load(registry: &Registry) -> Load {
    let all = registry.all();
    Load {
        matches: all.len() as u64,
        people: all
            .iter()
            .map(|h| h.hub.summary.borrow().meta.players as u64)
            .sum(),
    }
}

/// Runs the lifecycle until the server starts shutting down (the serve command calls
/// [`Sidecar::shutdown`] once its matches have ended and its history is written). Failed
/// calls are logged and retried next round: the server keeps serving whatever the sidecar
/// does.
pub async fn run(registry: Arc<Registry>, sidecar: Sidecar) {
    // Ready, retried until the sidecar is up (it may start after the server).
    let mut delay = Duration::from_millis(200);
    loop {
        match sidecar.ready().await {
            Ok(()) => break,
            Err(e) => {
                tracing::warn!(error = %e, "Agones: not ready yet");
                tokio::select! {
                    _ = tokio::time::sleep(delay) => {}
                    _ = registry.shutdown.cancelled() => return,
                }
                delay = (delay * 2).min(HEALTH_EVERY);
            }
        }
    }
    tracing::info!("Agones: ready");
    let mut counted = None;
    let mut allocated = false;
    let mut every = tokio::time::interval(HEALTH_EVERY);
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        tokio::select! {
            _ = every.tick() => {}
            _ = registry.shutdown.cancelled() => break,
        }
        if let Err(e) = sidecar.health().await {
            tracing::warn!(error = %e, "Agones: health");
        }
        let now = load(&registry);
        if counted != Some(now.matches) {
            match sidecar.set_counter(MATCHES_COUNTER, now.matches).await {
                Ok(()) => counted = Some(now.matches),
                Err(e) => tracing::warn!(error = %e, "Agones: the matches counter"),
            }
        }
        if !allocated && now.people > 0 {
            match sidecar.allocate().await {
                Ok(()) => {
                    allocated = true;
                    tracing::info!("Agones: allocated (a person is playing)");
                }
                Err(e) => tracing::warn!(error = %e, "Agones: allocate"),
            }
        }
    }
}
