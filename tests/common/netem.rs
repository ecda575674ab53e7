//! A loopback proxy that makes a TCP connection behave like one across a real network, for
//! the tests and measurement programs of play over a network.
//!
//! Every chunk read from one side is written to the other half a round trip later, give or
//! take the jitter. A lost chunk is not dropped (the bytes are a TCP stream, and TCP
//! delivers everything): it is held back one retransmission time-out, as the sender's TCP
//! would resend it, and everything behind it waits too (head-of-line blocking, what loss
//! really costs a WebSocket). Order is kept in each direction. Seeded, so a run can be
//! repeated.

use std::net::SocketAddr;
use std::time::Duration;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;
use tokio::time::Instant;

/// What the network between client and server does.
#[derive(Debug, Clone, Copy)]
pub struct Conditions {
    /// Round trip added (half each way).
    pub rtt: Duration,
    /// Each chunk's one-way delay varies by up to this much either way.
    pub jitter: Duration,
    /// Probability that a chunk is lost once (and resent after `rto`).
    pub loss: f64,
    /// How long a lost chunk takes to arrive after all (TCP's minimum time-out is 200 ms).
    pub rto: Duration,
    pub seed: u64,
}

impl Conditions {
    /// A round trip of `rtt_ms`, no jitter, no loss.
    pub fn rtt_ms(rtt_ms: u64) -> Conditions {
        Conditions {
            rtt: Duration::from_millis(rtt_ms),
            jitter: Duration::ZERO,
            loss: 0.0,
            rto: Duration::from_millis(200),
            seed: 1,
        }
    }
}

/// A running proxy: connect to `addr` to reach the upstream through the conditions.
#[derive(Debug)]
pub struct Netem {
    pub addr: SocketAddr,
}

impl Netem {
    /// Listens on an ephemeral loopback port and forwards every connection to `upstream`.
    pub async fn start(upstream: SocketAddr, conditions: Conditions) -> Netem {
        let listener = TcpListener::bind("127.0.0.1:0")
            .await
            .expect("bind the proxy");
        let addr = listener.local_addr().expect("proxy address");
        tokio::spawn(async move {
            let mut connection = 0u64;
            while let Ok((client, _)) = listener.accept().await {
                connection += 1;
                let Ok(server) = TcpStream::connect(upstream).await else {
                    continue;
                };
                let _ = client.set_nodelay(true);
                let _ = server.set_nodelay(true);
                let (cr, cw) = client.into_split();
                let (sr, sw) = server.into_split();
                // Each direction its own stream of draws.
                let seed = conditions.seed.wrapping_mul(1_000_003) ^ connection;
                tokio::spawn(pipe(cr, sw, conditions, seed * 2));
                tokio::spawn(pipe(sr, cw, conditions, seed * 2 + 1));
            }
        });
        Netem { addr }
    }
}

/// Copies `from` to `to`, each chunk delayed as `c` says.
async fn pipe(
    mut from: tokio::net::tcp::OwnedReadHalf,
    mut to: tokio::net::tcp::OwnedWriteHalf,
    c: Conditions,
    seed: u64,
) {
    let (tx, mut rx) = mpsc::unbounded_channel::<(Instant, Vec<u8>)>();
    let writer = tokio::spawn(async move {
        while let Some((at, bytes)) = rx.recv().await {
            tokio::time::sleep_until(at).await;
            if to.write_all(&bytes).await.is_err() {
                break;
            }
        }
        let _ = to.shutdown().await;
    });
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut last = Instant::now();
    let mut buf = vec![0u8; 64 * 1024];
    loop {
        let n = match from.read(&mut buf).await {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        let one_way = c.rtt.as_secs_f64() / 2.0;
        let jitter = c.jitter.as_secs_f64() * (rng.random::<f64>() * 2.0 - 1.0);
        let lost = rng.random::<f64>() < c.loss;
        let delay = (one_way + jitter).max(0.0) + if lost { c.rto.as_secs_f64() } else { 0.0 };
        // Never before the chunk ahead of it: a stream keeps its order.
        let at = (Instant::now() + Duration::from_secs_f64(delay)).max(last);
        last = at;
        if tx.send((at, buf[..n].to_vec())).is_err() {
            break;
        }
    }
    drop(tx);
    let _ = writer.await;
}
