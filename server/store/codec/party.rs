//! A party's room as the store keeps it (`backend::KeptParty`'s document): plain fields the
//! game fills in and reads back, as JSON, with every token as its SHA-256 hash.

use serde::{Deserialize, Serialize};

/// A room: who is in, on which side, ready or not, and what the host chose.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PartyRecord {
    pub code: String,
    /// The host's member id.
    pub host: String,
    pub map: String,
    /// A difficulty preset's wire name.
    pub difficulty: String,
    pub minutes: u32,
    pub members: Vec<MemberRecord>,
    /// The match the party plays, while it plays one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub match_id: Option<String>,
    /// Unix milliseconds of the last time somebody was connected to the room (a party
    /// nobody is connected to lapses).
    pub seen_ms: i64,
}

#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MemberRecord {
    pub id: String,
    pub name: String,
    /// Whether they showed the name's claim token (the match counts for the kept name).
    pub kept: bool,
    /// `opponents` or `robots`.
    pub side: String,
    pub ready: bool,
    /// The member token's SHA-256, hex.
    pub token: String,
    /// The address they joined from (`access::ClientKey`).
    pub client: String,
}

impl PartyRecord {
    pub fn to_doc(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }

    /// The room in `doc`, or what is wrong with it.
    pub fn from_doc(doc: &str) -> Result<PartyRecord, String> {
        serde_json::from_str(doc).map_err(|e| format!("stored party: {e}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_room_reads_back_as_kept_and_a_broken_one_says_so() {
        let room = PartyRecord {
            code: "ABC234".into(),
            host: "m1".into(),
            map: "office".into(),
            difficulty: "elite".into(),
            minutes: 3,
            members: vec![MemberRecord {
                id: "m1".into(),
                name: "alice".into(),
                kept: true,
                side: "robots".into(),
                ready: false,
                token: "ab".repeat(32),
                client: "127.0.0.1".into(),
            }],
            match_id: Some("m-1".into()),
            seen_ms: 1_700_000_000_000,
        };
        assert_eq!(PartyRecord::from_doc(&room.to_doc()).unwrap(), room);
        let broken = PartyRecord::from_doc("{\"code\": 3}").unwrap_err();
        assert!(broken.contains("stored party"), "{broken}");
    }
}
