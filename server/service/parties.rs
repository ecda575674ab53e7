//! Parties' use cases: a room made, joined, changed and left (`game::party`), and the
//! host's start, which creates the match the room chose and seats every member in it.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use crate::access::ClientKey;
use crate::game::MatchError;
use crate::game::party::{self, Party, PartyError, PartySettings, RoomView};
use crate::game::view::Team;
use crate::protocol::fleet::Place;
use crate::protocol::parties::party_match;
use crate::service::Service;
use crate::service::matches::{CreateError, Created, seat_all};
use crate::service::names::{NamesError, check_join};
use lasertag_core::difficulty::Difficulty;

/// Why a party request was refused.
#[derive(Debug, thiserror::Error)]
pub enum PartiesError {
    #[error(transparent)]
    Party(#[from] PartyError),
    #[error(transparent)]
    Name(#[from] NamesError),
    #[error("settings.map: no map {0:?} (GET /api/maps lists them)")]
    NoMap(String),
    #[error("the match could not start: {0}")]
    Create(#[from] CreateError),
    #[error("the match could not seat {name}: {error}")]
    Seat { name: String, error: MatchError },
}

/// The robot team a new room starts with: two robots searching at random, the lobby's
/// middle choice, which the host changes in the room.
const FIRST_DIFFICULTY: Difficulty = Difficulty::Veteran;
/// The map a new room starts with, when the server has it.
const FIRST_MAP: &str = "office";

/// A new room hosted by `name`: (code, member id, member token).
pub async fn create(
    service: Service<'_>,
    client: ClientKey,
    name: &str,
    name_token: Option<&str>,
) -> Result<(String, String, String), PartiesError> {
    let name = check_join(service, name, name_token).await?;
    let map = {
        let maps = service
            .registry
            .maps
            .read()
            .unwrap_or_else(|e| e.into_inner());
        match maps.get(FIRST_MAP) {
            Some(_) => FIRST_MAP.to_string(),
            None => maps
                .iter()
                .next()
                .map(|m| m.arena.def.name.clone())
                .unwrap_or_default(),
        }
    };
    let settings = PartySettings {
        map,
        difficulty: FIRST_DIFFICULTY,
        minutes: (FIRST_DIFFICULTY.preset().time_limit_s / 60) as u32,
    };
    Ok(service.registry.parties.create(name, client, settings)?)
}

/// `name` joins room `code`: (member id, member token).
pub async fn join(
    service: Service<'_>,
    client: ClientKey,
    code: &str,
    name: &str,
    name_token: Option<&str>,
) -> Result<(String, String), PartiesError> {
    // The code first: a guesser is refused before any name is read.
    service.registry.parties.get(code, Some(client))?;
    let name = check_join(service, name, name_token).await?;
    Ok(service.registry.parties.join(code, name, client)?)
}

/// A member's change (`PATCH`), the settings checked against the server's maps.
pub fn change(
    service: Service<'_>,
    client: ClientKey,
    code: &str,
    member: &str,
    token: &str,
    change: party::Change,
) -> Result<RoomView, PartiesError> {
    if let Some(map) = &change.map {
        let maps = service
            .registry
            .maps
            .read()
            .unwrap_or_else(|e| e.into_inner());
        if maps.get(map).is_none() {
            return Err(PartiesError::NoMap(map.clone()));
        }
    }
    Ok(service
        .registry
        .parties
        .change(code, member, token, client, change)?)
}

/// The host starts room `code`: the match it chose, every member seated in it. Nothing is
/// left behind when a seat cannot be had: the match is removed and the room waits as
/// before.
pub async fn start(
    service: Service<'_>,
    client: ClientKey,
    code: &str,
    token: &str,
) -> Result<String, PartiesError> {
    let parties = &service.registry.parties;
    let party = parties.begin_start(code, token, client)?;
    let code = party.code.clone();
    match seat_everyone(service, client, &party).await {
        Ok((match_id, seats)) => {
            parties.started(&code, &match_id, seats);
            Ok(match_id)
        }
        Err(e) => {
            parties.start_failed(&code);
            Err(e)
        }
    }
}

async fn seat_everyone(
    service: Service<'_>,
    client: ClientKey,
    party: &Party,
) -> Result<(String, BTreeMap<String, (String, Team)>), PartiesError> {
    let count = |side| party.members.iter().filter(|m| m.side == side).count();
    let (opponents, hunters) = (count(Team::Opponents), count(Team::Robots));
    // The preset's own length when the host kept it, so that one person alone plays the
    // preset as it was measured (rated); any other length is the host's.
    let time_limit =
        (!party.plays_the_preset_length()).then_some(f64::from(party.settings.minutes) * 60.0);
    let body = party_match(&party.settings, opponents, hunters, time_limit)
        .map_err(CreateError::Invalid)?;
    let created =
        crate::service::matches::create(service, Some(client), Place::Local, body, |_| None::<()>)
            .await?;
    let Created::Here(created) = created else {
        return Err(CreateError::Match(MatchError::Gone(party.code.clone())).into());
    };
    let id = created.summary.id.clone();
    let people = party
        .members
        .iter()
        .map(|m| (m.name.clone(), m.side))
        .collect();
    let tokens = seat_all(service, &id, people)
        .await
        .map_err(|u| PartiesError::Seat {
            name: u.name,
            error: u.error,
        })?;
    let seats = party
        .members
        .iter()
        .zip(tokens)
        .map(|(m, token)| (m.id.clone(), (token, m.side)))
        .collect();
    Ok((id, seats))
}

/// Keeps the rooms current for as long as the server runs: rooms whose match ended wait
/// again, and rooms nobody was connected to lapse.
pub async fn keep(registry: std::sync::Arc<crate::game::Registry>) {
    let mut every = tokio::time::interval(Duration::from_secs(1));
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    loop {
        tokio::select! {
            _ = every.tick() => {}
            _ = registry.shutdown.cancelled() => return,
        }
        registry.parties.sweep(Instant::now(), |id| {
            registry.get(id).is_some_and(|h| {
                h.hub.summary.borrow().status == lasertag_core::world::MatchStatus::Running
            })
        });
    }
}
