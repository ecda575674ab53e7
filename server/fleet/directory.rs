//! The one task that talks to Redis: every heartbeat it writes this node's key and reads
//! the others', then hands the handlers a new [`View`]. Nothing else waits on Redis.
//!
//! Keys (database of the `--fleet` URL):
//! - `lasertag:fleet:node:<id>`: the node's [`NodeRecord`] as JSON, set with `PX ttl` each
//!   heartbeat (so it vanishes `ttl` after the node's last one);
//! - `lasertag:fleet:nodes`: a set of node ids, to find the keys without `SCAN`. An id
//!   whose key has expired is removed from it by whichever node notices first.
//!
//! A heartbeat is two round trips: `SET`, `SADD`, `SMEMBERS` (and `SREM` of ids found
//! dead) in one pipeline, then one `MGET` of the others' keys. Every round trip is bounded
//! by the heartbeat period; a failed one drops the connection, and the next heartbeat
//! connects again.

use std::sync::Arc;
use std::time::Duration;

use redis::aio::MultiplexedConnection;
use tokio::sync::{mpsc, oneshot};
use tokio::time::{Instant, MissedTickBehavior};

use crate::fleet::nodes::{RemoteNode, Settings, View};
use crate::game::Registry;
use crate::protocol::fleet::{NodeRecord, NodeRef, RECORD_FORMAT, RemoteSummary};

const NODES: &str = "lasertag:fleet:nodes";

fn node_key(id: &str) -> String {
    format!("lasertag:fleet:node:{id}")
}

/// The directory task's state between heartbeats.
struct Directory {
    settings: Arc<Settings>,
    registry: Arc<Registry>,
    /// Hands the handlers each new view of the other nodes.
    publish: Box<dyn Fn(View) + Send + Sync>,
    client: redis::Client,
    connection: Option<MultiplexedConnection>,
    /// When Redis last answered a whole heartbeat.
    last_ok: Option<Instant>,
    /// Whether the last heartbeat failed (so that an outage is logged once, and so is the
    /// recovery).
    failing: bool,
    /// Ids found in the set whose keys had expired: removed with the next write.
    dead: Vec<String>,
    /// Node ids whose records could not be read, logged once each.
    unreadable: std::collections::HashSet<String>,
}

pub(super) async fn run(
    settings: Settings,
    registry: Arc<Registry>,
    publish: Box<dyn Fn(View) + Send + Sync>,
    client: redis::Client,
    mut leave: mpsc::Receiver<oneshot::Sender<()>>,
) {
    let heartbeat = settings.heartbeat;
    let draining = registry.draining.clone();
    let mut directory = Directory {
        settings: Arc::new(settings),
        registry,
        publish,
        client,
        connection: None,
        last_ok: None,
        failing: false,
        dead: Vec::new(),
        unreadable: Default::default(),
    };
    tracing::info!(
        node = %directory.settings.node_id,
        url = %directory.settings.public_url,
        "fleet: joining the directory"
    );
    let mut ticks = tokio::time::interval(heartbeat);
    ticks.set_missed_tick_behavior(MissedTickBehavior::Delay);
    let mut told_draining = false;
    loop {
        tokio::select! {
            _ = ticks.tick() => {}
            // The moment it starts draining, say so: no node should place a match here.
            () = draining.cancelled(), if !told_draining => told_draining = true,
            asked = leave.recv() => {
                directory.leave().await;
                if let Some(reply) = asked {
                    let _ = reply.send(());
                }
                return;
            }
        }
        directory.beat().await;
    }
}

impl Directory {
    fn timeout(&self) -> Duration {
        self.settings.heartbeat
    }

    async fn connection(&mut self) -> Result<MultiplexedConnection, redis::RedisError> {
        if let Some(c) = &self.connection {
            return Ok(c.clone());
        }
        let config = redis::AsyncConnectionConfig::new()
            .set_connection_timeout(Some(self.timeout()))
            .set_response_timeout(Some(self.timeout()));
        let c = self
            .client
            .get_multiplexed_async_connection_with_config(&config)
            .await?;
        self.connection = Some(c.clone());
        Ok(c)
    }

    /// One round trip, counted; a failure drops the connection.
    async fn round_trip<T: redis::FromRedisValue>(
        &mut self,
        pipe: &redis::Pipeline,
    ) -> Result<T, redis::RedisError> {
        let registry = self.registry.clone();
        let metrics = &registry.metrics;
        metrics.fleet_round_trips.inc();
        let r = match self.connection().await {
            Ok(mut c) => pipe.query_async(&mut c).await,
            Err(e) => Err(e),
        };
        if r.is_err() {
            metrics.fleet_errors.inc();
            self.connection = None;
        }
        r
    }

    async fn beat(&mut self) {
        match self.exchange().await {
            Ok(view) => {
                if self.failing {
                    tracing::info!("fleet: the directory answers again");
                }
                self.failing = false;
                self.last_ok = Some(Instant::now());
                (self.publish)(view);
            }
            Err(e) => {
                if !self.failing {
                    tracing::warn!(
                        "fleet: the directory does not answer ({e}); serving this node's matches, retrying every {:?}",
                        self.timeout()
                    );
                }
                self.failing = true;
                // Past the TTL nothing tells whether the others are alive: list only ours.
                let stale = self.last_ok.is_none_or(|t| t.elapsed() > self.settings.ttl);
                if stale {
                    (self.publish)(View::default());
                }
            }
        }
    }

    /// Writes this node's record and reads every other's.
    async fn exchange(&mut self) -> Result<View, redis::RedisError> {
        let settings = self.settings.clone();
        let me = &settings.node_id;
        let record = self.record();
        let ttl_ms = self.settings.ttl.as_millis() as u64;
        let mut pipe = redis::pipe();
        pipe.cmd("SET")
            .arg(node_key(me))
            .arg(record)
            .arg("PX")
            .arg(ttl_ms)
            .ignore()
            .cmd("SADD")
            .arg(NODES)
            .arg(me)
            .ignore();
        if !self.dead.is_empty() {
            pipe.cmd("SREM").arg(NODES).arg(&self.dead).ignore();
        }
        pipe.cmd("SMEMBERS").arg(NODES);
        let (mut ids,): (Vec<String>,) = self.round_trip(&pipe).await?;
        self.dead.clear();
        ids.retain(|id| id != me);
        ids.sort();
        if ids.is_empty() {
            return Ok(View::default());
        }
        let mut mget = redis::pipe();
        mget.cmd("MGET")
            .arg(ids.iter().map(|id| node_key(id)).collect::<Vec<_>>());
        let (records,): (Vec<Option<Vec<u8>>>,) = self.round_trip(&mget).await?;
        let mut nodes = Vec::with_capacity(ids.len());
        for (id, bytes) in ids.into_iter().zip(records) {
            let Some(bytes) = bytes else {
                self.dead.push(id);
                continue;
            };
            match NodeRecord::<RemoteSummary>::decode(&bytes) {
                Some(r) if r.id == id => nodes.push(RemoteNode {
                    node: NodeRef {
                        id: r.id,
                        url: r.url,
                        local: false,
                        draining: r.draining,
                    },
                    capacity: r.capacity,
                    held: r.held,
                    players: r.players,
                    spectators: r.spectators,
                    writer: r.writer,
                    matches: r.matches,
                }),
                _ => {
                    if self.unreadable.insert(id.clone()) {
                        tracing::warn!(
                            node = %id,
                            "fleet: a record this version cannot read (another format version?); its matches are not listed here"
                        );
                    }
                }
            }
        }
        Ok(View::new(nodes))
    }

    /// This node's record: its load and every match it holds, as its own listing shows them.
    fn record(&self) -> Vec<u8> {
        let registry = &self.registry;
        let summaries: Vec<_> = registry
            .all()
            .iter()
            .map(|h| crate::protocol::summary(&h.hub.summary.borrow()))
            .collect();
        let record = NodeRecord {
            format: RECORD_FORMAT,
            id: self.settings.node_id.clone(),
            url: self.settings.public_url.clone(),
            capacity: registry.config.max_matches,
            held: summaries.len(),
            players: summaries.iter().map(|s| s.players).sum(),
            spectators: summaries.iter().map(|s| s.spectators).sum(),
            draining: registry.draining.is_cancelled(),
            writer: registry
                .history
                .store()
                .filter(|s| s.adopts())
                .and_then(|s| s.writer_id().map(str::to_string)),
            matches: summaries.iter().collect(),
        };
        record.encode()
    }

    /// Deletes this node's key and id: the others drop it on their next read.
    async fn leave(&mut self) {
        let me = self.settings.node_id.clone();
        let mut pipe = redis::pipe();
        pipe.cmd("DEL")
            .arg(node_key(&me))
            .ignore()
            .cmd("SREM")
            .arg(NODES)
            .arg(&me)
            .ignore();
        match self.round_trip::<()>(&pipe).await {
            Ok(()) => tracing::info!(node = %me, "fleet: left the directory"),
            Err(e) => tracing::warn!(
                node = %me,
                "fleet: could not leave the directory ({e}); the key expires by itself"
            ),
        }
    }
}
