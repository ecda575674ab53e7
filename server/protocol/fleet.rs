//! The fleet's shapes: what a node writes to the directory in Redis each heartbeat
//! ([`NodeRecord`]), which node hosts a listed match ([`NodeRef`], the `node` field of a
//! summary), a listing that mixes this node's summaries with other nodes' ([`Listed`]), and
//! the body of a redirect to the hosting node ([`Elsewhere`]).
//!
//! Other nodes' summaries are relayed as the JSON objects they wrote, never re-parsed into
//! [`MatchSummary`]: a node running a newer version may add fields, and the lobby shows
//! them as that node wrote them.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::protocol::state::MatchSummary;
pub use crate::protocol::state::NodeRef;

/// The version of [`NodeRecord`]'s layout; a reader skips records of another version, so a
/// fleet can be upgraded one node at a time (old and new nodes ignore each other's matches
/// until all run the same version, and keep serving their own).
pub const RECORD_FORMAT: u32 = 1;

/// What a node writes to the directory each heartbeat (one key, expiring unless renewed).
/// `M` is a match summary: this node's own when written, a JSON object when read.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct NodeRecord<M> {
    /// [`RECORD_FORMAT`].
    pub format: u32,
    pub id: String,
    pub url: String,
    /// Matches it may hold (`--max-matches`).
    pub capacity: usize,
    /// Matches it holds now, finished ones included until they are removed.
    pub held: usize,
    pub players: usize,
    pub spectators: usize,
    pub draining: bool,
    /// Its writer's id in the fleet's shared store, when it takes matches over from other
    /// nodes (a draining node hands its matches to such a node).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub writer: Option<String>,
    pub matches: Vec<M>,
}

/// A summary of another node, as it wrote it: a JSON object with at least a string `id`.
pub type RemoteSummary = serde_json::Map<String, serde_json::Value>;

impl NodeRecord<RemoteSummary> {
    /// Reads a record another node wrote. `None` for another layout version or anything
    /// that is not one (a summary without an id is dropped, as is a `node` field it
    /// carries: the reader says which node hosts it).
    pub fn decode(bytes: &[u8]) -> Option<NodeRecord<RemoteSummary>> {
        let mut record: NodeRecord<RemoteSummary> = serde_json::from_slice(bytes).ok()?;
        if record.format != RECORD_FORMAT {
            return None;
        }
        record.matches.retain_mut(|m| {
            m.remove("node");
            m.get("id").is_some_and(|id| id.is_string())
        });
        Some(record)
    }
}

impl NodeRecord<&MatchSummary> {
    pub fn encode(&self) -> Vec<u8> {
        // Plain data with string keys: serialising it cannot fail.
        serde_json::to_vec(self).unwrap_or_default()
    }
}

/// A match in `GET /api/matches`: one of this node's, or another node's as it wrote it.
#[derive(Debug, Clone, Serialize)]
#[serde(untagged)]
pub enum Listed {
    Local(Box<MatchSummary>),
    Remote(RemoteSummary),
}

impl Listed {
    /// Another node's summary with the node that hosts it.
    pub fn remote(mut summary: RemoteSummary, node: &NodeRef) -> Listed {
        if let Ok(node) = serde_json::to_value(node) {
            summary.insert("node".into(), node);
        }
        Listed::Remote(summary)
    }
}

/// `POST /api/matches?place=…`: where the new match may go.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Place {
    /// The least-loaded node of the fleet with room (the default): this one, or a 307 to
    /// another.
    Fleet,
    /// This node, whatever the others hold (its own limits still apply).
    Local,
}

impl Place {
    pub fn parse(s: &str) -> Option<Place> {
        match s {
            "fleet" => Some(Place::Fleet),
            "local" => Some(Place::Local),
            _ => None,
        }
    }
}

/// The body of a 307 to the node that hosts a match (or that has room for a new one).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Elsewhere {
    /// What this is, for a person reading it.
    pub message: String,
    /// The node to ask.
    pub node: NodeRef,
    /// The same request's URL on that node (also the `Location` header).
    pub location: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_is_read_back_with_its_summaries_as_written() {
        let raw = br#"{"format":1,"id":"b","url":"http://b","capacity":10,"held":2,
            "players":1,"spectators":3,"draining":false,
            "matches":[{"id":"m1","map":"office","node":{"id":"x"},"new_field":7},{"map":"no id"}]}"#;
        let r = NodeRecord::decode(raw).expect("a record");
        assert_eq!((r.id.as_str(), r.capacity, r.held), ("b", 10, 2));
        assert_eq!(r.matches.len(), 1, "the summary without an id is dropped");
        assert_eq!(r.matches[0]["new_field"], 7, "unknown fields are relayed");
        assert!(!r.matches[0].contains_key("node"));
        let other = raw.to_vec();
        let other = String::from_utf8(other)
            .unwrap()
            .replace("\"format\":1", "\"format\":2");
        assert!(NodeRecord::decode(other.as_bytes()).is_none());
        assert!(NodeRecord::decode(b"not json").is_none());
    }

    #[test]
    fn a_remote_listing_names_its_node() {
        let mut s = RemoteSummary::new();
        s.insert("id".into(), "m1".into());
        let node = NodeRef {
            id: "b".into(),
            url: "http://b".into(),
            local: false,
            draining: true,
        };
        let v = serde_json::to_value(Listed::remote(s, &node)).unwrap();
        assert_eq!(v["node"]["url"], "http://b");
        assert_eq!(v["node"]["draining"], true);
        assert_eq!(v["id"], "m1");
    }
}
