//! The load test's clients: spectators and players (people at an opponent slot, sending an
//! input every tick), each over a WebSocket or a WebTransport session as the page opens
//! them. A client refused a WebTransport session, or a spectator moved off one for a player
//! (`server/http/transport/seats.rs`), goes on over its WebSocket, as the page does; each
//! client's stats say which carrier it ended on and why.

use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::json;
use tokio_tungstenite::tungstenite::Message;

use crate::wt;

/// Whom a client is: a spectator, or a person who takes a bot's opponent slot under `name`
/// just before connecting (a slot joined and not played lapses within seconds, and
/// thousands of handshakes before it can take longer).
#[derive(Debug, Clone)]
pub(crate) enum Seat {
    Spectator,
    Player { name: String },
}

/// What a client watches and for how long.
#[derive(Debug, Clone)]
pub(crate) struct Client {
    pub addr: SocketAddr,
    pub id: String,
    pub seat: Seat,
    pub http: reqwest::Client,
    /// When snapshots count: the window opens once every client is connected.
    pub window: Window,
    /// `json` or `compact`.
    pub format: String,
    /// Over WebTransport: acknowledge every this many snapshots taken (0: never).
    pub ack_every: u64,
    /// Its place among the clients (which loopback address its session opens from).
    pub index: usize,
}

/// The measured window, `[start, until)`: opened by the load test once every client is
/// connected (thousands of WebTransport handshakes, 8 at a time from each address, take
/// seconds, and a client connected late would otherwise count as starved), and the count
/// of clients connected.
#[derive(Debug, Clone)]
pub(crate) struct Window {
    opened: tokio::sync::watch::Receiver<Option<(Instant, Instant)>>,
    pub connected: Arc<AtomicUsize>,
}

impl Window {
    pub(crate) fn new(opened: tokio::sync::watch::Receiver<Option<(Instant, Instant)>>) -> Window {
        Window {
            opened,
            connected: Arc::default(),
        }
    }

    /// Whether a snapshot arriving now counts.
    fn counts(&self, now: Instant) -> bool {
        self.opened.borrow().is_some_and(|(start, _)| now >= start)
    }

    /// When the client stops: the window's end, or an hour off while it is not yet open.
    fn until(&self, now: Instant) -> Instant {
        self.opened
            .borrow()
            .map_or(now + Duration::from_secs(3600), |(_, until)| until)
    }

    fn note_connected(&self) {
        self.connected.fetch_add(1, Ordering::Relaxed);
    }
}

/// Where WebTransport sessions open, and the hash to pin (`GET /api/transport`).
#[derive(Clone)]
pub(crate) struct Published {
    pub url: String,
    pub hash: wtransport::tls::Sha256Digest,
    /// The loopback addresses the sessions open from, each with its handshakes in progress
    /// (the server takes 8 at once from one address): client `k` uses `sources[k % len]`.
    pub sources: Vec<(std::net::IpAddr, std::sync::Arc<tokio::sync::Semaphore>)>,
}

/// The carrier a client's snapshots came over at the end.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Carrier {
    #[default]
    WebSocket,
    WebTransport,
}

#[derive(Debug, Default, Clone)]
pub(crate) struct ClientStats {
    pub player: bool,
    pub carrier: Carrier,
    /// Its WebTransport session was refused (the server's sessions full).
    pub refused: bool,
    /// It held a WebTransport session and was moved off it (a player needed the place).
    pub moved: bool,
    pub snapshots: u64,
    pub distinct_ticks: u64,
    pub bytes_plain: u64,
    pub n_plain: u64,
    pub bytes_belief: u64,
    pub n_belief: u64,
    pub max_belief: u64,
    pub max_plain: u64,
    pub events: u64,
    pub closed_early: bool,
    /// Why its WebTransport session was closed early, as the server said.
    pub close_reason: Option<String>,
    last_tick: Option<u64>,
}

impl ClientStats {
    /// One snapshot of `len` bytes for `tick`.
    fn count(&mut self, tick: u64, belief: bool, len: u64) {
        self.snapshots += 1;
        if self.last_tick != Some(tick) {
            self.distinct_ticks += 1;
            self.last_tick = Some(tick);
        }
        if belief {
            self.bytes_belief += len;
            self.n_belief += 1;
            self.max_belief = self.max_belief.max(len);
        } else {
            self.bytes_plain += len;
            self.n_plain += 1;
            self.max_plain = self.max_plain.max(len);
        }
    }
}

impl Client {
    /// The socket's path: a spectator's, or the player's with its `token`.
    fn path(&self, token: Option<&str>) -> String {
        match token {
            None => format!("/ws/matches/{}?format={}", self.id, self.format),
            Some(token) => format!(
                "/ws/matches/{}?token={token}&format={}",
                self.id, self.format
            ),
        }
    }

    /// A player's token: its slot taken now (`POST /api/matches/{id}/players`); none for a
    /// spectator, or when the join failed (the player then counts as closed early).
    async fn join(&self) -> Result<Option<String>, ()> {
        let Seat::Player { name } = &self.seat else {
            return Ok(None);
        };
        let url = format!("http://{}/api/matches/{}/players", self.addr, self.id);
        let r = self
            .http
            .post(url)
            .json(&json!({"name": name}))
            .send()
            .await;
        let v: serde_json::Value = match r {
            Ok(r) if r.status() == 201 => r.json().await.map_err(|_| ())?,
            Ok(r) => {
                let status = r.status();
                eprintln!(
                    "{name} could not join: {status} {}",
                    r.text().await.unwrap_or_default()
                );
                return Err(());
            }
            Err(e) => {
                eprintln!("{name} could not join: {e}");
                return Err(());
            }
        };
        Ok(v["token"].as_str().map(str::to_string))
    }

    fn player(&self) -> bool {
        matches!(self.seat, Seat::Player { .. })
    }

    /// The input a player sends for tick-step `seq`: walking, turning a little, so that it
    /// moves about the map and its view changes as a person's does.
    fn input(seq: u64) -> serde_json::Value {
        json!({"type": "input", "forward": 1.0, "turn": 0.3, "tag": false, "seq": seq})
    }

    /// Watches over a WebSocket until `until`.
    pub(crate) async fn over_websocket(&self) -> ClientStats {
        let mut st = ClientStats {
            player: self.player(),
            ..ClientStats::default()
        };
        match self.join().await {
            Ok(token) => self.websocket_into(&mut st, token.as_deref()).await,
            Err(()) => {
                self.window.note_connected();
                st.closed_early = true;
            }
        }
        st
    }

    async fn websocket_into(&self, st: &mut ClientStats, token: Option<&str>) {
        st.carrier = Carrier::WebSocket;
        let url = format!("ws://{}{}", self.addr, self.path(token));
        let connected =
            tokio_tungstenite::connect_async_with_config(url, Some(lean_client()), true).await;
        if !st.moved {
            self.window.note_connected();
        }
        let Ok((mut ws, _)) = connected else {
            st.closed_early = true;
            return;
        };
        let mut inputs = tokio::time::interval(Duration::from_millis(50));
        let mut seq = 0;
        loop {
            let now = Instant::now();
            let until = self.window.until(now);
            if now >= until {
                break;
            }
            let msg = tokio::select! {
                _ = inputs.tick(), if self.player() => {
                    seq += 1;
                    let text = Client::input(seq).to_string();
                    if ws.send(Message::text(text)).await.is_err() {
                        st.closed_early = true;
                        break;
                    }
                    continue;
                }
                m = tokio::time::timeout(until - now, ws.next()) => m,
            };
            let msg = match msg {
                Err(_) => break,
                Ok(Some(Ok(m))) => m,
                Ok(_) => {
                    st.closed_early = true;
                    break;
                }
            };
            if !self.window.counts(Instant::now()) {
                continue; // warm-up: connecting clients
            }
            if let Message::Binary(b) = &msg {
                // A compact snapshot, whole (kind 1) or a delta (2): flags (2: with the
                // belief), the tick.
                if let (Some(1 | 2), Some(tick)) =
                    (b.first(), lasertag::protocol::compact::tick_of(b))
                {
                    st.count(u64::from(tick), b[1] & 2 != 0, b.len() as u64);
                }
                continue;
            }
            let Message::Text(t) = msg else { continue };
            let text = t.as_str();
            if text.starts_with("{\"type\":\"snapshot\"") {
                if let Some(tick) = tick_of(text) {
                    st.count(tick, text.contains("\"belief\":"), text.len() as u64);
                }
            } else if text.starts_with("{\"type\":\"event\"") {
                st.events += 1;
            }
        }
        let _ = ws.close(None).await;
    }

    /// Watches over WebTransport (compact snapshots by datagram or on the stream, what is
    /// held acknowledged every `--ack-every` taken, a player's inputs by datagram, as the page
    /// does); over the WebSocket when the session is refused or, for a spectator, moved.
    pub(crate) async fn over_webtransport(&self, at: &Published) -> ClientStats {
        let mut st = ClientStats {
            player: self.player(),
            carrier: Carrier::WebTransport,
            ..ClientStats::default()
        };
        let (connected, token) = {
            let (from, handshakes) = &at.sources[self.index % at.sources.len()];
            let _permit = handshakes.acquire().await;
            let Ok(token) = self.join().await else {
                self.window.note_connected();
                st.closed_early = true;
                return st;
            };
            let url = format!("{}{}", at.url, self.path(token.as_deref()));
            (
                wt::WtClient::connect_from(&url, &at.hash, Some(*from)).await,
                token,
            )
        };
        let Ok(client) = connected else {
            st.refused = true;
            self.websocket_into(&mut st, token.as_deref()).await;
            return st;
        };
        self.window.note_connected();
        let (mut snapshots, conn) = client.snapshots();
        let mut held = wt::Held::default();
        let mut inputs = tokio::time::interval(Duration::from_millis(50));
        let mut seq = 0u64;
        loop {
            let now = Instant::now();
            let until = self.window.until(now);
            if now >= until {
                break;
            }
            let arrived = tokio::select! {
                _ = inputs.tick(), if self.player() => {
                    // Each datagram carries the two inputs before it, as the page's do.
                    seq += 1;
                    let batch: Vec<_> = (seq.saturating_sub(2).max(1)..=seq).map(Client::input).collect();
                    let mut d = vec![wt::TEXT];
                    d.extend_from_slice(json!(batch).to_string().as_bytes());
                    let _ = conn.send_datagram(d);
                    continue;
                }
                a = tokio::time::timeout(until - now, snapshots.recv()) => a,
            };
            let a = match arrived {
                Err(_) => break,
                Ok(Some(a)) => a,
                Ok(None) if self.player() => {
                    st.closed_early = true;
                    st.close_reason = Some(conn.closed().await.to_string());
                    break;
                }
                Ok(None) => {
                    // Moved off for a player (1012, as the page is told): the rest of the
                    // window over the WebSocket. Any other close (the match ended) ends it.
                    let moved = matches!(
                        conn.closed().await,
                        wtransport::error::ConnectionError::ApplicationClosed(c)
                            if c.code() == wtransport::VarInt::from_u32(1012)
                    );
                    if !moved {
                        break;
                    }
                    st.moved = true;
                    self.websocket_into(&mut st, None).await;
                    return st;
                }
            };
            let (kind, flags, len) = (a.bytes[0], a.bytes.get(1).copied(), a.bytes.len() as u64);
            let tick = lasertag::protocol::compact::tick_of(&a.bytes);
            if let (Ok(Some(_)), Some(ack)) =
                (held.take(a.bytes), held.ack_due_every(self.ack_every))
            {
                let _ = conn.send_datagram(ack);
            }
            // Wholes and deltas (a motion part is followed by its whole).
            if self.window.counts(Instant::now())
                && matches!(kind, 1 | 2)
                && let (Some(t), Some(f)) = (tick, flags)
            {
                st.count(u64::from(t), f & 2 != 0, len);
            }
        }
        conn.close(0u32.into(), b"done");
        st
    }
}

fn tick_of(text: &str) -> Option<u64> {
    let i = text.find("\"tick\":")? + 7;
    let rest = &text[i..];
    let end = rest
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// A client that reads 4 KiB at a time: tungstenite's default 128 KiB read buffer is zeroed
/// on every read, and thousands of clients on the server's own cores would measure that
/// rather than the server (a browser has no such cost).
fn lean_client() -> tokio_tungstenite::tungstenite::protocol::WebSocketConfig {
    tokio_tungstenite::tungstenite::protocol::WebSocketConfig::default().read_buffer_size(4 << 10)
}
