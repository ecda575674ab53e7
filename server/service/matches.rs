//! The matches' use cases: the lobby's listing and creating a match (placement in a fleet,
//! the per-match limits, the map, admission, the build on the blocking pool, the start).

use std::sync::Arc;

use crate::access::{ClientKey, Owner};
use crate::fleet::Placement;
use crate::game::admission::{self, NoRoom};
use crate::game::view::MatchMeta;
use crate::game::{MatchError, random_id};
use crate::maps::{self, MapError};
use crate::metrics::Refusal;
use crate::protocol::fleet::{Listed, NodeRef, Place};
use crate::protocol::{self, CreateMatch, Invalid, MatchCreated, MatchSummary};
use crate::service::admit::{OverLimit, within_request_limits};
use crate::service::{PoolError, Service};
use lasertag_core::sim::arena::{Arena, MapDef};
use lasertag_core::world::{SetupError, World};

/// Why a match was not created.
#[derive(Debug, thiserror::Error)]
pub enum CreateError {
    /// A field of the request is out of its bounds.
    #[error(transparent)]
    Invalid(#[from] Invalid),
    #[error(
        "robots + opponents: {robots} + {opponents} = {agents} agents is over this server's limit of {max} per match"
    )]
    TooManyAgents {
        robots: usize,
        opponents: usize,
        agents: usize,
        max: usize,
    },
    #[error(
        "tracker.particles_per_role: {per_role} per role × {opponents} opponents = {particles} particles is over this server's limit of {max} per match"
    )]
    TooManyParticles {
        per_role: usize,
        opponents: usize,
        particles: usize,
        max: usize,
    },
    /// `map` names no map the server holds.
    #[error("map: no map {0:?}")]
    NoMap(String),
    #[error("planner: no policy {0:?} on this server (GET /api/policies lists them)")]
    NoPolicy(String),
    #[error("planner: policy {name:?} cannot drive this team: {why}")]
    PolicyMisfit { name: String, why: String },
    /// The inline map breaks a rule (its path names the field as the request has it).
    #[error(transparent)]
    BadMap(MapError),
    #[error("map: must be a map name or a map object")]
    NotAMap,
    #[error(transparent)]
    OverLimit(#[from] OverLimit),
    /// The server's or the client's room or budgets are taken.
    #[error(transparent)]
    NoRoom(#[from] NoRoom),
    /// The settings and the map make no match (e.g. too few spawns).
    #[error(transparent)]
    Setup(#[from] SetupError),
    #[error(transparent)]
    Pool(#[from] PoolError),
    #[error(transparent)]
    Match(#[from] MatchError),
}

/// What came of a request to create a match.
#[derive(Debug)]
pub enum Created<R> {
    /// The match runs here.
    Here(Box<MatchCreated>),
    /// The fleet placed it on another node: what `elsewhere` made of that node.
    Elsewhere(R),
}

/// A person a party or the queue seats, and who could not be seated.
#[derive(Debug)]
pub struct Unseated {
    pub name: String,
    pub error: MatchError,
}

/// Seats everyone of `people` (a name and a side each) in match `id`, answering each seat's
/// token in order. The seats are priced by whoever gathered the people (a party, the queue),
/// not by each address's seat count, so friends behind one router play together. When one
/// cannot be seated the match is stopped and removed: nothing is left running.
pub async fn seat_all(
    service: Service<'_>,
    id: &str,
    people: Vec<(crate::names::JoinName, crate::game::view::Team)>,
) -> Result<Vec<String>, Unseated> {
    let Some(handle) = service.registry.get(id) else {
        return Err(Unseated {
            name: String::new(),
            error: MatchError::Gone(id.to_string()),
        });
    };
    let mut tokens = Vec::with_capacity(people.len());
    for (name, team) in people {
        match handle.join(name.clone(), team, None).await {
            Ok(joined) => tokens.push(joined.token),
            Err(error) => {
                handle
                    .stop(lasertag_core::world::FinishReason::Stopped)
                    .await;
                service.registry.remove(id).await;
                return Err(Unseated {
                    name: name.name.as_str().to_string(),
                    error,
                });
            }
        }
    }
    Ok(tokens)
}

/// The lobby: this server's matches and, in a fleet, every other node's from the fleet's
/// last read of the directory (never a wait on Redis). The secret seeds of this server's
/// matches show only where `opens` the match's owner (the caller holds its token or the
/// admin token).
pub fn list(service: Service<'_>, opens: impl Fn(&Owner) -> bool) -> Vec<Listed> {
    // Published summaries, not a question to each task: a match busy stepping thousands of
    // ticks must not hold up the lobby.
    let local: Vec<MatchSummary> = service
        .registry
        .all()
        .iter()
        .map(|h| {
            let summary = h.hub.summary.borrow();
            if opens(&h.owner) {
                protocol::owners_summary(&summary)
            } else {
                protocol::summary(&summary)
            }
        })
        .collect();
    match service.fleet {
        Some(fleet) => fleet.listing(local),
        None => local
            .into_iter()
            .map(|s| Listed::Local(Box::new(s)))
            .collect(),
    }
}

/// Creates the match `body` asks for, owned by `client` (`None`: the operator's, counted
/// against no address's quota). In a fleet with `place` [`Place::Fleet`], a node with more
/// room is offered to `elsewhere` first, before anything is checked or built (the node it
/// goes to checks it); when `elsewhere` makes nothing of it, the match is created here.
pub async fn create<R>(
    service: Service<'_>,
    client: Option<ClientKey>,
    place: Place,
    body: CreateMatch,
    elsewhere: impl FnOnce(NodeRef) -> Option<R>,
) -> Result<Created<R>, CreateError> {
    if let Some(fleet) = service.fleet
        && place == Place::Fleet
        && let Placement::Remote(node) = fleet.place()
        && let Some(moved) = elsewhere(node)
    {
        return Ok(Created::Elsewhere(moved));
    }
    let registry = service.registry;
    let mut req = body.validate()?;
    if req.people {
        // Secret until the match ends: nothing public lets a stranger rebuild it live.
        req.config.seed = crate::game::random_seed();
    }
    within_match_limits(service, &req.config)?;
    // Refused before anything is built; `try_start` checks again under the lock.
    registry.has_room(client)?;
    // Only on a map the server ships (a map of one's own could wall the robots off) and the
    // presets were measured on (their ratings say nothing of another).
    req.rated &= shipped(service, &req.map)
        && req
            .map
            .as_str()
            .is_some_and(|m| lasertag_core::difficulty::Difficulty::MEASURED_ON.contains(&m));
    let policy = policy_fits(service, &req.config)?;
    let source = map_source(service, req.map).await?;
    let def = match &source {
        MapSource::Stored(arena) => &arena.def,
        MapSource::Inline(def) => def,
    };
    let price = admission::held_back(&req.config, req.spectator_delay_ticks)
        + admission::match_on(def, &req.config)
        + policy.map_or_else(admission::Price::default, |(inference_us, every)| {
            admission::policy(def, &req.config, inference_us, every)
        })
        + match &source {
            MapSource::Stored(_) => admission::Price::default(),
            MapSource::Inline(def) => admission::map(def),
        };
    within_request_limits(registry, "the match", price)?;
    registry.has_budget(price, client)?;
    let config = req.config;
    let world = service
        .pool
        .run("setting up the match", move || {
            let arena = match source {
                MapSource::Stored(arena) => arena,
                MapSource::Inline(def) => Arc::new(Arena::new(def)),
            };
            World::new(arena, config)
        })
        .await??;
    let meta = MatchMeta {
        id: random_id(8),
        map: world.arena.def.name.clone(),
        clock: req.clock.into(),
        players: 0,
        spectators: 0,
        free_slots: 0,
        free_pursuer_slots: 0,
        bots_joinable: req.bots_joinable,
        spectator_delay_ticks: req.spectator_delay_ticks,
        head_start_ticks: 0,
        difficulty: req.difficulty,
        rated: req.rated,
    };
    let rated = req.rated;
    let (owner, owner_token) = Owner::new(client);
    let owner = Owner {
        reads_live: !rated,
        ..owner
    };
    let handle = registry.try_start(world, meta, owner, price)?;
    // Asked of the task so that fields it owns (free slots) are filled in.
    let mut summary = handle
        .read(crate::game::Sight::Live, protocol::read_summary)
        .await?;
    summary.node = service.fleet.map(|f| f.me());
    if rated {
        // Whoever made a rated match may be the person playing it.
        summary.seed = None;
    }
    Ok(Created::Here(Box::new(MatchCreated {
        summary,
        owner_token,
    })))
}

/// What the price of the trained policy that drives the team, if any, depends on: its
/// inference's microseconds and ticks between decisions. Refused when the server holds no
/// policy of that name or its sizes do not fit the team.
fn policy_fits(
    service: Service<'_>,
    config: &lasertag_core::world::MatchConfig,
) -> Result<Option<(f64, u64)>, CreateError> {
    let Some(name) = config.policy.as_deref() else {
        return Ok(None);
    };
    let store = service
        .registry
        .policies
        .read()
        .unwrap_or_else(|e| e.into_inner());
    let stored = store
        .get(name)
        .ok_or_else(|| CreateError::NoPolicy(name.to_string()))?;
    lasertag_policy::team::fits(&stored.policy, config.robots, &config.physics).map_err(|e| {
        CreateError::PolicyMisfit {
            name: name.to_string(),
            why: e.to_string(),
        }
    })?;
    Ok(Some((stored.inference_us, stored.every)))
}

/// Refuses more agents, or more particles, than this server takes in one match.
fn within_match_limits(
    service: Service<'_>,
    config: &lasertag_core::world::MatchConfig,
) -> Result<(), CreateError> {
    let cfg = &service.registry.config;
    let metrics = &service.registry.metrics;
    let agents = config.robots + config.opponents;
    if agents > cfg.max_agents_per_match {
        metrics.refuse(Refusal::TooManyAgents);
        return Err(CreateError::TooManyAgents {
            robots: config.robots,
            opponents: config.opponents,
            agents,
            max: cfg.max_agents_per_match,
        });
    }
    // The tracker holds at most one role per opponent.
    let particles = config.tracker.particles_per_role * config.opponents;
    if particles > cfg.max_particles_per_match {
        metrics.refuse(Refusal::TooManyParticles);
        return Err(CreateError::TooManyParticles {
            per_role: config.tracker.particles_per_role,
            opponents: config.opponents,
            particles,
            max: cfg.max_particles_per_match,
        });
    }
    Ok(())
}

/// Where a new match's map comes from.
enum MapSource {
    /// A map the server holds, built already (and priced when it was added).
    Stored(Arc<Arena>),
    /// A map in the request, validated, to be priced with the match and built for it alone.
    Inline(MapDef),
}

/// The request's `map`: a stored map's name, or an inline map validated on the pool.
/// Whether `map` names one of the maps the server ships (not an uploaded or inline one).
fn shipped(service: Service<'_>, map: &serde_json::Value) -> bool {
    let maps = service
        .registry
        .maps
        .read()
        .unwrap_or_else(|e| e.into_inner());
    map.as_str()
        .and_then(|name| maps.get(name))
        .is_some_and(|m| m.owner.token.is_none())
}

async fn map_source(
    service: Service<'_>,
    map: serde_json::Value,
) -> Result<MapSource, CreateError> {
    match map {
        serde_json::Value::String(name) => {
            let maps = service
                .registry
                .maps
                .read()
                .unwrap_or_else(|e| e.into_inner());
            match maps.get(&name) {
                Some(m) => Ok(MapSource::Stored(m.arena.clone())),
                None => Err(CreateError::NoMap(name)),
            }
        }
        value @ serde_json::Value::Object(_) => {
            let def = service
                .pool
                .run("validating the map", move || maps::from_value(value))
                .await?
                .map_err(|e| {
                    // Name the field as the request has it: `map.obstacles[2]`, or `map`.
                    let path = if e.path == "map" {
                        e.path
                    } else {
                        format!("map.{}", e.path)
                    };
                    CreateError::BadMap(MapError {
                        path,
                        message: e.message,
                    })
                })?;
            Ok(MapSource::Inline(def))
        }
        _ => Err(CreateError::NotAMap),
    }
}
