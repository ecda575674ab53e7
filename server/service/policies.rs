//! The trained policies' use cases (docs/api.md, "Trained robot teams"): the listing, an
//! upload (bounded in bytes, read and checked on the blocking pool, one inference timed,
//! priced in memory within the server's and the client's room) and a removal.

use std::sync::Arc;

use lasertag_policy::{Limits, Policy, PolicyError};

use crate::access::{ClientKey, Owner};
use crate::game::admission::{NoRoom, Price};
use crate::game::policies::{StoredPolicy, memory_of, time_inference};
use crate::metrics::Refusal;
use crate::protocol::{PolicyCreated, PolicyInfo};
use crate::service::admit::{OverLimit, within_request_limits};
use crate::service::{PoolError, Service};
use crate::store::{KeptPolicy, StoreError, Write, unix_ms};
use lasertag_core::world::MatchStatus;

/// How long an upload waits for the store's writer to keep it.
const WRITER_WAIT: std::time::Duration = std::time::Duration::from_secs(10);

/// Characters a policy's name may have (it travels in `planner` and in paths).
pub const MAX_NAME_LEN: usize = 64;

/// Why a policy was not found, added or removed.
#[derive(Debug, thiserror::Error)]
pub enum PoliciesError {
    #[error("no policy {0:?}")]
    NotFound(String),
    #[error("name: {0}")]
    BadName(String),
    #[error(
        "decide_every: {0:?} is not a whole number of ticks in 1..={max} (ticks between a policy's decisions; 2 when not given)",
        max = lasertag_policy::team::MAX_EVERY
    )]
    BadEvery(String),
    /// The model is not one this server runs (the error names what).
    #[error("the model: {0}")]
    Invalid(#[from] PolicyError),
    #[error("the model cannot drive a robot: {0}")]
    Misfit(String),
    #[error("body: {got} bytes or more, over this server's limit of {max} bytes for a policy")]
    TooLarge { got: usize, max: usize },
    #[error(
        "the model: one inference took {took_us:.0} µs on this server, over its limit of {max_us} µs (a robot decides every few ticks of 50 ms, beside every other match): use a smaller model"
    )]
    TooSlow { took_us: f64, max_us: u64 },
    #[error("a policy named {0:?} exists")]
    Taken(String),
    #[error(
        "the server holds {0} policies, its most; uploaded policies can be deleted by their owners"
    )]
    Full(usize),
    #[error(
        "{client} has uploaded {max} policies, the most one client may keep; delete one (DELETE /api/policies/{{name}} with its owner_token)"
    )]
    Quota { client: ClientKey, max: usize },
    #[error("policy {0:?} is shipped with the server and cannot be removed")]
    Shipped(String),
    #[error("policy {0:?} drives a running match; delete it when the match has ended")]
    InUse(String),
    #[error(transparent)]
    OverLimit(#[from] OverLimit),
    #[error(transparent)]
    NoRoom(#[from] NoRoom),
    #[error(transparent)]
    Pool(#[from] PoolError),
    #[error("the store cannot keep the policy now: {0}")]
    Store(#[from] StoreError),
}

fn info(name: &str, p: &StoredPolicy) -> PolicyInfo {
    PolicyInfo {
        name: name.to_string(),
        observation_size: p.policy.input_len(),
        action_size: p.policy.output_len(),
        inference_us: (p.inference_us * 10.0).round() / 10.0,
        decide_every: p.every,
        shipped: p.shipped(),
    }
}

/// Every policy the server holds.
pub fn list(service: Service<'_>) -> Vec<PolicyInfo> {
    let store = service
        .registry
        .policies
        .read()
        .unwrap_or_else(|e| e.into_inner());
    store.iter().map(|(name, p)| info(name, p)).collect()
}

/// A name a policy may take: 1 to 64 letters, digits, `-` and `_`.
pub fn check_name(name: &str) -> Result<(), PoliciesError> {
    if name.is_empty() || name.len() > MAX_NAME_LEN {
        return Err(PoliciesError::BadName(format!(
            "{name:?} must have 1 to {MAX_NAME_LEN} characters (give ?name=<name>)"
        )));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '-' || *c == '_'))
    {
        return Err(PoliciesError::BadName(format!(
            "{name:?}: {c:?} is not a letter, digit, '-' or '_'"
        )));
    }
    Ok(())
}

/// The ticks between a policy's decisions `sent` as `?decide_every=` (the default when
/// not given).
pub fn check_every(sent: Option<&str>) -> Result<u64, PoliciesError> {
    use lasertag_policy::team::{DEFAULT_EVERY, MAX_EVERY};
    let Some(sent) = sent else {
        return Ok(DEFAULT_EVERY);
    };
    sent.parse::<u64>()
        .ok()
        .filter(|every| (1..=MAX_EVERY).contains(every))
        .ok_or_else(|| PoliciesError::BadEvery(sent.to_string()))
}

/// Adds the model `bytes` as `name`, deciding every `every` ticks ([`check_every`]),
/// uploaded by `client`, who owns it.
pub async fn add(
    service: Service<'_>,
    client: ClientKey,
    name: String,
    every: u64,
    bytes: Vec<u8>,
) -> Result<PolicyCreated, PoliciesError> {
    check_name(&name)?;
    if !(1..=lasertag_policy::team::MAX_EVERY).contains(&every) {
        return Err(PoliciesError::BadEvery(every.to_string()));
    }
    room(service, &name, client)?;
    let registry = service.registry;
    // Reading allocates at most the file's size (the reader's guarantee), which the body
    // limit bounds: priced before it runs.
    let read = Price {
        memory: 2 * bytes.len() as u64,
        ..Price::default()
    };
    within_request_limits(registry, "the policy", read)?;
    let (policy, took_us, bytes) = service
        .pool
        .run("reading the policy", move || {
            let policy = Policy::from_onnx(&bytes, &Limits::default())?;
            let took = time_inference(&policy);
            Ok::<_, PolicyError>((policy, took, bytes))
        })
        .await??;
    lasertag_policy::team::check_action(&policy)
        .map_err(|e| PoliciesError::Misfit(e.to_string()))?;
    // A model must fit some team: its input is a robot's observation for 1 to 8 robots.
    let physics = lasertag_core::sim::Physics::default();
    if !(1..=8).any(|robots| {
        lasertag_policy::team::detection_slots(policy.input_len(), robots, &physics).is_ok()
    }) {
        let base = lasertag_policy::team::detection_slots(0, 1, &physics)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        return Err(PoliciesError::Misfit(format!(
            "it takes {} values, which is no robot observation of the research environment (docs/research.md, \"Observations\"; {base})",
            policy.input_len()
        )));
    }
    let max_us = registry.config.max_policy_inference_us;
    if took_us > max_us as f64 {
        return Err(PoliciesError::TooSlow { took_us, max_us });
    }
    let memory = memory_of(&policy);
    // The store keeps the model as uploaded: its bytes are charged to the disk budget too
    // (with no store they are kept nowhere).
    let disk = if registry.history.store().is_some() {
        bytes.len() as u64
    } else {
        0
    };
    let price = Price {
        memory,
        disk,
        ..Price::default()
    };
    within_request_limits(registry, "the policy", price)?;
    registry.has_budget(price, Some(client))?;
    // Checked again: others may have uploaded while this one was read.
    room(service, &name, client)?;
    let (owner, owner_token) = Owner::new(Some(client));
    // Kept before it is held: a 201 means it outlives this server, and on a store servers
    // share, the store is where two uploads of one name meet.
    if registry.history.store().is_some() {
        let history = registry.history.clone();
        let kept = KeptPolicy {
            name: name.clone(),
            model: bytes,
            token: owner.token.map(|t| t.to_hex()).unwrap_or_default(),
            client: client.to_string(),
            every,
            added_at: unix_ms(std::time::SystemTime::now()),
        };
        let added = service
            .pool
            .run("keeping the policy", move || {
                let store = history.store().ok_or(StoreError::Closed)?;
                store.keep_policy(kept, WRITER_WAIT)
            })
            .await??;
        if !added {
            return Err(PoliciesError::Taken(name));
        }
    }
    let stored = StoredPolicy {
        policy: Arc::new(policy),
        owner,
        inference_us: took_us,
        memory,
        disk,
        every,
    };
    let created = info(&name, &stored);
    let mut store = registry.policies.write().unwrap_or_else(|e| e.into_inner());
    if !store.insert(name.clone(), stored) {
        // The store kept it, yet a policy of this name is held here (loaded before another
        // server of the fleet removed it from the store): the row just kept is this refused
        // upload's, and goes with it.
        if let Some(history) = registry.history.store() {
            let _ = history.send(Write::DropPolicy { name: name.clone() });
        }
        return Err(PoliciesError::Taken(name));
    }
    Ok(PolicyCreated {
        policy: created,
        owner_token,
    })
}

/// Refuses an upload whose name is taken, past the server's most policies, or past the
/// client's quota.
fn room(service: Service<'_>, name: &str, client: ClientKey) -> Result<(), PoliciesError> {
    let cfg = &service.registry.config;
    let metrics = &service.registry.metrics;
    let store = service
        .registry
        .policies
        .read()
        .unwrap_or_else(|e| e.into_inner());
    if store.contains(name) {
        return Err(PoliciesError::Taken(name.to_string()));
    }
    if store.len() >= cfg.max_policies {
        metrics.refuse(Refusal::PoliciesFull);
        return Err(PoliciesError::Full(cfg.max_policies));
    }
    if store.uploaded_by(client) >= cfg.max_policies_per_address {
        metrics.refuse(Refusal::ClientQuota);
        return Err(PoliciesError::Quota {
            client,
            max: cfg.max_policies_per_address,
        });
    }
    Ok(())
}

/// The policy `name` as stored (with its owner, whom a removal must be allowed by).
pub fn stored(service: Service<'_>, name: &str) -> Result<StoredPolicy, PoliciesError> {
    service
        .registry
        .policies
        .read()
        .unwrap_or_else(|e| e.into_inner())
        .get(name)
        .cloned()
        .ok_or_else(|| PoliciesError::NotFound(name.to_string()))
}

/// Removes `stored`, the policy `name` as [`stored`] found it: not a shipped one, nor one
/// that drives a running match.
pub fn delete(service: Service<'_>, name: &str, stored: StoredPolicy) -> Result<(), PoliciesError> {
    if stored.shipped() {
        return Err(PoliciesError::Shipped(name.to_string()));
    }
    let in_use = service.registry.all().into_iter().any(|h| {
        h.hub.frames.borrow().status == MatchStatus::Running
            && h.hub.summary.borrow().config.policy.as_deref() == Some(name)
    });
    if in_use {
        return Err(PoliciesError::InUse(name.to_string()));
    }
    service
        .registry
        .policies
        .write()
        .unwrap_or_else(|e| e.into_inner())
        .remove_if(name, &stored.policy);
    if let Some(store) = service.registry.history.store()
        && store
            .send(Write::DropPolicy {
                name: name.to_string(),
            })
            .is_err()
    {
        tracing::error!(
            policy = name,
            "the history's queue is full: the policy stays kept, and comes back at the next start"
        );
    }
    Ok(())
}
