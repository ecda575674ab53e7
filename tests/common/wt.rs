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
