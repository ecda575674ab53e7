//! A party's room as plain data: who is in it, on which side, ready or not, what the host
//! chose, and the code that names it.

use std::time::{Duration, SystemTime};

use crate::access::{ClientKey, SecretHash, random_id};
use crate::game::view::Team;
use crate::names::{JoinName, Name};
use crate::store::codec::{MemberRecord, PartyRecord};
use crate::store::unix_ms;
use lasertag_core::difficulty::Difficulty;

/// The letters a code is made of: no look-alikes (0/O, 1/I/L), so that a code read aloud or
/// off a screen is typed right the first time.
pub const CODE_ALPHABET: &[u8] = b"ABCDEFGHJKMNPQRSTUVWXYZ23456789";
/// Characters in a code: 31^6, almost 900 million codes, against a guesser held to
/// `Config::party_misses_per_minute`.
pub const CODE_LEN: usize = 6;
/// People in one room (the hunted and the hunters together).
pub const MAX_MEMBERS: usize = 8;
/// How long a room nobody is connected to stays.
pub const LAPSE: Duration = Duration::from_secs(10 * 60);
/// Minutes a party's match may last.
pub const MINUTES: std::ops::RangeInclusive<u32> = 1..=10;

/// What the host chose.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PartySettings {
    pub map: String,
    pub difficulty: Difficulty,
    pub minutes: u32,
}

/// One person in a room.
#[derive(Debug, Clone)]
pub struct Member {
    pub id: String,
    pub name: JoinName,
    pub side: Team,
    pub ready: bool,
    token: SecretHash,
    pub client: ClientKey,
}

/// A room as everyone may read it.
#[derive(Debug, Clone)]
pub struct Party {
    pub code: String,
    /// The host's member id.
    pub host: String,
    pub members: Vec<Member>,
    pub settings: PartySettings,
    /// The match the party plays, while it plays.
    pub match_id: Option<String>,
}

impl Party {
    pub fn member(&self, id: &str) -> Option<&Member> {
        self.members.iter().find(|m| m.id == id)
    }

    /// The id of the member `token` belongs to.
    pub fn holder(&self, token: &str) -> Option<&str> {
        self.members
            .iter()
            .find(|m| m.token.matches(token))
            .map(|m| m.id.as_str())
    }

    /// Whether the match the host would start now counts for ratings: one person against
    /// a preset exactly as it was measured (docs/ratings.md), which a party of more than
    /// one person never is.
    pub fn rated(&self) -> bool {
        self.members.len() == 1
            && self.members[0].side == Team::Opponents
            && self.plays_the_preset_length()
    }

    /// Whether the host kept the robot team's own match length.
    pub fn plays_the_preset_length(&self) -> bool {
        u64::from(self.settings.minutes) * 60 == self.settings.difficulty.preset().time_limit_s
    }

    pub(super) fn record(&self, seen: SystemTime) -> PartyRecord {
        PartyRecord {
            code: self.code.clone(),
            host: self.host.clone(),
            map: self.settings.map.clone(),
            difficulty: self.settings.difficulty.name().to_string(),
            minutes: self.settings.minutes,
            members: self
                .members
                .iter()
                .map(|m| MemberRecord {
                    id: m.id.clone(),
                    name: m.name.name.as_str().to_string(),
                    kept: m.name.claimed,
                    side: side_name(m.side).to_string(),
                    ready: m.ready,
                    token: m.token.to_hex(),
                    client: m.client.to_string(),
                })
                .collect(),
            match_id: self.match_id.clone(),
            seen_ms: unix_ms(seen),
        }
    }

    pub(super) fn from_record(r: PartyRecord) -> Option<Party> {
        let members = r
            .members
            .into_iter()
            .map(|m| {
                Some(Member {
                    name: JoinName {
                        name: Name::parse(&m.name).ok()?,
                        claimed: m.kept,
                    },
                    side: side_of(&m.side)?,
                    ready: m.ready,
                    token: SecretHash::from_hex(&m.token)?,
                    client: ClientKey::parse(&m.client)?,
                    id: m.id,
                })
            })
            .collect::<Option<Vec<_>>>()?;
        Some(Party {
            code: r.code,
            host: r.host,
            members,
            settings: PartySettings {
                map: r.map,
                difficulty: Difficulty::parse(&r.difficulty)?,
                minutes: r.minutes.clamp(*MINUTES.start(), *MINUTES.end()),
            },
            match_id: r.match_id,
        })
    }
}

pub fn side_name(side: Team) -> &'static str {
    match side {
        Team::Opponents => "opponents",
        Team::Robots => "robots",
    }
}

pub fn side_of(name: &str) -> Option<Team> {
    match name {
        "opponents" => Some(Team::Opponents),
        "robots" => Some(Team::Robots),
        _ => None,
    }
}

/// A fresh code.
pub(super) fn random_code() -> String {
    let mut bytes = [0u8; CODE_LEN];
    if getrandom::fill(&mut bytes).is_err() {
        panic!("the operating system's random number generator failed");
    }
    // 256 is not a multiple of 31: drawing by modulo favours the first 8 letters by a
    // fraction of a percent, which costs a guesser nothing worth having.
    bytes
        .iter()
        .map(|b| CODE_ALPHABET[*b as usize % CODE_ALPHABET.len()] as char)
        .collect()
}

/// A code as typed: upper-cased, spaces and dashes dropped; `None` when it cannot be one.
pub fn normalise_code(typed: &str) -> Option<String> {
    let code: String = typed
        .chars()
        .filter(|c| !matches!(c, ' ' | '-'))
        .map(|c| c.to_ascii_uppercase())
        .collect();
    (code.len() == CODE_LEN && code.bytes().all(|b| CODE_ALPHABET.contains(&b))).then_some(code)
}

pub(super) fn new_member(name: JoinName, client: ClientKey, side: Team) -> (Member, String) {
    let token = random_id(16);
    let member = Member {
        id: format!("m{}", random_id(4)),
        name,
        side,
        ready: false,
        token: SecretHash::of(&token),
        client,
    };
    (member, token)
}
