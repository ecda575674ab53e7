//! `GET /api/rules`: the constants every match plays by and the requests' bounds
//! ([`Rules`]), for clients that draw or encode what the robots sense; `GET
//! /api/difficulties`: the robot-team presets a person chooses from.

use axum::Json;

use crate::protocol::rules::Rules;

#[utoipa::path(get, path = "/api/rules",
    responses((status = 200, body = Rules,
        description = "The physical and sensor constants of every match, and the bounds of the requests' numbers")))]
pub async fn rules() -> Json<Rules> {
    Json(Rules::default())
}

#[utoipa::path(get, path = "/api/difficulties",
    responses((status = 200, body = Vec<crate::protocol::difficulties::DifficultyDto>,
        description = "The robot-team presets, from the easiest, with what each sets and how often its robots beat the built-in bots")))]
pub async fn difficulties() -> Json<Vec<crate::protocol::difficulties::DifficultyDto>> {
    Json(crate::protocol::difficulties::all())
}
