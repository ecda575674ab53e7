//! The maps' use cases: the listing, one map, an upload (validated, priced and built on the
//! blocking pool, within the server's and the client's room) and a removal.

use std::sync::Arc;

use crate::access::{ClientKey, Owner};
use crate::game::admission::{self, NoRoom};
use crate::maps::{self, MapError, MapFile, StoredMap};
use crate::metrics::Refusal;
use crate::protocol::{MapCreated, MapInfo};
use crate::service::admit::{OverLimit, within_request_limits};
use crate::service::{PoolError, Service};
use lasertag_core::sim::arena::{Arena, MapDef};
use lasertag_core::world::MatchStatus;

/// Why a map was not found, added or removed.
#[derive(Debug, thiserror::Error)]
pub enum MapsError {
    #[error("no map {0:?}")]
    NotFound(String),
    /// The uploaded map breaks a rule.
    #[error(transparent)]
    Invalid(#[from] MapError),
    #[error("a map named {0:?} exists")]
    Taken(String),
    #[error("the server holds {0} maps, its most; uploaded maps can be deleted by their owners")]
    Full(usize),
    #[error(
        "{client} has uploaded {max} maps, the most one client may keep; delete one (DELETE /api/maps/{{name}} with its owner_token)"
    )]
    Quota { client: ClientKey, max: usize },
    #[error("map {0:?} is shipped with the server and cannot be removed")]
    Shipped(String),
    #[error("map {0:?} is in use by a running match; delete it when the match has ended")]
    InUse(String),
    #[error(transparent)]
    OverLimit(#[from] OverLimit),
    #[error(transparent)]
    NoRoom(#[from] NoRoom),
    #[error(transparent)]
    Pool(#[from] PoolError),
}

fn info(def: &MapDef) -> MapInfo {
    MapInfo {
        name: def.name.clone(),
        width: def.width as f64,
        height: def.height as f64,
    }
}

/// Every map the server holds.
pub fn list(service: Service<'_>) -> Vec<MapInfo> {
    let maps = service
        .registry
        .maps
        .read()
        .unwrap_or_else(|e| e.into_inner());
    maps.iter().map(|m| info(&m.arena.def)).collect()
}

/// The map `name`, as a map file.
pub fn get(service: Service<'_>, name: &str) -> Result<MapFile, MapsError> {
    let maps = service
        .registry
        .maps
        .read()
        .unwrap_or_else(|e| e.into_inner());
    maps.get(name)
        .map(|m| maps::to_file(&m.arena.def))
        .ok_or_else(|| MapsError::NotFound(name.to_string()))
}

/// Adds the map `value` uploaded by `client`, who owns it.
pub async fn add(
    service: Service<'_>,
    client: ClientKey,
    value: serde_json::Value,
) -> Result<MapCreated, MapsError> {
    let registry = service.registry;
    let def = service
        .pool
        .run("validating the map", move || maps::from_value(value))
        .await??;
    room(service, &def.name, client)?;
    let price = admission::map(&def);
    within_request_limits(registry, "the map", price)?;
    registry.has_budget(price, Some(client))?;
    let name = def.name.clone();
    let info = info(&def);
    let arena = service
        .pool
        .run("building the map", move || Arc::new(Arena::new(def)))
        .await?;
    // Checked again: others may have uploaded while this one was built.
    room(service, &name, client)?;
    let (owner, owner_token) = Owner::new(Some(client));
    let mut store = registry.maps.write().unwrap_or_else(|e| e.into_inner());
    if !store.insert_owned(arena, owner, price.memory) {
        return Err(MapsError::Taken(name));
    }
    Ok(MapCreated {
        map: info,
        owner_token,
    })
}

/// Refuses a map upload whose name is taken, past the server's most maps, or past the
/// client's quota.
fn room(service: Service<'_>, name: &str, client: ClientKey) -> Result<(), MapsError> {
    let cfg = &service.registry.config;
    let metrics = &service.registry.metrics;
    let store = service
        .registry
        .maps
        .read()
        .unwrap_or_else(|e| e.into_inner());
    if store.contains(name) {
        return Err(MapsError::Taken(name.to_string()));
    }
    if store.len() >= cfg.max_maps {
        metrics.refuse(Refusal::MapsFull);
        return Err(MapsError::Full(cfg.max_maps));
    }
    if store.uploaded_by(client) >= cfg.max_maps_per_address {
        metrics.refuse(Refusal::ClientQuota);
        return Err(MapsError::Quota {
            client,
            max: cfg.max_maps_per_address,
        });
    }
    Ok(())
}

/// The map `name` as stored (with its owner, whom a removal must be allowed by), if any.
pub fn stored(service: Service<'_>, name: &str) -> Option<StoredMap> {
    service
        .registry
        .maps
        .read()
        .unwrap_or_else(|e| e.into_inner())
        .get(name)
        .cloned()
}

/// Removes `stored`, the map `name` as [`stored`] found it: not a shipped map, nor one a
/// running match plays on.
pub fn delete(service: Service<'_>, name: &str, stored: StoredMap) -> Result<(), MapsError> {
    if stored.owner.token.is_none() {
        return Err(MapsError::Shipped(name.to_string()));
    }
    let in_use = service.registry.all().into_iter().any(|h| {
        Arc::ptr_eq(&h.hub.arena, &stored.arena)
            && h.hub.frames.borrow().status == MatchStatus::Running
    });
    if in_use {
        return Err(MapsError::InUse(name.to_string()));
    }
    let mut maps = service
        .registry
        .maps
        .write()
        .unwrap_or_else(|e| e.into_inner());
    // Only the map that was checked: a new one under the same name is not this request's.
    if maps
        .get(name)
        .is_some_and(|m| Arc::ptr_eq(&m.arena, &stored.arena))
    {
        maps.remove(name);
    }
    Ok(())
}
