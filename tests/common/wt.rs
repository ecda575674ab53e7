//! A WebTransport client for the tests: a session on the server's UDP port, pinning the
//! certificate hash `GET /api/transport` publishes, that reads the server's frames and
//! datagrams and sends its own (the framing of `server/http/transport/session.rs`).

use std::time::Duration;

use serde_json::Value;
use wtransport::error::ConnectingError;
use wtransport::tls::Sha256Digest;
use wtransport::{ClientConfig, Connection, Endpoint, RecvStream, SendStream};

pub const TEXT: u8 = 0;
pub const BINARY: u8 = 1;
pub const ACK: u8 = 2;

/// A compact snapshot as it came: by datagram or on the stream.
#[derive(Debug)]
pub struct Arrived {
    pub datagram: bool,
    pub bytes: Vec<u8>,
}

pub struct WtClient {
    pub conn: Connection,
    frames: Option<RecvStream>,
    out: Option<SendStream>,
}

/// What `GET /api/transport` says: the URL and the hash to pin.
pub fn published(reply: &Value) -> (String, Sha256Digest) {
    let at = &reply["webtransport"];
    let url = at["url"].as_str().expect("a WebTransport URL").to_string();
    let hex = at["certificate_hashes"][0]["value"]
        .as_str()
        .expect("a hash");
    let mut bytes = [0u8; 32];
    for (i, b) in bytes.iter_mut().enumerate() {
        *b = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).expect("hex");
    }
    (url, Sha256Digest::new(bytes))
}

/// The whole snapshots a client holds, as the page keeps them (web/compact.js): the newest
/// 33 ticks, what its acknowledgements name.
#[derive(Default)]
pub struct Held {
    pub wholes: std::collections::BTreeMap<u32, Vec<u8>>,
    /// Snapshots taken (wholes and deltas).
    pub taken: u64,
}

/// The page acknowledges every this many snapshots it takes (web/socket.js).
pub const ACK_EVERY: u64 = 8;

impl Held {
    /// Takes a compact snapshot as it came: a whole is kept, a delta applied to the whole it
    /// names (which must be held) and kept, a motion part left; what it stands for.
    pub fn take(&mut self, bytes: Vec<u8>) -> Result<Option<Vec<u8>>, String> {
        use lasertag::protocol::compact;
        let tick = compact::tick_of(&bytes).ok_or("a snapshot without a tick")?;
        let whole = match bytes[0] {
            compact::KIND_MOTION => return Ok(None),
            compact::KIND_DELTA => {
                let base = compact::baseline_of(&bytes).ok_or("a delta without a base")?;
                let b = self
                    .wholes
                    .get(&base)
                    .ok_or_else(|| format!("a delta of {tick} against {base}, not held"))?;
                compact::apply_delta(b, &bytes).map_err(|e| e.to_string())?
            }
            _ => bytes,
        };
        self.taken += 1;
        self.wholes.insert(tick, whole.clone());
        while self.wholes.len() > 33 {
            self.wholes.pop_first();
        }
        Ok(Some(whole))
    }

    /// The acknowledgement datagram of what is held, when the page would send one (every
    /// [`ACK_EVERY`] snapshots taken).
    pub fn ack_due(&self) -> Option<Vec<u8>> {
        self.ack_due_every(ACK_EVERY)
    }

    /// The acknowledgement datagram when one is due every `every` snapshots taken (0: never).
    pub fn ack_due_every(&self, every: u64) -> Option<Vec<u8>> {
        (every > 0 && self.taken.is_multiple_of(every)).then(|| self.ack())
    }

    /// The acknowledgement datagram of what is held.
    pub fn ack(&self) -> Vec<u8> {
        let newest = self.wholes.keys().next_back().copied().unwrap_or(0);
        let bits = (0..32u32)
            .filter(|i| {
                newest
                    .checked_sub(1 + i)
                    .is_some_and(|t| self.wholes.contains_key(&t))
            })
            .fold(0u32, |b, i| b | 1 << i);
        let acks = lasertag::protocol::compact::Acks { newest, bits };
        [&[ACK][..], &acks.to_bytes()].concat()
    }
}

impl WtClient {
    /// Opens `url` (`https://host:port/ws/...?...`), pinning `hash`.
    pub async fn connect(url: &str, hash: &Sha256Digest) -> Result<WtClient, ConnectingError> {
        WtClient::connect_from(url, hash, None).await
    }

    /// [`WtClient::connect`] from the address `from` (its port chosen), or any.
    pub async fn connect_from(
        url: &str,
        hash: &Sha256Digest,
        from: Option<std::net::IpAddr>,
    ) -> Result<WtClient, ConnectingError> {
        let builder = ClientConfig::builder();
        let builder = match from {
            Some(ip) => builder.with_bind_address(std::net::SocketAddr::new(ip, 0)),
            None => builder.with_bind_default(),
        };
        let config = builder
            .with_server_certificate_hashes([hash.clone()])
            .build();
        let endpoint = Endpoint::client(config).expect("a client endpoint");
        let conn = endpoint.connect(url).await?;
        Ok(WtClient {
            conn,
            frames: None,
            out: None,
        })
    }

    /// The server's next frame on its stream: (kind, payload); `None` at the stream's end.
    pub async fn frame(&mut self) -> Option<(u8, Vec<u8>)> {
        if self.frames.is_none() {
            let s = tokio::time::timeout(Duration::from_secs(10), self.conn.accept_uni())
                .await
                .expect("the server opens its stream")
                .ok()?;
            self.frames = Some(s);
        }
        let s = self.frames.as_mut()?;
        let mut head = [0u8; 5];
        tokio::time::timeout(Duration::from_secs(10), s.read_exact(&mut head))
            .await
            .expect("a frame within 10 s")
            .ok()?;
        let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]) as usize;
        let mut payload = vec![0u8; len];
        s.read_exact(&mut payload).await.ok()?;
        Some((head[0], payload))
    }

    /// The next JSON frame of the server's stream.
    pub async fn json(&mut self) -> Value {
        loop {
            let (kind, payload) = self.frame().await.expect("a frame");
            if kind == TEXT {
                return serde_json::from_slice(&payload).expect("JSON");
            }
        }
    }

    /// The next frame of `kind` (`type`), skipping the others.
    pub async fn next_of(&mut self, kind: &str) -> Value {
        loop {
            let v = self.json().await;
            if v["type"] == kind {
                return v;
            }
        }
    }

    /// The next datagram: (kind, payload).
    pub async fn datagram(&mut self) -> (u8, Vec<u8>) {
        let d = tokio::time::timeout(Duration::from_secs(10), self.conn.receive_datagram())
            .await
            .expect("a datagram within 10 s")
            .expect("the session is open");
        let (kind, payload) = d.split_first().expect("a kind byte");
        (*kind, payload.to_vec())
    }

    /// Every compact snapshot from now on, by datagram or on the stream, in the order they
    /// arrive (each read by a task of its own: a frame half read is never given up).
    pub fn snapshots(mut self) -> (tokio::sync::mpsc::UnboundedReceiver<Arrived>, Connection) {
        let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
        let conn = self.conn.clone();
        let by_datagram = tx.clone();
        let datagrams = conn.clone();
        tokio::spawn(async move {
            while let Ok(d) = datagrams.receive_datagram().await {
                if d.first() == Some(&BINARY) {
                    let bytes = d[1..].to_vec();
                    if by_datagram
                        .send(Arrived {
                            datagram: true,
                            bytes,
                        })
                        .is_err()
                    {
                        break;
                    }
                }
            }
        });
        tokio::spawn(async move {
            let stream = match self.frames.take() {
                Some(s) => Some(s),
                None => self.conn.accept_uni().await.ok(),
            };
            let Some(mut s) = stream else { return };
            let mut head = [0u8; 5];
            while s.read_exact(&mut head).await.is_ok() {
                let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]) as usize;
                let mut bytes = vec![0u8; len];
                if s.read_exact(&mut bytes).await.is_err() {
                    break;
                }
                if head[0] == BINARY
                    && tx
                        .send(Arrived {
                            datagram: false,
                            bytes,
                        })
                        .is_err()
                {
                    break;
                }
            }
        });
        (rx, conn)
    }

    pub fn send_datagram(&self, kind: u8, payload: &[u8]) {
        let mut d = vec![kind];
        d.extend_from_slice(payload);
        self.conn.send_datagram(d).expect("a datagram goes");
    }

    /// Sends a frame on the client's own stream (opened at the first).
    pub async fn send_frame(&mut self, kind: u8, payload: &[u8], declared_len: Option<u32>) {
        if self.out.is_none() {
            let s = self
                .conn
                .open_uni()
                .await
                .expect("open")
                .await
                .expect("opened");
            self.out = Some(s);
        }
        let s = self.out.as_mut().expect("opened");
        let mut head = vec![kind];
        head.extend_from_slice(&declared_len.unwrap_or(payload.len() as u32).to_le_bytes());
        let _ = s.write_all(&head).await;
        let _ = s.write_all(payload).await;
    }
}
