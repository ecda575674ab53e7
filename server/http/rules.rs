//! `GET /api/rules`: the constants every match plays by and the requests' bounds
//! ([`Rules`]), for clients that draw or encode what the robots sense.

use axum::Json;

use crate::protocol::rules::Rules;

#[utoipa::path(get, path = "/api/rules",
    responses((status = 200, body = Rules,
        description = "The physical and sensor constants of every match, and the bounds of the requests' numbers")))]
pub async fn rules() -> Json<Rules> {
    Json(Rules::default())
}
