//! What resumes a running match besides its settings and inputs (`game::resume`), as the
//! store keeps it.

use serde::{Deserialize, Serialize};

/// What a running match holds besides its settings and inputs that a server resuming it
/// needs (`game::resume`): who owns it and who sits in its seats, their tokens as hashes
/// only (`access::SecretHash`), so that a copied database lets nobody in.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StoredLive {
    /// The owner token's hash (hex); none for the server's own matches.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub owner: Option<String>,
    /// The client that made it (its per-client quotas follow it), as an address.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub client: Option<String>,
    /// Whether the owner token reads the match live (`Owner::reads_live`).
    #[serde(default)]
    pub reads_live: bool,
    /// The seats people hold now.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub seats: Vec<StoredSeat>,
    /// Ticks it ran at once when it started (the showcase's head start), for its viewers.
    #[serde(default, skip_serializing_if = "is_zero_u64")]
    pub head_start_ticks: u64,
    /// Everyone who has played it so far, by name (what their result counts for).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub people: Vec<StoredPerson>,
}

/// A name that has played a running match (`game::task::people`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StoredPerson {
    pub name: String,
    /// Whether they showed the name's token.
    #[serde(default)]
    pub claimed: bool,
    /// Whether they have played enough for their result to rate.
    #[serde(default)]
    pub played: bool,
}

fn is_zero_u64(n: &u64) -> bool {
    *n == 0
}

/// A person's seat in a running match.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StoredSeat {
    /// The seat's number (`MatchTask::bodies`: opponent slots, then pursuer robots).
    pub seat: usize,
    pub player_id: String,
    pub name: String,
    /// The seat token's hash (hex).
    pub token: String,
    /// The address that joined (for its per-client seat counts).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub client: Option<String>,
}

impl StoredLive {
    /// The stored form, JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_else(|_| "{}".into())
    }

    pub fn from_json(json: &str) -> Result<StoredLive, serde_json::Error> {
        serde_json::from_str(json)
    }
}
