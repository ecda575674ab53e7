//! Parties and the queue on the wire (`/api/parties`, `/ws/parties/{code}`, `/api/queue`,
//! `/ws/queue/{ticket}`; docs/api.md "Playing together").

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::game::party::{self, RoomView};
use crate::game::view::Team;
use crate::protocol::DifficultyName;
use crate::protocol::socket::to_json;

/// Body of `POST /api/parties`, `POST /api/parties/{code}/members` and `POST /api/queue`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NameRequest {
    /// As in a join (`JoinRequest::name`).
    #[schema(min_length = 1, max_length = 64)]
    pub name: String,
    /// As in a join (`JoinRequest::name_token`).
    pub name_token: Option<String>,
}

/// Answer of `POST /api/parties`: the caller hosts it.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct PartyCreated {
    /// 6 characters of `ABCDEFGHJKMNPQRSTUVWXYZ23456789`.
    pub code: String,
    /// The page's address that joins it (`/#/party/<code>`).
    pub invite_url: String,
    pub member_id: String,
    /// `Authorization: Bearer <member_token>` changes this member; `?token=` opens the
    /// room's socket. Secret, shown once.
    pub member_token: String,
}

/// Answer of `POST /api/parties/{code}/members`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct PartyJoined {
    pub member_id: String,
    pub member_token: String,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    /// The hunted.
    Opponents,
    /// A robot of the robots' team (a versus match).
    Robots,
}

impl Side {
    pub fn team(self) -> Team {
        match self {
            Side::Opponents => Team::Opponents,
            Side::Robots => Team::Robots,
        }
    }

    pub fn of(team: Team) -> Side {
        match team {
            Team::Opponents => Side::Opponents,
            Team::Robots => Side::Robots,
        }
    }
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct MemberDto {
    pub id: String,
    pub name: String,
    pub side: Side,
    pub ready: bool,
    /// Whether the room's page of this member is open now.
    pub connected: bool,
    /// Whether they showed the kept name's token (the match counts for the name).
    pub kept: bool,
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct PartySettingsDto {
    pub map: String,
    pub difficulty: DifficultyName,
    /// 1 to 10.
    #[schema(minimum = 1, maximum = 10)]
    pub minutes: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum PartyStatus {
    Waiting,
    Playing,
}

/// `GET /api/parties/{code}`, and every `party` message of the room's socket.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct PartyDto {
    pub code: String,
    pub status: PartyStatus,
    /// The host's member id.
    pub host: String,
    pub members: Vec<MemberDto>,
    pub settings: PartySettingsDto,
    /// The match the party plays, while it plays.
    pub match_id: Option<String>,
    /// Whether the match the host would start now counts for ratings: never with more
    /// than one person (docs/ratings.md, "Playing together").
    pub rated: bool,
}

pub fn party(view: &RoomView) -> PartyDto {
    let p = &view.party;
    PartyDto {
        code: p.code.clone(),
        status: if p.match_id.is_some() {
            PartyStatus::Playing
        } else {
            PartyStatus::Waiting
        },
        host: p.host.clone(),
        members: p
            .members
            .iter()
            .map(|m| MemberDto {
                id: m.id.clone(),
                name: m.name.name.as_str().to_string(),
                side: Side::of(m.side),
                ready: m.ready,
                connected: view.connected.contains(&m.id),
                kept: m.name.claimed,
            })
            .collect(),
        settings: PartySettingsDto {
            map: p.settings.map.clone(),
            difficulty: DifficultyName::of(p.settings.difficulty),
            minutes: p.settings.minutes,
        },
        match_id: p.match_id.clone(),
        rated: p.rated(),
    }
}

/// Body of `PATCH /api/parties/{code}/members/{member_id}`.
#[derive(Debug, Clone, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MemberPatch {
    /// The member's own.
    pub ready: Option<bool>,
    /// The member's own, or anyone's with the host's token.
    pub side: Option<Side>,
    /// The host's only.
    pub settings: Option<SettingsPatch>,
}

#[derive(Debug, Clone, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SettingsPatch {
    /// A map of `GET /api/maps`.
    pub map: Option<String>,
    pub difficulty: Option<DifficultyName>,
    /// 1 to 10.
    #[schema(minimum = 1, maximum = 10)]
    pub minutes: Option<u32>,
}

impl MemberPatch {
    pub fn change(self) -> party::Change {
        let s = self.settings.unwrap_or_default();
        party::Change {
            ready: self.ready,
            side: self.side.map(Side::team),
            map: s.map,
            difficulty: s.difficulty.map(DifficultyName::kind),
            minutes: s.minutes,
        }
    }
}

/// Answer of `POST /api/parties/{code}/start`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct PartyStarted {
    pub match_id: String,
}

#[derive(Serialize)]
struct PartyMessage<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    #[serde(flatten)]
    party: &'a PartyDto,
}

/// The room's socket's `party` message.
pub fn party_message(view: &RoomView) -> String {
    to_json(&PartyMessage {
        kind: "party",
        party: &party(view),
    })
}

#[derive(Serialize)]
struct SeatMessage<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    match_id: &'a str,
    token: &'a str,
    team: Side,
}

/// A socket's `start` message (a party's) or `matched` (the queue's): the seat in
/// `match_id` that `token` plays.
pub fn seat_message(kind: &'static str, match_id: &str, token: &str, team: Team) -> String {
    to_json(&SeatMessage {
        kind,
        match_id,
        token,
        team: Side::of(team),
    })
}

/// Answer of `POST /api/queue`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct QueueTicket {
    pub ticket: String,
    /// `?token=` opens `/ws/queue/{ticket}`; `Authorization: Bearer` leaves the queue.
    pub token: String,
}

#[derive(Serialize)]
struct Waiting {
    #[serde(rename = "type")]
    kind: &'static str,
    seconds: u64,
    people: usize,
}

/// The queue's socket's `waiting` message.
pub fn waiting_message(seconds: u64, people: usize) -> String {
    to_json(&Waiting {
        kind: "waiting",
        seconds,
        people,
    })
}

/// The match a party's host starts: the host's map and robot team, an opponent slot for
/// each person on the opponents' side (a bot that runs from the robots when nobody is
/// there), and a robot of the team for each person on the robots' side (the team grows to
/// seat them). `time_limit_s` is left to the preset when `None`.
pub fn party_match(
    settings: &party::PartySettings,
    opponents: usize,
    hunters: usize,
    time_limit_s: Option<f64>,
) -> Result<crate::protocol::CreateMatch, crate::protocol::Invalid> {
    let preset = settings.difficulty.preset();
    let mut body = serde_json::json!({
        "map": settings.map,
        "difficulty": DifficultyName::of(settings.difficulty),
    });
    if opponents > 0 {
        body["opponents"] = opponents.into();
        body["opponent_control"] = "human".into();
    } else {
        body["opponents"] = 1.into();
        body["opponent_control"] = "bot".into();
        body["opponent_bot"] = "evade".into();
    }
    if hunters > 0 {
        body["pursuer_slots"] = hunters.into();
        body["robots"] = preset.robots.max(hunters).into();
    }
    if let Some(t) = time_limit_s {
        body["time_limit_s"] = t.into();
    }
    crate::protocol::deserialize_at(body, "party")
}

/// The map queue matches are played on: one the presets were measured on, so that the robot
/// team of the group's level is the team its rating says.
const QUEUE_MAP: &str = "office";

/// A queue group's match: `seats` opponents, bots that run from the robots until people take
/// them (the queue seats its people at once; a seat nobody takes stays a bot), against
/// `difficulty` for the preset's length.
pub fn queue_match(
    difficulty: lasertag_core::difficulty::Difficulty,
    seats: usize,
) -> Result<crate::protocol::CreateMatch, crate::protocol::Invalid> {
    let body = serde_json::json!({
        "map": lasertag_core::difficulty::Difficulty::MEASURED_ON.first().copied().unwrap_or(QUEUE_MAP),
        "difficulty": DifficultyName::of(difficulty),
        "opponents": seats,
        "opponent_control": "bot",
        "opponent_bot": "evade",
        "bots_joinable": true,
    });
    crate::protocol::deserialize_at(body, "queue")
}

/// The queue's socket's `gone` message: the ticket left or could not be seated.
pub fn gone_message(why: &str) -> String {
    #[derive(Serialize)]
    struct Gone<'a> {
        #[serde(rename = "type")]
        kind: &'static str,
        error: &'a str,
    }
    to_json(&Gone {
        kind: "error",
        error: why,
    })
}
