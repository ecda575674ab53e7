//! One WebTransport session as a socket's carrier ([`crate::http::socket::Carrier`]): what a
//! WebSocket carries as messages, it carries in two ways. Snapshots go as datagrams when they
//! fit one (a lost one costs that snapshot, nothing behind it waits); everything else
//! (`welcome`, events, `finished`, errors, a snapshot too large for a datagram) goes on one
//! reliable stream the server opens, in frames. The client sends its inputs as datagrams and
//! the rest on one stream of its own.
//!
//! A frame, on either stream, and a datagram alike: a kind byte ([`TEXT`]: JSON, [`BINARY`]:
//! a compact snapshot) and the payload; on a stream the payload's length (`u32`, little
//! endian) comes between the two. An input datagram may hold a JSON array of inputs, oldest
//! first (the few before the newest, so that one lost datagram loses no input): those already
//! seen (by `seq`) are dropped here, so the socket sees each input once. A datagram of kind
//! [`ACK`] says which snapshots the client holds ([`Acks`]): kept here for the socket's next
//! delta, never a message (each costs a store, as cheap as QUIC's own reading of it).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::ws::{Message, Utf8Bytes};
use axum::http::StatusCode;
use serde::Deserialize;
use tokio::sync::mpsc;
use wtransport::endpoint::SessionRequest;
use wtransport::{Connection, RecvStream, SendStream, VarInt};

use crate::protocol::compact::Acks;

/// A frame's or datagram's kind: JSON text.
pub const TEXT: u8 = 0;
/// ... or a compact binary snapshot.
pub const BINARY: u8 = 1;
/// ... or, from the client, a datagram acknowledging snapshots ([`Acks`]).
pub const ACK: u8 = 2;
/// [`Session::acks`]'s word before the client has acknowledged any.
const NO_ACKS: u64 = u64::MAX;
/// The most inputs one datagram may repeat.
pub const MAX_INPUTS_PER_DATAGRAM: usize = 8;
/// The largest snapshot sent as a datagram (kind byte included): what every browser takes
/// (Chromium's `maxDatagramSize` is 1,024 at the least), whatever the path's MTU allows.
pub const MAX_DATAGRAM_BYTES: usize = 1024;
/// What was received and not yet read by the socket: the reader waits beyond it, and QUIC's
/// own buffers (bounded in `super::quic_transport`) drop datagrams behind it.
const QUEUE: usize = 16;

/// What the reader hands the socket: a message, or an error that ends it.
type Received = Result<Message, axum::Error>;

pub struct Session {
    conn: Connection,
    out: SendStream,
    incoming: mpsc::Receiver<Received>,
    reader: tokio::task::JoinHandle<()>,
    /// What the client last said it holds ([`Acks::to_word`]), or [`NO_ACKS`].
    acks: Arc<AtomicU64>,
    /// Snapshots sent as datagrams, and on the stream (too large for one).
    pub datagrams: u64,
    pub streamed: u64,
}

impl Drop for Session {
    fn drop(&mut self) {
        self.reader.abort();
    }
}

impl Session {
    /// Opens the server's stream on `conn` and starts reading what the client sends:
    /// messages up to `hard_bytes` (a larger one ends the session).
    pub async fn open(conn: Connection, hard_bytes: usize) -> Result<Session, String> {
        let out = conn
            .open_uni()
            .await
            .map_err(|e| e.to_string())?
            .await
            .map_err(|e| e.to_string())?;
        let (tx, incoming) = mpsc::channel(QUEUE);
        let acks = Arc::new(AtomicU64::new(NO_ACKS));
        let reader = tokio::spawn(read(conn.clone(), tx, acks.clone(), hard_bytes));
        Ok(Session {
            conn,
            out,
            incoming,
            reader,
            acks,
            datagrams: 0,
            streamed: 0,
        })
    }

    /// The client's next message; `None` once it has gone. Cancel-safe.
    pub async fn recv(&mut self) -> Option<Received> {
        self.incoming.recv().await
    }

    /// The snapshots the client last said it holds, if it has said.
    pub fn acks(&self) -> Option<Acks> {
        let word = self.acks.load(Ordering::Relaxed);
        (word != NO_ACKS).then(|| Acks::from_word(word))
    }

    /// Sends `message` on the reliable stream (a ping is QUIC's own business: nothing).
    pub async fn send(&mut self, message: Message) -> Result<(), String> {
        let (kind, payload): (u8, Bytes) = match message {
            Message::Text(t) => (TEXT, Bytes::from(t)),
            Message::Binary(b) => (BINARY, b),
            Message::Ping(_) | Message::Pong(_) | Message::Close(_) => return Ok(()),
        };
        let mut head = [0u8; 5];
        head[0] = kind;
        head[1..].copy_from_slice(&(payload.len() as u32).to_le_bytes());
        self.out.write_all(&head).await.map_err(|e| e.to_string())?;
        self.out
            .write_all(&payload)
            .await
            .map_err(|e| e.to_string())
    }

    /// Whether a snapshot of `len` bytes goes as one datagram (with its kind byte).
    pub fn fits_datagram(&self, len: usize) -> bool {
        let room = self
            .conn
            .max_datagram_size()
            .unwrap_or(0)
            .min(MAX_DATAGRAM_BYTES);
        len < room
    }

    /// Sends a snapshot: as a datagram when it fits one, else on the stream.
    pub async fn send_snapshot(&mut self, message: Message) -> Result<(), String> {
        let (kind, payload) = match &message {
            Message::Text(t) => (TEXT, t.as_bytes()),
            Message::Binary(b) => (BINARY, &b[..]),
            _ => return Ok(()),
        };
        if self.fits_datagram(payload.len()) {
            let mut datagram = Vec::with_capacity(payload.len() + 1);
            datagram.push(kind);
            datagram.extend_from_slice(payload);
            match self.conn.send_datagram(datagram) {
                Ok(()) => {
                    self.datagrams += 1;
                    return Ok(());
                }
                Err(wtransport::error::SendDatagramError::TooLarge) => {}
                Err(e) => return Err(e.to_string()),
            }
        }
        self.streamed += 1;
        self.send(message).await
    }

    /// Ends the session: a last `close` frame with `code` and `reason` (QUIC's own close
    /// code does not reach a browser's page), the stream finished within `drain`, then the
    /// connection closed.
    pub async fn close(&mut self, code: u16, reason: &str, drain: Duration) {
        let text = serde_json::json!({"type": "close", "code": code, "reason": reason});
        let sent = async {
            self.send(Message::Text(Utf8Bytes::from(text.to_string())))
                .await?;
            self.out.finish().await.map_err(|e| e.to_string())
        };
        let _ = tokio::time::timeout(drain, sent).await;
        self.conn
            .close(VarInt::from_u32(u32::from(code)), reason.as_bytes());
    }
}

/// A session's request, shared between the socket's handler (which accepts it once it is
/// admitted) and the accept loop (which refuses it when the handler says no).
#[derive(Clone)]
pub struct Refusable(Arc<Mutex<Option<SessionRequest>>>);

impl Refusable {
    pub fn new(request: SessionRequest) -> Refusable {
        Refusable(Arc::new(Mutex::new(Some(request))))
    }

    fn take(&self) -> Option<SessionRequest> {
        self.0.lock().ok().and_then(|mut r| r.take())
    }

    /// Accepts the session and opens its streams; `None` if the client went meanwhile.
    pub async fn accept(&self, hard_bytes: usize) -> Option<Session> {
        let conn = self.take()?.accept().await.ok()?;
        Session::open(conn, hard_bytes).await.ok()
    }

    /// Refuses it with the nearest status the protocol can say: 404, 429 (for 503 too), or
    /// else 403. (A browser's page is told only that the handshake failed.)
    pub async fn refuse(&self, status: StatusCode) {
        let Some(request) = self.take() else { return };
        match status {
            StatusCode::NOT_FOUND => request.not_found().await,
            StatusCode::TOO_MANY_REQUESTS | StatusCode::SERVICE_UNAVAILABLE => {
                request.too_many_requests().await
            }
            _ => request.forbidden().await,
        }
    }
}

/// An input's number: enough of it to tell one already seen.
#[derive(Deserialize)]
struct Numbered {
    seq: Option<u64>,
}

/// Reads the client's datagrams and its stream into `tx` until either side ends.
async fn read(
    conn: Connection,
    tx: mpsc::Sender<Received>,
    acks: Arc<AtomicU64>,
    hard_bytes: usize,
) {
    let mut stream: Option<RecvStream> = None;
    let mut newest_seq = 0u64;
    loop {
        let got = tokio::select! {
            datagram = conn.receive_datagram() => match datagram {
                Ok(d) => {
                    if let Some(a) = acknowledged(&d) {
                        acks.store(a.to_word(), Ordering::Relaxed);
                        continue;
                    }
                    inputs(&d, &mut newest_seq)
                }
                Err(_) => return,
            },
            accepted = conn.accept_uni(), if stream.is_none() => match accepted {
                Ok(s) => {
                    stream = Some(s);
                    continue;
                }
                Err(_) => return,
            },
            frame = async {
                match stream.as_mut() {
                    Some(s) => read_frame(s, hard_bytes).await,
                    None => std::future::pending().await,
                }
            } => match frame {
                Ok(Some(m)) => vec![Ok(m)],
                Ok(None) => return,
                Err(e) => vec![Err(e)],
            },
        };
        for m in got {
            let end = m.is_err();
            if tx.send(m).await.is_err() || end {
                return;
            }
        }
    }
}

/// What an acknowledgement datagram says; `None` for any other datagram (a malformed
/// acknowledgement goes to the socket, which refuses it).
fn acknowledged(datagram: &[u8]) -> Option<Acks> {
    match datagram.split_first() {
        Some((&ACK, rest)) => Acks::parse(rest).filter(|a| a.to_word() != NO_ACKS),
        _ => None,
    }
}

/// The messages of one datagram: a binary one as it is (the socket refuses it), a text one
/// as it is, or each input of an array the socket has not seen yet.
fn inputs(datagram: &[u8], newest_seq: &mut u64) -> Vec<Received> {
    let Some((&kind, payload)) = datagram.split_first() else {
        return vec![Ok(Message::Binary(Bytes::new()))];
    };
    let Ok(text) = std::str::from_utf8(payload) else {
        return vec![Ok(Message::Binary(Bytes::copy_from_slice(payload)))];
    };
    if kind != TEXT {
        return vec![Ok(Message::Binary(Bytes::copy_from_slice(payload)))];
    }
    let whole = || vec![Ok(Message::Text(Utf8Bytes::from(text)))];
    if !text.trim_start().starts_with('[') {
        return whole();
    }
    let Ok(list) = serde_json::from_str::<Vec<serde_json::Value>>(text) else {
        return whole();
    };
    if list.len() > MAX_INPUTS_PER_DATAGRAM {
        return whole();
    }
    let mut out = Vec::new();
    for input in list {
        let seq = Numbered::deserialize(&input).ok().and_then(|n| n.seq);
        if let Some(seq) = seq {
            if seq <= *newest_seq {
                continue;
            }
            *newest_seq = seq;
        }
        out.push(Ok(Message::Text(Utf8Bytes::from(input.to_string()))));
    }
    out
}

/// The next frame of the client's stream; `None` at its end. A frame over `hard_bytes` is an
/// error that names it (the socket closes with "message too big").
async fn read_frame(s: &mut RecvStream, hard_bytes: usize) -> Result<Option<Message>, axum::Error> {
    let mut head = [0u8; 5];
    if s.read_exact(&mut head).await.is_err() {
        return Ok(None);
    }
    let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]) as usize;
    if len > hard_bytes {
        return Err(axum::Error::new(format!(
            "frame of {len} bytes is too long (space limit {hard_bytes})"
        )));
    }
    let mut payload = vec![0u8; len];
    if s.read_exact(&mut payload).await.is_err() {
        return Ok(None);
    }
    Ok(Some(match (head[0], String::from_utf8(payload)) {
        (TEXT, Ok(text)) => Message::Text(Utf8Bytes::from(text)),
        (_, Ok(text)) => Message::Binary(Bytes::from(text.into_bytes())),
        (_, Err(e)) => Message::Binary(Bytes::from(e.into_bytes())),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn texts(got: Vec<Received>) -> Vec<String> {
        got.into_iter()
            .map(|m| match m {
                Ok(Message::Text(t)) => t.to_string(),
                other => format!("{other:?}"),
            })
            .collect()
    }

    #[test]
    fn repeated_inputs_pass_once_in_order() {
        let mut newest = 0;
        let d = |s: &str| [&[TEXT][..], s.as_bytes()].concat();
        let first = inputs(&d(r#"[{"seq":1},{"seq":2}]"#), &mut newest);
        assert_eq!(texts(first), [r#"{"seq":1}"#, r#"{"seq":2}"#]);
        // The datagram with 3 was lost; 4's repeats it.
        let next = inputs(&d(r#"[{"seq":2},{"seq":3},{"seq":4}]"#), &mut newest);
        assert_eq!(texts(next), [r#"{"seq":3}"#, r#"{"seq":4}"#]);
        // A late datagram brings nothing new.
        assert!(inputs(&d(r#"[{"seq":3}]"#), &mut newest).is_empty());
        // A single message, and unnumbered ones, pass as they are.
        assert_eq!(
            texts(inputs(&d(r#"{"type":"ping","t":1}"#), &mut newest)),
            [r#"{"type":"ping","t":1}"#]
        );
    }

    #[test]
    fn acknowledgements_are_read_apart_from_messages() {
        let a = Acks {
            newest: 70,
            bits: 3,
        };
        let d = [&[ACK][..], &a.to_bytes()].concat();
        assert_eq!(acknowledged(&d), Some(a));
        assert_eq!(acknowledged(&d[..5]), None);
        assert_eq!(acknowledged(&[TEXT, b'{', b'}']), None);
        let mut newest = 0;
        assert!(matches!(
            inputs(&d[..5], &mut newest)[0],
            Ok(Message::Binary(_))
        ));
    }

    #[test]
    fn bad_datagrams_reach_the_socket_to_be_refused() {
        let mut newest = 0;
        let many = format!("[{}]", ["{}"; MAX_INPUTS_PER_DATAGRAM + 1].join(","));
        let d = [&[TEXT][..], many.as_bytes()].concat();
        assert_eq!(texts(inputs(&d, &mut newest)), [many]);
        assert!(matches!(
            inputs(&[BINARY, 1, 2], &mut newest)[0],
            Ok(Message::Binary(_))
        ));
        assert!(matches!(
            inputs(&[], &mut newest)[0],
            Ok(Message::Binary(_))
        ));
        assert!(matches!(
            inputs(&[TEXT, 0xff, 0xfe], &mut newest)[0],
            Ok(Message::Binary(_))
        ));
    }
}
