//! This node's fleet settings and the other nodes as the directory last read them: what
//! the directory task writes and the handlers read.

use std::collections::HashMap;
use std::time::Duration;

use crate::protocol::fleet::{NodeRef, RemoteSummary};

/// The fleet's settings, checked.
#[derive(Debug, Clone)]
pub struct Settings {
    pub node_id: String,
    /// Without a trailing slash.
    pub public_url: String,
    pub heartbeat: Duration,
    pub ttl: Duration,
}

/// Another node, as its last heartbeat described it.
#[derive(Debug, Clone)]
pub struct RemoteNode {
    pub node: NodeRef,
    pub capacity: usize,
    pub held: usize,
    pub players: usize,
    pub spectators: usize,
    /// Its writer in the shared store, when it adopts matches (`NodeRecord::writer`).
    pub writer: Option<String>,
    pub matches: Vec<RemoteSummary>,
}

/// A node's load, for placement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Load {
    pub held: usize,
    pub capacity: usize,
    pub draining: bool,
}

impl Load {
    pub(super) fn has_room(self) -> bool {
        !self.draining && self.held < self.capacity
    }

    /// The share of its capacity it would hold with one more match.
    pub(super) fn after_one(self) -> f64 {
        (self.held + 1) as f64 / self.capacity.max(1) as f64
    }
}

impl RemoteNode {
    /// Its load as its last heartbeat gave it.
    pub fn load(&self) -> Load {
        Load {
            held: self.held,
            capacity: self.capacity,
            draining: self.node.draining,
        }
    }
}

/// The other nodes of the fleet as of the last read of the directory.
#[derive(Debug, Default)]
pub struct View {
    /// By id.
    pub nodes: Vec<RemoteNode>,
    /// Match id → index in `nodes`.
    pub(super) hosts: HashMap<String, usize>,
}

impl View {
    pub fn new(mut nodes: Vec<RemoteNode>) -> View {
        nodes.sort_by(|a, b| a.node.id.cmp(&b.node.id));
        let mut hosts = HashMap::new();
        for (i, n) in nodes.iter().enumerate() {
            for m in &n.matches {
                if let Some(id) = m.get("id").and_then(|v| v.as_str()) {
                    hosts.entry(id.to_owned()).or_insert(i);
                }
            }
        }
        View { nodes, hosts }
    }
}
