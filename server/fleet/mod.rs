//! The fleet: several servers that share one directory in Redis (`--fleet redis://…`), so
//! that any node's lobby lists every node's matches and a request for a match hosted
//! elsewhere is sent there.
//!
//! Each node writes one key to Redis every heartbeat: its id, public URL, capacity, load,
//! whether it is draining, and the summaries of its matches. The key expires `ttl` after
//! it was written, so a node that dies drops out of the directory by itself; one task per
//! node does all the Redis traffic ([`directory`]) and keeps a [`View`] of the other nodes
//! that handlers read without waiting on anything. A node that loses Redis keeps serving
//! its own matches; after `ttl` without an answer it forgets the others (it cannot know
//! they are alive) and lists only its own.
//!
//! How long a dead node stays listed: its key lives at most `ttl` after its last heartbeat,
//! and each node reads the directory every `heartbeat`, so at most `ttl + heartbeat` after
//! it died (4 s with the defaults) plus one Redis round trip.

mod directory;
pub mod nodes;

pub use nodes::{Load, RemoteNode, Settings, View};

use std::collections::{HashMap, VecDeque};
use std::net::SocketAddr;
use std::sync::{Arc, Mutex, RwLock};
use std::time::{Duration, Instant};

use tokio::sync::{mpsc, oneshot};

use crate::game::Registry;
use crate::protocol::MatchSummary;
use crate::protocol::fleet::{Listed, NodeRef};

/// The defaults of the fleet's timing (seconds).
pub mod defaults {
    pub const HEARTBEAT: &str = "1";
    pub const TTL: &str = "3";
}

/// The flags of `lasertag serve` that put the server in a fleet.
#[derive(Debug, Clone, clap::Args)]
pub struct FleetArgs {
    /// Join the fleet whose directory is this Redis (`redis://host:6379/0`; the database
    /// number separates fleets sharing one Redis). Without it the server runs alone and
    /// never connects to Redis.
    #[arg(long = "fleet", value_name = "REDIS_URL", env = "LASERTAG_FLEET")]
    pub redis: Option<String>,
    /// This node's URL as other nodes' clients and browsers reach it (`https://n1.example`);
    /// default `http://<the address it listens on>`, which must then not be 0.0.0.0 or [::].
    #[arg(long, value_name = "URL", env = "LASERTAG_PUBLIC_URL")]
    pub public_url: Option<String>,
    /// This node's id in the fleet (letters, digits, `.`, `_`, `-`; at most 64); default the
    /// host's name and a random suffix. Two live nodes must not share one.
    #[arg(long, env = "LASERTAG_NODE_ID")]
    pub node_id: Option<String>,
    /// Seconds between two heartbeats (each writes this node's key and reads the others').
    #[arg(long = "fleet-heartbeat-s", value_name = "SECONDS", env = "LASERTAG_FLEET_HEARTBEAT_S",
          default_value = defaults::HEARTBEAT, value_parser = seconds)]
    pub heartbeat: Duration,
    /// Seconds a node's key lives after its last heartbeat: at least twice the heartbeat, so
    /// one late heartbeat does not drop a live node. A dead node leaves every lobby within
    /// this plus one heartbeat.
    #[arg(long = "fleet-ttl-s", value_name = "SECONDS", env = "LASERTAG_FLEET_TTL_S",
          default_value = defaults::TTL, value_parser = seconds)]
    pub ttl: Duration,
}

/// Why the fleet's settings were refused.
#[derive(Debug, thiserror::Error)]
pub enum FleetError {
    #[error("--fleet: {0}")]
    Redis(#[from] redis::RedisError),
    #[error("--public-url: {0:?} is not an http:// or https:// URL with a host and no path")]
    PublicUrl(String),
    #[error(
        "--public-url is needed: this node listens on {0}, which other nodes and browsers cannot reach"
    )]
    NoPublicUrl(SocketAddr),
    #[error("--node-id: {0:?} must be 1 to 64 letters, digits, '.', '_' or '-'")]
    NodeId(String),
    #[error(
        "--fleet-ttl-s ({ttl:?}) must be at least twice --fleet-heartbeat-s ({heartbeat:?}), which must be at least 0.05 s"
    )]
    Timing { heartbeat: Duration, ttl: Duration },
}

impl FleetArgs {
    /// The settings when `--fleet` is given (`listening` is the address the server got),
    /// and the Redis client (which does not connect yet).
    pub fn settings(
        &self,
        listening: SocketAddr,
    ) -> Result<Option<(Settings, redis::Client)>, FleetError> {
        let Some(url) = &self.redis else {
            return Ok(None);
        };
        let client = redis::Client::open(url.as_str())?;
        let public_url = match &self.public_url {
            Some(u) => public_url(u)?,
            None if listening.ip().is_unspecified() => {
                return Err(FleetError::NoPublicUrl(listening));
            }
            None => format!("http://{listening}"),
        };
        let node_id = match &self.node_id {
            Some(id) if valid_node_id(id) => id.clone(),
            Some(id) => return Err(FleetError::NodeId(id.clone())),
            None => default_node_id(),
        };
        if self.heartbeat < Duration::from_millis(50) || self.ttl < 2 * self.heartbeat {
            return Err(FleetError::Timing {
                heartbeat: self.heartbeat,
                ttl: self.ttl,
            });
        }
        let settings = Settings {
            node_id,
            public_url,
            heartbeat: self.heartbeat,
            ttl: self.ttl,
        };
        Ok(Some((settings, client)))
    }
}

fn seconds(s: &str) -> Result<Duration, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if !(v.is_finite() && (0.0..=3600.0).contains(&v)) {
        return Err(format!("{s}: must be between 0 and 3600 seconds"));
    }
    Ok(Duration::from_secs_f64(v))
}

/// `http(s)://host[:port]`, as a browser's origin: no path, query or user.
fn public_url(u: &str) -> Result<String, FleetError> {
    let trimmed = u.trim().trim_end_matches('/');
    let bad = || FleetError::PublicUrl(u.to_owned());
    let uri: axum::http::Uri = trimmed.parse().map_err(|_| bad())?;
    let scheme_ok = matches!(uri.scheme_str(), Some("http" | "https"));
    let authority = uri.authority().ok_or_else(bad)?;
    let plain = uri.path_and_query().is_none_or(|p| p.as_str() == "/")
        && !authority.as_str().contains('@')
        && !authority.host().is_empty();
    if !(scheme_ok && plain) {
        return Err(bad());
    }
    Ok(trimmed.to_owned())
}

fn valid_node_id(id: &str) -> bool {
    (1..=64).contains(&id.len())
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || matches!(b, b'.' | b'_' | b'-'))
}

/// The host's name (as the kernel has it) and a random suffix, so that two servers on one
/// host, or a restarted one whose old key has not expired, never share an id.
fn default_node_id() -> String {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .unwrap_or_default();
    let host: String = host
        .trim()
        .chars()
        .filter(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-'))
        .take(40)
        .collect();
    let suffix = crate::game::random_id(3);
    if host.is_empty() {
        format!("node-{suffix}")
    } else {
        format!("{host}-{suffix}")
    }
}

/// Where a new match goes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Placement {
    /// Here (this node's admission decides, as outside a fleet).
    Local,
    /// The other node with the most room.
    Remote(NodeRef),
}

/// Least-loaded with room: the node whose share of its capacity would be lowest with one
/// more match. Ties stay here (no redirect for nothing); a node that is full or draining
/// sends it to the best other one with room, or keeps it (and refuses it) when none has.
pub fn place<'a>(local: Load, others: impl IntoIterator<Item = (&'a NodeRef, Load)>) -> Placement {
    let best = others
        .into_iter()
        .filter(|(_, l)| l.has_room())
        .min_by(|(a, la), (b, lb)| {
            la.after_one()
                .total_cmp(&lb.after_one())
                .then_with(|| a.id.cmp(&b.id))
        });
    match best {
        Some((node, load)) if !local.has_room() || load.after_one() < local.after_one() => {
            Placement::Remote(node.clone())
        }
        _ => Placement::Local,
    }
}

/// The node whose queue every node's newcomers join: the one with the lowest id among
/// those not draining and with room for a match (this node included), so that people who
/// press *Play with others* on different nodes wait in one queue and meet. Every node reads
/// the same directory, so they agree within a heartbeat; a ticket already waiting stays with
/// the node that holds it, which goes on seating it. `None` when this node is that node.
pub fn queue_home<'a>(
    me: (&'a NodeRef, Load),
    others: impl IntoIterator<Item = (&'a NodeRef, Load)>,
) -> Option<NodeRef> {
    let home = std::iter::once(me)
        .chain(others)
        .filter(|(_, l)| l.has_room())
        .min_by(|(a, _), (b, _)| a.id.cmp(&b.id))
        .map(|(n, _)| n);
    home.filter(|n| n.id != me.0.id).cloned()
}

/// Matches this node sent to others (by node id, when) that their records did not show
/// at the last read of the directory.
#[derive(Debug, Default)]
struct Pending(HashMap<String, VecDeque<Instant>>);

impl Pending {
    fn count(&self, node: &str) -> usize {
        self.0.get(node).map_or(0, VecDeque::len)
    }

    fn add(&mut self, node: &str, at: Instant) {
        self.0.entry(node.to_owned()).or_default().push_back(at);
    }

    /// A new read of the directory: a node whose record holds k more matches than at the
    /// last read has had (at most) k of ours arrive, the oldest first; one sent longer ago
    /// than `lapse` was not followed or was refused; a node gone takes its own with it.
    fn reconcile(&mut self, old: &View, new: &View, now: Instant, lapse: Duration) {
        let held =
            |view: &View, id: &str| view.nodes.iter().find(|n| n.node.id == id).map(|n| n.held);
        self.0.retain(|id, sent| {
            let Some(held_now) = held(new, id) else {
                return false;
            };
            let arrived = held_now.saturating_sub(held(old, id).unwrap_or(held_now));
            for _ in 0..arrived.min(sent.len()) {
                sent.pop_front();
            }
            sent.retain(|at| now.saturating_duration_since(*at) < lapse);
            !sent.is_empty()
        });
    }
}

/// This node's part in the fleet, shared by the handlers and the directory task.
#[derive(Debug)]
pub struct Fleet {
    pub settings: Settings,
    registry: Arc<Registry>,
    view: RwLock<Arc<View>>,
    /// Matches sent to other nodes that their records do not show yet: counted in their
    /// load meanwhile, so that a burst of creations spreads over the fleet instead of all
    /// going to the node that looked emptiest a second ago.
    placed: Mutex<Pending>,
    /// Asks the directory task to leave the directory and end.
    leave: mpsc::Sender<oneshot::Sender<()>>,
}

impl Fleet {
    /// Starts the directory task (it connects, and reconnects, by itself: a Redis that is
    /// down does not keep the server from starting).
    pub fn start(settings: Settings, client: redis::Client, registry: Arc<Registry>) -> Arc<Fleet> {
        let (leave, leave_rx) = mpsc::channel(1);
        let fleet = Arc::new(Fleet {
            settings,
            registry,
            view: RwLock::default(),
            placed: Mutex::default(),
            leave,
        });
        fleet.registry.metrics.fleet_nodes.set(1);
        let publisher = fleet.clone();
        tokio::spawn(directory::run(
            fleet.settings.clone(),
            fleet.registry.clone(),
            Box::new(move |view| publisher.set_view(view)),
            client,
            leave_rx,
        ));
        fleet
    }

    /// This node, as listings show it.
    pub fn me(&self) -> NodeRef {
        NodeRef {
            id: self.settings.node_id.clone(),
            url: self.settings.public_url.clone(),
            local: true,
            draining: self.registry.draining.is_cancelled(),
        }
    }

    pub fn view(&self) -> Arc<View> {
        self.view.read().unwrap_or_else(|e| e.into_inner()).clone()
    }

    fn set_view(&self, view: View) {
        self.registry
            .metrics
            .fleet_nodes
            .set(1 + view.nodes.len() as i64);
        let old = self.view();
        self.placed
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .reconcile(&old, &view, Instant::now(), self.settings.ttl);
        *self.view.write().unwrap_or_else(|e| e.into_inner()) = Arc::new(view);
    }

    /// The node that hosts match `id`, when another node does.
    pub fn host_of(&self, id: &str) -> Option<NodeRef> {
        let view = self.view();
        view.hosts.get(id).map(|&i| view.nodes[i].node.clone())
    }

    /// This node's matches (`local`, oldest first) with their node, then every other
    /// node's as it wrote them, node by node.
    pub fn listing(&self, local: Vec<MatchSummary>) -> Vec<Listed> {
        let me = self.me();
        let mut out: Vec<Listed> = local
            .into_iter()
            .map(|mut s| {
                s.node = Some(me.clone());
                Listed::Local(Box::new(s))
            })
            .collect();
        let view = self.view();
        for n in &view.nodes {
            out.extend(
                n.matches
                    .iter()
                    .filter(|m| {
                        // A match this node holds is listed once, as its own.
                        m.get("id")
                            .and_then(|v| v.as_str())
                            .is_none_or(|id| self.registry.get(id).is_none())
                    })
                    .map(|m| Listed::remote(m.clone(), &n.node)),
            );
        }
        out
    }

    fn local_load(&self) -> Load {
        Load {
            held: self.registry.len(),
            capacity: self.registry.config.max_matches,
            draining: self.registry.draining.is_cancelled(),
        }
    }

    /// Where a new match should go; a remote choice is counted against that node until
    /// the next read of the directory.
    pub fn place(&self) -> Placement {
        let local = self.local_load();
        let view = self.view();
        let placement = {
            let placed = self.placed.lock().unwrap_or_else(|e| e.into_inner());
            place(
                local,
                view.nodes.iter().map(|n| {
                    let load = Load {
                        held: n.held + placed.count(&n.node.id),
                        ..n.load()
                    };
                    (&n.node, load)
                }),
            )
        };
        if let Placement::Remote(node) = &placement {
            self.placed
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .add(&node.id, Instant::now());
        }
        placement
    }

    /// The node whose queue a newcomer here joins ([`queue_home`]), when it is another.
    pub fn queue_home(&self) -> Option<NodeRef> {
        let me = self.me();
        let view = self.view();
        queue_home(
            (&me, self.local_load()),
            view.nodes.iter().map(|n| (&n.node, n.load())),
        )
    }

    /// Where this node's running matches go when it stops: the least loaded other node that
    /// is not draining, has room for them and takes matches over (its URL and its writer in
    /// the shared store); none when no node does (then they end here, as a lone node's do).
    pub fn hand_over_to(&self) -> Option<(String, String)> {
        let want = self.registry.len();
        let view = self.view();
        view.nodes
            .iter()
            .filter(|n| !n.node.draining && n.capacity.saturating_sub(n.held) >= want)
            .filter_map(|n| Some((n.held, n.node.url.clone(), n.writer.clone()?)))
            .min_by_key(|(held, _, _)| *held)
            .map(|(_, url, writer)| (url, writer))
    }

    /// Leaves the directory (this node's key is deleted at once, so the others drop it on
    /// their next read) and ends the directory task; gives up after `within`.
    pub async fn leave(&self, within: Duration) {
        let (tx, rx) = oneshot::channel();
        let asked = self.leave.send(tx).await.is_ok();
        if asked && tokio::time::timeout(within, rx).await.is_err() {
            tracing::warn!("fleet: could not leave the directory in time; the key will expire");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(id: &str) -> NodeRef {
        NodeRef {
            id: id.into(),
            url: format!("http://{id}"),
            local: false,
            draining: false,
        }
    }

    fn load(held: usize, capacity: usize) -> Load {
        Load {
            held,
            capacity,
            draining: false,
        }
    }

    #[test]
    fn a_new_match_goes_to_the_least_loaded_node_with_room() {
        let (b, c) = (node("b"), node("c"));
        // Equal: stays here.
        assert_eq!(place(load(1, 10), [(&b, load(1, 10))]), Placement::Local);
        assert_eq!(
            place(load(2, 10), [(&b, load(1, 10)), (&c, load(0, 10))]),
            Placement::Remote(c.clone())
        );
        // Shares of capacity, not counts: 3 of 100 is emptier than 1 of 10.
        assert_eq!(
            place(load(2, 10), [(&b, load(3, 100))]),
            Placement::Remote(b.clone())
        );
        // Full or draining nodes take nothing.
        let draining = Load {
            draining: true,
            ..load(0, 10)
        };
        assert_eq!(
            place(load(5, 10), [(&b, load(10, 10)), (&c, draining)]),
            Placement::Local
        );
        // A full or draining node sends it anywhere with room, even to a busier one.
        assert_eq!(
            place(load(10, 10), [(&b, load(9, 10))]),
            Placement::Remote(b.clone())
        );
        assert_eq!(place(draining, [(&b, load(9, 10))]), Placement::Remote(b));
        assert_eq!(place(load(10, 10), []), Placement::Local);
    }

    #[test]
    fn the_queue_lives_on_the_lowest_id_with_room() {
        let (a, b, c) = (node("a"), node("b"), node("c"));
        // The lowest id: here, or the other.
        assert_eq!(queue_home((&a, load(3, 10)), [(&b, load(0, 10))]), None);
        assert_eq!(
            queue_home((&c, load(0, 10)), [(&b, load(9, 10)), (&a, load(5, 10))]),
            Some(a.clone())
        );
        // A full or draining node holds no queue.
        let draining = Load {
            draining: true,
            ..load(0, 10)
        };
        assert_eq!(
            queue_home((&c, load(0, 10)), [(&a, draining), (&b, load(10, 10))]),
            None
        );
        // Nobody has room: here, which refuses as outside a fleet.
        assert_eq!(queue_home((&b, load(10, 10)), [(&a, draining)]), None);
    }

    #[test]
    fn a_placement_counts_until_the_nodes_record_shows_it() {
        let remote = |id: &str, held: usize| RemoteNode {
            node: node(id),
            capacity: 10,
            held,
            players: 0,
            spectators: 0,
            writer: None,
            matches: Vec::new(),
        };
        let t0 = Instant::now();
        let lapse = Duration::from_secs(3);
        let mut pending = Pending::default();
        for _ in 0..3 {
            pending.add("b", t0);
        }
        pending.add("c", t0);
        let old = View::new(vec![remote("b", 1), remote("c", 1)]);
        // b's record shows two of the three; c's none yet.
        let new = View::new(vec![remote("b", 3), remote("c", 1)]);
        pending.reconcile(&old, &new, t0 + Duration::from_secs(1), lapse);
        assert_eq!((pending.count("b"), pending.count("c")), (1, 1));
        // Past the lapse a placement that never arrived stops counting; a node gone takes
        // its own.
        let later = View::new(vec![remote("b", 3)]);
        pending.reconcile(&new, &later, t0 + lapse, lapse);
        assert_eq!((pending.count("b"), pending.count("c")), (0, 0));
    }

    #[test]
    fn settings_are_checked() {
        let addr: SocketAddr = "127.0.0.1:8080".parse().unwrap();
        let args = |redis: Option<&str>, url: Option<&str>, id: Option<&str>| FleetArgs {
            redis: redis.map(String::from),
            public_url: url.map(String::from),
            node_id: id.map(String::from),
            heartbeat: Duration::from_secs(1),
            ttl: Duration::from_secs(3),
        };
        assert!(args(None, None, None).settings(addr).unwrap().is_none());
        let (s, _) = args(Some("redis://127.0.0.1:6379/2"), None, Some("a-1"))
            .settings(addr)
            .unwrap()
            .unwrap();
        assert_eq!(s.public_url, "http://127.0.0.1:8080");
        assert_eq!(s.node_id, "a-1");
        let (s, _) = args(Some("redis://r"), Some("https://n1.example/"), None)
            .settings(addr)
            .unwrap()
            .unwrap();
        assert_eq!(s.public_url, "https://n1.example");
        assert!(valid_node_id(&s.node_id), "{}", s.node_id);
        for bad in ["n1.example", "ftp://n1", "http://n1/api", "http://u@n1"] {
            let e = args(Some("redis://r"), Some(bad), None).settings(addr);
            assert!(matches!(e, Err(FleetError::PublicUrl(_))), "{bad}: {e:?}");
        }
        let e = args(Some("redis://r"), None, Some("a b")).settings(addr);
        assert!(matches!(e, Err(FleetError::NodeId(_))), "{e:?}");
        let anywhere: SocketAddr = "0.0.0.0:8080".parse().unwrap();
        let e = args(Some("redis://r"), None, None).settings(anywhere);
        assert!(matches!(e, Err(FleetError::NoPublicUrl(_))), "{e:?}");
        let e = args(Some("not a url"), None, None).settings(addr);
        assert!(matches!(e, Err(FleetError::Redis(_))), "{e:?}");
        let mut fast = args(Some("redis://r"), None, None);
        fast.ttl = Duration::from_millis(1500);
        assert!(matches!(
            fast.settings(addr),
            Err(FleetError::Timing { .. })
        ));
    }
}
