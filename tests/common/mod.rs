//! A real server on an ephemeral port, and helpers to drive it over HTTP.
#![allow(dead_code)]

use std::net::SocketAddr;
use std::path::Path;

use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use lasertag::config::Config;
use lasertag::game::Registry;
use lasertag::maps::MapStore;
use serde_json::{Value, json};

/// The robot observation of a team of 2 with 1 detection slot (docs/research.md).
pub const POLICY_OBSERVATION: usize = 240;

/// A dense layer of a test policy: `outputs` x `inputs` weights of at most `scale`, in a
/// fixed pattern, then `activation` ("" for none).
pub fn policy_layer(
    outputs: usize,
    inputs: usize,
    scale: f32,
    activation: &str,
) -> lasertag_policy::testing::DenseLayer<'_> {
    let weights = (0..outputs)
        .map(|o| {
            (0..inputs)
                .map(|i| scale * (((o * 31 + i * 17) % 13) as f32 - 6.0) / 6.0)
                .collect()
        })
        .collect();
    (weights, vec![0.1; outputs], activation)
}

/// A small ONNX policy of the right sizes (a robot observation of [`POLICY_OBSERVATION`]
/// values to the 3 action values) that drives forward and turns.
pub fn small_policy() -> Vec<u8> {
    lasertag_policy::testing::model(
        POLICY_OBSERVATION,
        &[
            policy_layer(16, POLICY_OBSERVATION, 0.05, "Tanh"),
            policy_layer(3, 16, 0.5, ""),
        ],
    )
}

/// The `id`s of a list of agents in a snapshot or a state.
pub fn ids(list: &Value) -> std::collections::BTreeSet<String> {
    list.as_array()
        .unwrap()
        .iter()
        .map(|a| a["id"].as_str().unwrap().to_string())
        .collect()
}

/// The shipped map `name`, loaded and validated as the server does at start-up.
pub fn shipped_arena(name: &str) -> std::sync::Arc<lasertag_core::sim::arena::Arena> {
    let store = MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps"))
        .expect("shipped maps load");
    store
        .get(name)
        .unwrap_or_else(|| panic!("{name} is shipped"))
        .arena
        .clone()
}

/// How many maps the server ships with.
pub fn shipped_map_count() -> usize {
    MapStore::load_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("maps"))
        .expect("shipped maps load")
        .len()
}

/// A new, empty directory under the system's temporary one, named for `what`.
pub fn temp_dir(what: &str) -> std::path::PathBuf {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("lasertag-{what}-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    dir
}

pub struct TestServer {
    pub addr: SocketAddr,
    pub client: reqwest::Client,
    pub registry: std::sync::Arc<Registry>,
    /// The owner token of each match this server's helpers created: `post` and `delete`
    /// present it for paths under that match, as its owner would.
    owner_tokens: std::sync::Mutex<std::collections::HashMap<String, String>>,
}

/// The default settings, except the per-address request rate and quotas: tests step manual
/// matches tick by tick and read the state after each, thousands of requests a second from
/// one address. The rate limit itself is crossed in `tests/limits.rs`.
pub fn test_config() -> Config {
    Config {
        requests_per_s: 1e6,
        request_burst: 1e6,
        // Every test client is 127.0.0.1; the per-client quotas are crossed in tests/access.rs.
        max_matches_per_address: 1000,
        max_maps_per_address: 1000,
        max_holds_per_address: 1000,
        max_seats_per_address: 1000,
        // One address plays both sides of a match in the tests; tests/pursuers.rs crosses
        // the rule.
        both_sides_per_address: true,
        max_exports_per_address: 1000,
        max_spectators_per_address: 1000,
        client_budget_share: 1.0,
        // Tests read beliefs as fast as they step; tests/hostile.rs crosses the rate.
        belief_mb_per_s: 1e4,
        belief_mb_per_s_all: 1e4,
        ..Config::default()
    }
}

pub struct Reply {
    pub status: u16,
    pub body: Value,
}

/// The operator's token of [`TestServer::with_admin`].
pub const ADMIN: &str = "operator-secret-0123456789";

impl TestServer {
    /// The app of `lasertag::http::app` with the shipped maps, on 127.0.0.1:0, without a showcase.
    pub async fn start() -> TestServer {
        TestServer::start_with(test_config()).await
    }

    /// [`TestServer::start`] with an operator whose token is [`ADMIN`].
    pub async fn with_admin() -> TestServer {
        TestServer::start_with(Config {
            admin_token: Some(lasertag::config::Secret(ADMIN.into())),
            ..test_config()
        })
        .await
    }

    /// Like [`TestServer::start`], with other settings (e.g. a short reconnect grace, tiny
    /// limits).
    pub async fn start_with(config: Config) -> TestServer {
        TestServer::start_with_history(config, lasertag::game::replay::History::default()).await
    }

    /// A server whose history is the store in `dir` (made by [`temp_dir`]); a second one on
    /// the same `dir` is the first restarted.
    pub async fn start_stored(dir: &Path) -> TestServer {
        let retention = lasertag::store::Retention {
            max_matches: 10_000,
            max_bytes: 1 << 30,
        };
        let store = lasertag::store::Store::open(dir, retention).expect("the store opens");
        let history = lasertag::game::replay::History::with_store(store);
        TestServer::start_with_history(test_config(), history).await
    }

    /// Waits until the store has everything this server's matches sent it.
    pub fn flush_history(&self) {
        if let Some(store) = self.registry.history.store() {
            store
                .flush(std::time::Duration::from_secs(10))
                .expect("the store flushes");
        }
    }

    pub async fn start_with_history(
        config: Config,
        history: lasertag::game::replay::History,
    ) -> TestServer {
        TestServer::start_serving(config, history, None).await
    }

    /// [`TestServer::start_with`], with WebTransport on the same port in UDP (a certificate
    /// of the server's own, `GET /api/transport`), as the binary serves it.
    pub async fn with_webtransport(config: Config) -> TestServer {
        let history = lasertag::game::replay::History::default();
        TestServer::start_serving(config, history, Some("127.0.0.1".parse().unwrap())).await
    }

    /// [`TestServer::with_webtransport`] with its UDP socket on another loopback address
    /// (`ip`, the same port): what it publishes (the page's host, the port) then reaches
    /// whatever the test puts there, a black hole for UDP blocked on the way.
    pub async fn with_webtransport_on(config: Config, ip: std::net::IpAddr) -> TestServer {
        let history = lasertag::game::replay::History::default();
        TestServer::start_serving(config, history, Some(ip)).await
    }

    async fn start_serving(
        config: Config,
        history: lasertag::game::replay::History,
        webtransport: Option<std::net::IpAddr>,
    ) -> TestServer {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let maps = MapStore::load_dir(&root.join("maps")).expect("shipped maps load");
        let registry = Registry::with_history(maps, config, history);
        let (app, state) = lasertag::http::app_and_state(registry.clone(), root.join("web"), None);
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        if let Some(ip) = webtransport {
            let source = lasertag::http::transport::Source::SelfSigned;
            let at = SocketAddr::new(ip, addr.port());
            lasertag::http::transport::start(state, at, source)
                .await
                .expect("WebTransport serves on the same port");
        }
        // As the binary serves it: its open files limit raised, its accept loop, with the
        // peer's address on each request.
        lasertag::http::raise_open_files_limit();
        let limits = lasertag::http::ConnectionLimits::of(&registry).expect("open files to serve");
        tokio::spawn(lasertag::http::serve(
            listener,
            app,
            limits,
            std::future::pending(),
        ));
        TestServer {
            addr,
            client: reqwest::Client::new(),
            registry,
            owner_tokens: Default::default(),
        }
    }

    /// Opens `/ws/matches/{id}` (with `?token=` when given); the handshake's error otherwise.
    pub async fn ws(&self, id: &str, token: Option<&str>) -> Result<Ws, WsError> {
        let url = match token {
            Some(t) => format!("ws://{}/ws/matches/{id}?token={t}", self.addr),
            None => format!("ws://{}/ws/matches/{id}", self.addr),
        };
        let (stream, _) = tokio_tungstenite::connect_async(url).await?;
        Ok(Ws { stream })
    }

    /// Joins match `id` as `name`: (opponent id, token).
    pub async fn join(&self, id: &str, name: &str) -> (String, String) {
        self.join_with(id, &json!({"name": name})).await
    }

    /// Claims `name` and joins match `id` under it, so its result is kept in the name's
    /// history (docs/api.md, "Names people keep"): (opponent id, token).
    pub async fn join_kept(&self, id: &str, name: &str) -> (String, String) {
        let claim = self.post("/api/names", &json!({"name": name})).await;
        assert_eq!(claim.status, 201, "{}", claim.body);
        let name_token = claim.body["name_token"].as_str().unwrap();
        self.join_with(id, &json!({"name": name, "name_token": name_token}))
            .await
    }

    async fn join_with(&self, id: &str, body: &Value) -> (String, String) {
        let r = self.post(&format!("/api/matches/{id}/players"), body).await;
        assert_eq!(r.status, 201, "{}", r.body);
        (
            r.body["opponent_id"].as_str().unwrap().to_string(),
            r.body["token"].as_str().unwrap().to_string(),
        )
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

    /// GET as the owner of the match it names (who sees a match people play live; see
    /// [`TestServer::owner_token`]).
    pub async fn get(&self, path: &str) -> Reply {
        self.get_as(path, self.owner_token(path).as_deref()).await
    }

    /// GET with `Authorization: Bearer <token>`, or without one (as anybody).
    pub async fn get_as(&self, path: &str, token: Option<&str>) -> Reply {
        let mut r = self.client.get(self.url(path));
        if let Some(t) = token {
            r = r.bearer_auth(t);
        }
        Self::reply(r.send().await.unwrap()).await
    }

    /// The owner token of the match `path` is under, if a helper created it.
    pub fn owner_token(&self, path: &str) -> Option<String> {
        let id = path
            .strip_prefix("/api/matches/")?
            .split(['/', '?'])
            .next()?;
        self.owner_tokens.lock().unwrap().get(id).cloned()
    }

    /// DELETE as the owner of the match it names (see [`TestServer::owner_token`]).
    pub async fn delete(&self, path: &str) -> Reply {
        self.delete_as(path, self.owner_token(path).as_deref())
            .await
    }

    /// DELETE with `Authorization: Bearer <token>`, or without one.
    pub async fn delete_as(&self, path: &str, token: Option<&str>) -> Reply {
        let mut r = self.client.delete(self.url(path));
        if let Some(t) = token {
            r = r.bearer_auth(t);
        }
        Self::reply(r.send().await.unwrap()).await
    }

    /// POST as the owner of the match it names (see [`TestServer::owner_token`]).
    pub async fn post(&self, path: &str, body: &Value) -> Reply {
        self.post_raw(path, serde_json::to_vec(body).unwrap()).await
    }

    /// POST with `Authorization: Bearer <token>`, or without one.
    pub async fn post_as(&self, path: &str, body: &Value, token: Option<&str>) -> Reply {
        let mut r = self
            .client
            .post(self.url(path))
            .header("content-type", "application/json")
            .body(serde_json::to_vec(body).unwrap());
        if let Some(t) = token {
            r = r.bearer_auth(t);
        }
        Self::reply(r.send().await.unwrap()).await
    }

    pub async fn post_raw(&self, path: &str, body: impl Into<reqwest::Body>) -> Reply {
        let mut r = self
            .client
            .post(self.url(path))
            .header("content-type", "application/json")
            .body(body);
        if let Some(t) = self.owner_token(path) {
            r = r.bearer_auth(t);
        }
        let reply = Self::reply(r.send().await.unwrap()).await;
        // Remember the owner of what this server's helpers create.
        if path == "/api/matches"
            && reply.status == 201
            && let (Some(id), Some(token)) = (
                reply.body["id"].as_str(),
                reply.body["owner_token"].as_str(),
            )
        {
            self.owner_tokens
                .lock()
                .unwrap()
                .insert(id.to_owned(), token.to_owned());
        }
        reply
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

/// A match on `office` for one person against two idle robots: `r0` 4 m in front of the
/// person's opponent in the west corridor, facing it; `r1` in a far room.
pub fn corridor_duel() -> Value {
    json!({"map": "office", "robots": 2, "opponents": 1,
        "opponent_control": "human", "planner": "idle", "time_limit_s": 120,
        "robot_starts": [[7.0, 8.0, std::f64::consts::PI], [22.0, 1.5, 0.0]],
        "opponent_starts": [[3.0, 8.0]]})
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

pub type WsError = tokio_tungstenite::tungstenite::Error;
pub use tokio_tungstenite::tungstenite::Message as WsMessage;

/// A WebSocket client of the game.
pub struct Ws {
    pub stream: tokio_tungstenite::WebSocketStream<
        tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>,
    >,
}

/// What [`Ws::next`] saw.
#[derive(Debug)]
pub enum Got {
    Json(Value),
    Closed {
        code: u16,
        reason: String,
    },
    /// The connection ended without a close frame.
    Ended,
}

impl Ws {
    pub async fn send_json(&mut self, v: &Value) -> Result<(), WsError> {
        self.stream
            .send(WsMessage::Text(v.to_string().into()))
            .await
    }

    pub async fn send_text(&mut self, s: String) -> Result<(), WsError> {
        self.stream.send(WsMessage::Text(s.into())).await
    }

    /// The next message (text parsed as JSON), waiting at most 10 s.
    pub async fn next(&mut self) -> Got {
        loop {
            let msg = tokio::time::timeout(Duration::from_secs(10), self.stream.next())
                .await
                .expect("a message within 10 s");
            match msg {
                Some(Ok(WsMessage::Text(t))) => {
                    return Got::Json(serde_json::from_str(t.as_str()).expect("JSON text"));
                }
                Some(Ok(WsMessage::Close(frame))) => {
                    return match frame {
                        Some(f) => Got::Closed {
                            code: f.code.into(),
                            reason: f.reason.to_string(),
                        },
                        None => Got::Closed {
                            code: 1005,
                            reason: String::new(),
                        },
                    };
                }
                Some(Ok(_)) => continue,
                Some(Err(_)) | None => return Got::Ended,
            }
        }
    }

    /// The next JSON message (panics on a close).
    pub async fn json(&mut self) -> Value {
        match self.next().await {
            Got::Json(v) => v,
            other => panic!("expected a message, got {other:?}"),
        }
    }

    /// The next message of `kind` (`snapshot`, `event`, …), skipping others.
    pub async fn next_of(&mut self, kind: &str) -> Value {
        loop {
            let v = self.json().await;
            if v["type"] == kind {
                return v;
            }
        }
    }
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

/// Asserts an API error reply: its status, and an `error` message that mentions `mentions`.
pub fn assert_error(r: &Reply, status: u16, mentions: &str) {
    assert_eq!(r.status, status, "{}", r.body);
    let msg = r.body["error"]
        .as_str()
        .unwrap_or_else(|| panic!("no error field: {}", r.body));
    assert!(
        msg.contains(mentions),
        "{msg:?} should mention {mentions:?}"
    );
}

/// A manual match on `office` with one human slot and robots that never move: what players
/// do is all that happens.
pub async fn idle_human_match(s: &TestServer) -> String {
    s.create_match(
        json!({"map": "office", "opponent_control": "human", "clock": "manual",
                          "planner": "idle"}),
    )
    .await
}
