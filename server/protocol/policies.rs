//! Trained robot teams on the wire (`/api/policies`).

use serde::Serialize;
use utoipa::ToSchema;

/// A trained policy the server holds (`GET /api/policies`).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct PolicyInfo {
    pub name: String,
    /// Floats of the robot observation it takes (docs/research.md, "Observations").
    pub observation_size: usize,
    /// Floats of the action it gives (forward, turn, tag).
    pub action_size: usize,
    /// Microseconds of one inference on this server, timed when it was loaded.
    pub inference_us: f64,
    /// Ticks between its decisions (`?decide_every=` at upload; 2 for the shipped team).
    pub decide_every: u64,
    /// Shipped with the server (listed from the start, never removed).
    pub shipped: bool,
}

/// The reply to `POST /api/policies`: the policy and the secret that removes it (shown only
/// here).
#[derive(Debug, Serialize, ToSchema)]
pub struct PolicyCreated {
    #[serde(flatten)]
    pub policy: PolicyInfo,
    /// `Authorization: Bearer <owner_token>` deletes the policy.
    pub owner_token: String,
}
