//! `POST /api/matches/{id}/players`: a person asks for a seat on either team, and is told
//! which body they play and the secret that drives it.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use lasertag_core::sim::AgentId;

/// Body of `POST /api/matches/{id}/players`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct JoinRequest {
    /// 1 to 32 characters, none of them control characters, not all whitespace (leading
    /// and trailing whitespace is trimmed off).
    #[schema(
        min_length = 1,
        max_length = 32,
        pattern = r"^[^\u0000-\u001F\u007F-\u009F]*[^\s\u0000-\u001F\u007F-\u009F][^\u0000-\u001F\u007F-\u009F]*$"
    )]
    pub name: String,
    /// `opponents` (default: a free opponent slot, the hunted) or `robots` (a free pursuer
    /// slot: a robot of the team, hunting beside the others).
    pub team: Option<JoinTeam>,
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
