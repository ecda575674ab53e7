//! Names people keep (docs/api.md, "Names people keep"): claiming a name, giving it up, and
//! the check a join under a name makes. A claim is the only way a name gets a rating or
//! statistics; an unclaimed name still plays, unrated.
//!
//! Claims go to the history's store (its writer, so that two look-alike claims cannot both
//! win), on the blocking pool. They are priced three ways: a client keeps at most
//! `max_names_per_address` names (counted in the store, so a restart forgets nothing), the
//! server at most `max_names`, and it takes at most `name_claims_per_minute` claims from
//! everyone together (each one is a write beside the live matches').

use std::time::{Duration, Instant};

use crate::access::{ClientKey, SecretHash, random_id};
use crate::game::replay::HistoryError;
use crate::names::{JoinName, Name, NameError};
use crate::service::{PoolError, Service};
use crate::store::{ClaimLimits, ClaimOutcome, NameClaim, ReleaseOutcome, StoreError};

/// How long a claim waits for the history's writer.
const WRITER_WAIT: Duration = Duration::from_secs(10);

#[derive(Debug, thiserror::Error)]
pub enum NamesError {
    #[error(transparent)]
    Invalid(#[from] NameError),
    #[error("this server keeps no history, so it keeps no names: play under any name, unrated")]
    NoHistory,
    #[error("name: {sent:?} is kept by somebody else (as {kept:?}, which it looks like or is)")]
    Taken { sent: String, kept: String },
    #[error(
        "{client} keeps {most} names, its most: give one up first (DELETE /api/names/{{name}})"
    )]
    ClientFull { client: ClientKey, most: u64 },
    #[error("this server keeps {0} names, its most")]
    ServerFull(u64),
    #[error("this server takes {per_minute} claims of names a minute from everyone; retry in {} s", .wait.as_secs().max(1))]
    Busy { per_minute: f64, wait: Duration },
    #[error("nobody keeps the name {0:?}")]
    NotClaimed(String),
    #[error("name: {0:?} is kept by somebody: join with its name_token, or choose another name")]
    NeedsToken(String),
    #[error("that is not the name_token of {0:?}")]
    WrongToken(String),
    #[error("the history could not be read: {0}")]
    History(#[from] HistoryError),
    #[error(transparent)]
    Pool(#[from] PoolError),
}

impl From<StoreError> for NamesError {
    fn from(e: StoreError) -> NamesError {
        NamesError::History(e.into())
    }
}

/// A claimed name and its token, the only time the server holds the token in clear.
#[derive(Debug, Clone)]
pub struct Kept {
    pub name: String,
    pub token: String,
}

/// Claims `sent` for `client`.
pub async fn claim(
    service: Service<'_>,
    sent: String,
    client: ClientKey,
) -> Result<Kept, NamesError> {
    let name = Name::parse(&sent)?;
    let config = &service.registry.config;
    let history = service.registry.history.clone();
    if history.store().is_none() {
        return Err(NamesError::NoHistory);
    }
    {
        let mut bucket = service
            .registry
            .name_claims
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        let per_minute = config.name_claims_per_minute;
        let bucket = bucket.get_or_insert_with(|| {
            crate::access::Bucket::new(per_minute.max(1.0), per_minute / 60.0)
        });
        bucket.refill(Instant::now());
        if let Err(wait) = bucket.take() {
            return Err(NamesError::Busy { per_minute, wait });
        }
    }
    let token = random_id(24);
    let claim = NameClaim {
        name: name.as_str().to_string(),
        key: name.key().to_string(),
        token: SecretHash::of(&token).to_hex(),
        client: client.to_string(),
        claimed_at: crate::store::unix_ms(std::time::SystemTime::now()),
    };
    let limits = ClaimLimits {
        per_client: config.max_names_per_address,
        total: config.max_names,
    };
    let outcome = service
        .pool
        .run("claiming a name", move || {
            let store = history.store().ok_or(StoreError::Closed)?;
            store.claim(claim, limits, WRITER_WAIT)
        })
        .await??;
    match outcome {
        ClaimOutcome::Claimed => Ok(Kept {
            name: name.as_str().to_string(),
            token,
        }),
        ClaimOutcome::Taken(kept) => Err(NamesError::Taken {
            sent: name.as_str().to_string(),
            kept,
        }),
        ClaimOutcome::ClientFull => Err(NamesError::ClientFull {
            client,
            most: limits.per_client,
        }),
        ClaimOutcome::ServerFull => Err(NamesError::ServerFull(limits.total)),
    }
}

/// Gives up the claim on `sent`, with its token.
pub async fn release(service: Service<'_>, sent: String, token: &str) -> Result<(), NamesError> {
    let name = Name::parse(&sent)?;
    let history = service.registry.history.clone();
    if history.store().is_none() {
        return Err(NamesError::NoHistory);
    }
    let key = name.key().to_string();
    let hash = SecretHash::of(token).to_hex();
    let outcome = service
        .pool
        .run("giving a name up", move || {
            let store = history.store().ok_or(StoreError::Closed)?;
            store.release(key, hash, WRITER_WAIT)
        })
        .await??;
    match outcome {
        ReleaseOutcome::Released => Ok(()),
        ReleaseOutcome::NotClaimed => Err(NamesError::NotClaimed(name.as_str().to_string())),
        ReleaseOutcome::WrongToken => Err(NamesError::WrongToken(name.as_str().to_string())),
    }
}

/// Checks a join under `sent`: a kept name needs its token (`token`), a free one plays
/// unrated. With no history nothing is kept, and every name plays unrated.
pub async fn check_join(
    service: Service<'_>,
    sent: &str,
    token: Option<&str>,
) -> Result<JoinName, NamesError> {
    let name = Name::parse(sent)?;
    let history = service.registry.history.clone();
    if history.store().is_none() {
        return Ok(JoinName::unclaimed(name));
    }
    let key = name.key().to_string();
    let kept = service
        .pool
        .run("reading a name's claim", move || {
            let store = history.store().ok_or(StoreError::Closed)?;
            store.read(|b| b.claimed(&key))
        })
        .await??;
    match kept {
        None => Ok(JoinName::unclaimed(name)),
        Some(kept) => {
            let shown = token.map(SecretHash::of).map(|h| h.to_hex());
            match shown {
                // The kept spelling: a look-alike joins under the name it looks like.
                Some(hash) if crate::access::same_secret(&hash, &kept.token) => Ok(JoinName {
                    name: Name::parse(&kept.name)?,
                    claimed: true,
                }),
                Some(_) => Err(NamesError::WrongToken(kept.name)),
                None => Err(NamesError::NeedsToken(kept.name)),
            }
        }
    }
}
