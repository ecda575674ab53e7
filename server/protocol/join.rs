//! `POST /api/matches/{id}/players`: a person asks for a seat on either team, and is told
//! which body they play and the secret that drives it.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use lasertag_core::sim::AgentId;

/// Body of `POST /api/names`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ClaimRequest {
    /// The name to keep: the rules of a join's name; a look-alike of a kept name is taken.
    #[schema(min_length = 1, max_length = 64)]
    pub name: String,
}

/// Answer of `POST /api/names`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct NameKept {
    /// The name as kept (normalised).
    pub name: String,
    /// The claim's secret, shown once: joins under the name need it, and so does giving
    /// the name up (`DELETE /api/names/{name}`, `Authorization: Bearer <name_token>`).
    pub name_token: String,
}

/// Body of `POST /api/matches/{id}/players`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JoinRequest {
    /// 1 to 24 characters once normalised (NFKC, outer spaces trimmed, runs of spaces made
    /// one): letters and digits of the world's scripts, ASCII punctuation and spaces; no
    /// control, bidirectional, invisible or tag characters, no line separators, no symbols
    /// or emoji (docs/api.md, "Names").
    #[schema(min_length = 1, max_length = 64)]
    pub name: String,
    /// `opponents` (default: a free opponent slot, the hunted) or `robots` (a free pursuer
    /// slot: a robot of the team, hunting beside the others).
    pub team: Option<JoinTeam>,
    /// The token of the name's claim (`POST /api/names`): needed to join under a name
    /// somebody keeps, and what makes the match count for the name's statistics and rating.
    pub name_token: Option<String>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum JoinTeam {
    Opponents,
    Robots,
}

impl JoinTeam {
    pub fn team(team: Option<JoinTeam>) -> crate::game::view::Team {
        match team {
            None | Some(JoinTeam::Opponents) => crate::game::view::Team::Opponents,
            Some(JoinTeam::Robots) => crate::game::view::Team::Robots,
        }
    }
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Joined {
    pub player_id: String,
    /// The opponent taken (`o0`, …), for a seat on the opponents' side ...
    #[serde(skip_serializing_if = "Option::is_none")]
    pub opponent_id: Option<String>,
    /// ... or the robot (`r1`, …), for a pursuer slot.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub robot_id: Option<String>,
    pub token: String,
}

impl From<crate::game::view::Joined> for Joined {
    fn from(j: crate::game::view::Joined) -> Self {
        let id = Some(j.body.to_string());
        let robot = matches!(j.body, AgentId::Robot(_));
        Joined {
            player_id: j.player_id,
            opponent_id: if robot { None } else { id.clone() },
            robot_id: if robot { id } else { None },
            token: j.token,
        }
    }
}

/// Body of `POST /api/showcase/players`: a name, as for any join (the seat is always an
/// opponent: showcases have no pursuer slots).
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ShowcaseJoinRequest {
    /// As in a join (`JoinRequest::name`).
    #[schema(min_length = 1, max_length = 64)]
    pub name: String,
    /// As in a join (`JoinRequest::name_token`).
    pub name_token: Option<String>,
}

/// Answer of `POST /api/showcase/players`: the showcase the seat is in, and the seat.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ShowcaseSeat {
    pub match_id: String,
    #[serde(flatten)]
    pub seat: Joined,
}
