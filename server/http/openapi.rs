//! The OpenAPI document of the API, generated from the handlers' annotations and the
//! protocol types, served at `GET /api/openapi.json`.

use axum::Json;
use utoipa::OpenApi;

use crate::http::handlers;
use crate::maps::MapFile;
use crate::protocol::*;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "lasertag",
        description = "Robots play laser tag against people: the HTTP API. Play and spectate over the WebSocket `GET /ws/matches/{id}` (`?token=` to play); its messages are described in the project's docs/api.md. Every endpoint may answer 429 (too many requests from one address, with Retry-After); the server's limits are its command-line settings (docs/operations.md)."
    ),
    paths(
        handlers::health,
        crate::http::rules::rules,
        crate::http::rules::difficulties,
        crate::http::transport::transport,
        handlers::list_maps,
        handlers::get_map,
        handlers::add_map,
        handlers::delete_map,
        crate::http::policies::list_policies,
        crate::http::policies::add_policy,
        crate::http::policies::delete_policy,
        handlers::list_matches,
        handlers::create_match,
        handlers::get_match,
        handlers::delete_match,
        handlers::step,
        crate::http::belief::belief,
        handlers::events,
        handlers::command,
        crate::http::robots::command,
        crate::http::robots::observation,
        crate::http::robots::act,
        crate::http::replays::list,
        crate::http::replays::detail,
        crate::http::replays::state_at,
        crate::http::replays::belief_at,
        crate::http::export::export,
        crate::http::players::player,
        crate::http::players::leaderboard,
        crate::http::names::claim,
        crate::http::names::release,
        crate::http::parties::create,
        crate::http::parties::get,
        crate::http::parties::join,
        crate::http::parties::change,
        crate::http::parties::remove,
        crate::http::parties::start,
        crate::http::parties::invite,
        crate::http::queue::enter,
        crate::http::queue::leave,
        handlers::join,
        handlers::join_showcase,
        handlers::stats,
        crate::http::handlers::metrics,
    ),
    components(schemas(
        ErrorBody,
        Health,
        crate::http::transport::TransportReply,
        crate::http::transport::WebTransportAt,
        crate::http::transport::CertificateHash,
        rules::Rules,
        crate::protocol::difficulties::DifficultyDto,
        crate::protocol::difficulties::MeasuredDto,
        crate::protocol::DifficultyName,
        rules::Motion,
        rules::Laser,
        rules::Detection,
        rules::Tag,
        rules::Landmarks,
        rules::RequestBounds,
        rules::BoundDto,
        MapInfo,
        MapCreated,
        crate::protocol::PolicyInfo,
        crate::protocol::PolicyCreated,
        MapFile,
        CreateMatch,
        MatchSummary,
        MatchCreated,
        MatchState,
        RobotState,
        OpponentState,
        PoseDto,
        DetectionDto,
        Belief,
        Role,
        Events,
        EventDto,
        StepRequest,
        OpponentCommand,
        robots::RobotCommand,
        robots::ActRequest,
        robots::ActResponse,
        robots::Observation,
        robots::LandmarkDto,
        robots::TeammateDto,
        robots::BeliefFeaturesDto,
        replays::ReplayListed,
        replays::ReplayDetail,
        replays::PlayerTotals,
        replays::RatingDto,
        replays::PlayedMatch,
        replays::PlayerDetail,
        replays::Leaderboard,
        JoinRequest,
        crate::protocol::ClaimRequest,
        crate::protocol::NameKept,
        crate::protocol::JoinTeam,
        Joined,
        ShowcaseJoinRequest,
        ShowcaseSeat,
        crate::protocol::parties::NameRequest,
        crate::protocol::parties::PartyCreated,
        crate::protocol::parties::PartyJoined,
        crate::protocol::parties::PartyDto,
        crate::protocol::parties::MemberDto,
        crate::protocol::parties::PartySettingsDto,
        crate::protocol::parties::PartyStatus,
        crate::protocol::parties::Side,
        crate::protocol::parties::MemberPatch,
        crate::protocol::parties::SettingsPatch,
        crate::protocol::parties::PartyStarted,
        crate::protocol::parties::QueueTicket,
        MatchStats,
        fleet::NodeRef,
        fleet::Elsewhere,
        fleet::Place
    )),
    modifiers(&OwnerToken)
)]
pub struct ApiDoc;

/// The bearer scheme of `owner_token` (and the operator's admin token).
struct OwnerToken;

impl utoipa::Modify for OwnerToken {
    fn modify(&self, doc: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
        let components = doc.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "owner_token",
            SecurityScheme::Http(
                HttpBuilder::new()
                    .scheme(HttpAuthScheme::Bearer)
                    .description(Some(
                        "The owner_token of POST /api/matches or POST /api/maps, or the server's admin token",
                    ))
                    .build(),
            ),
        );
    }
}

pub async fn document() -> Json<serde_json::Value> {
    static DOC: std::sync::OnceLock<serde_json::Value> = std::sync::OnceLock::new();
    Json(DOC.get_or_init(json).clone())
}

/// The document as JSON. utoipa 5 writes the fields of a response link in snake case
/// (`operation_id`); OpenAPI spells them in camel case (`operationId`), and tools such as
/// schemathesis follow links only when they are spelt right. (utoipa 6 fixes it.)
pub fn json() -> serde_json::Value {
    let mut doc = serde_json::to_value(ApiDoc::openapi()).unwrap_or_default();
    let operations = doc
        .get_mut("paths")
        .and_then(|p| p.as_object_mut())
        .into_iter()
        .flat_map(|paths| paths.iter_mut())
        .filter_map(|(name, path)| Some((name.clone(), path.as_object_mut()?)))
        .flat_map(|(name, path)| path.values_mut().map(move |op| (name.clone(), op)));
    for (path, op) in operations {
        if let Some(responses) = op.get_mut("responses").and_then(|r| r.as_object_mut()) {
            redirect_in_fleet(&path, responses);
        }
        let responses = op
            .get_mut("responses")
            .and_then(|r| r.as_object_mut())
            .into_iter()
            .flat_map(|r| r.values_mut());
        for response in responses {
            let links = response
                .get_mut("links")
                .and_then(|l| l.as_object_mut())
                .into_iter()
                .flat_map(|l| l.values_mut())
                .filter_map(|l| l.as_object_mut());
            for link in links {
                for (snake, camel) in [
                    ("operation_id", "operationId"),
                    ("operation_ref", "operationRef"),
                    ("request_body", "requestBody"),
                ] {
                    if let Some(v) = link.remove(snake) {
                        link.insert(camel.to_string(), v);
                    }
                }
            }
        }
    }
    doc
}

/// In a fleet every request for one match may be answered 307 (the match is on another
/// node), as may `POST /api/matches` (another node has more room): one place says so for
/// all of them, with the `Location` header.
fn redirect_in_fleet(path: &str, responses: &mut serde_json::Map<String, serde_json::Value>) {
    let for_one_match = path.starts_with("/api/matches/{id}");
    if !for_one_match && !responses.contains_key("307") {
        return;
    }
    let description = responses
        .get("307")
        .and_then(|r| r["description"].as_str())
        .unwrap_or("in a fleet (`--fleet`): another node hosts the match; the same request to `Location` reaches it")
        .to_owned();
    responses.insert(
        "307".into(),
        serde_json::json!({
            "description": description,
            "headers": {"Location": {
                "description": "the same request's URL on the node to ask",
                "schema": {"type": "string"}
            }},
            "content": {"application/json": {"schema": {"$ref": "#/components/schemas/Elsewhere"}}}
        }),
    );
}

#[cfg(test)]
mod tests {
    #[test]
    fn response_links_are_spelt_as_openapi_spells_them() {
        let doc = super::json();
        let link = &doc["paths"]["/api/matches"]["post"]["responses"]["201"]["links"]["GetMatch"];
        assert_eq!(link["operationId"], "get_match", "{link}");
        assert!(link.get("operation_id").is_none(), "{link}");
        assert_eq!(link["parameters"]["id"], "$response.body#/id");
    }
}
