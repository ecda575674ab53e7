//! Trained robot teams the server holds (`POST /api/policies`, docs/api.md "Trained robot
//! teams"): each a checked model (`lasertag_policy::Policy`), who owns it, what one inference
//! costs here, and how often it decides. The shipped ones are built into the binary and
//! listed from the start. Uploaded ones are kept in the store (`store::KeptPolicy`) and
//! loaded again by every server that starts on it, or that resumes a match one drives
//! (`resume::restore_policies`, `resume::hold_if_kept`); a resumed match whose policy is gone
//! from both keeps its robots where their last orders left them.
//!
//! A match driven by a policy holds its own [`TeamPolicy`] (the model shared, the buffers
//! its own), made when its task starts (`policy_for`): new, resumed and the showcase alike.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use lasertag_core::world::World;
use lasertag_policy::team::{DEFAULT_EVERY, MAX_EVERY};
use lasertag_policy::{Limits, Policy, PolicyError, TeamPolicy};

use crate::access::{ClientKey, Owner, SecretHash};
use crate::store::KeptPolicy;

/// One policy the server holds.
#[derive(Debug, Clone)]
pub struct StoredPolicy {
    pub policy: Arc<Policy>,
    /// Who uploaded it; the default (no token) for shipped policies, which nobody removes.
    pub owner: Owner,
    /// Microseconds of one inference on this machine, timed when it was loaded.
    pub inference_us: f64,
    /// Bytes it holds in memory (its parameters), priced against the server's budget.
    pub memory: u64,
    /// Bytes the store keeps of it (the model as uploaded; none for a shipped one), charged
    /// to the server's disk budget for as long as it is held.
    pub disk: u64,
    /// Ticks between its decisions.
    pub every: u64,
}

impl StoredPolicy {
    pub fn shipped(&self) -> bool {
        self.owner.token.is_none()
    }
}

/// Every policy the server holds, by name.
#[derive(Debug, Default)]
pub struct PolicyStore {
    policies: BTreeMap<String, StoredPolicy>,
}

/// The bytes a model's parameters hold in memory, and a little for the rest.
pub fn memory_of(policy: &Policy) -> u64 {
    4 * policy.multiply_adds() as u64 + 4096
}

/// Times one inference of `policy` on an observation of zeros: the fastest of a few runs
/// (the first warms the caches), in microseconds.
pub fn time_inference(policy: &Policy) -> f64 {
    let observation = vec![0.0f32; policy.input_len()];
    let (mut action, mut scratch) = (Vec::new(), Vec::new());
    (0..5)
        .map(|_| {
            let start = Instant::now();
            let _ = policy.infer(&observation, &mut action, &mut scratch);
            start.elapsed().as_secs_f64() * 1e6
        })
        .fold(f64::INFINITY, f64::min)
}

impl PolicyStore {
    /// The shipped policies (`lasertag_policy::SHIPPED`), each checked and timed. A shipped
    /// model that does not load is left out, loudly: the server still starts.
    pub fn shipped() -> PolicyStore {
        let mut store = PolicyStore::default();
        for (name, bytes) in lasertag_policy::SHIPPED {
            match Policy::from_onnx(bytes, &Limits::default()) {
                Ok(policy) => {
                    let stored = StoredPolicy {
                        inference_us: time_inference(&policy),
                        memory: memory_of(&policy),
                        disk: 0,
                        policy: Arc::new(policy),
                        owner: Owner::default(),
                        every: DEFAULT_EVERY,
                    };
                    store.policies.insert(name.to_string(), stored);
                }
                Err(e) => {
                    tracing::error!(policy = name, error = %e, "a shipped policy does not load")
                }
            }
        }
        store
    }

    pub fn get(&self, name: &str) -> Option<&StoredPolicy> {
        self.policies.get(name)
    }

    pub fn iter(&self) -> impl Iterator<Item = (&String, &StoredPolicy)> {
        self.policies.iter()
    }

    pub fn len(&self) -> usize {
        self.policies.len()
    }

    pub fn is_empty(&self) -> bool {
        self.policies.is_empty()
    }

    pub fn contains(&self, name: &str) -> bool {
        self.policies.contains_key(name)
    }

    /// Policies `client` uploaded.
    pub fn uploaded_by(&self, client: ClientKey) -> usize {
        self.policies
            .values()
            .filter(|p| p.owner.client == Some(client))
            .count()
    }

    /// Memory of the uploaded policies: everyone's (`None`) or one client's.
    pub fn uploaded_memory(&self, client: Option<ClientKey>) -> u64 {
        self.policies
            .values()
            .filter(|p| !p.shipped() && (client.is_none() || p.owner.client == client))
            .map(|p| p.memory)
            .sum()
    }

    /// Bytes the store keeps of the uploaded policies (see [`StoredPolicy::disk`]).
    pub fn uploaded_disk(&self) -> u64 {
        self.policies.values().map(|p| p.disk).sum()
    }

    /// Adds `stored` as `name`; false when the name is taken.
    pub fn insert(&mut self, name: String, stored: StoredPolicy) -> bool {
        if self.policies.contains_key(&name) {
            return false;
        }
        self.policies.insert(name, stored);
        true
    }

    /// Removes `name` if it is still the policy `expected` (a new upload under the same name
    /// is not the remover's).
    pub fn remove_if(&mut self, name: &str, expected: &Arc<Policy>) -> bool {
        if self
            .policies
            .get(name)
            .is_some_and(|p| Arc::ptr_eq(&p.policy, expected))
        {
            self.policies.remove(name);
            return true;
        }
        false
    }
}

/// The policy that drives `world`'s team, set up for it, when its settings name one this
/// server holds and it fits the team.
pub fn policy_for(store: &PolicyStore, world: &World) -> Option<TeamPolicy> {
    let name = world.config.policy.as_deref()?;
    let Some(stored) = store.get(name) else {
        tracing::warn!(
            policy = name,
            "the match's policy is not held here: its robots wait"
        );
        return None;
    };
    team_for(stored, world)
        .map_err(
            |e| tracing::warn!(policy = name, error = %e, "the match's policy does not fit it"),
        )
        .ok()
}

/// `stored` set up for `world`'s team, or why it does not fit: a shipped model with the
/// guard against parking (`lasertag_policy::unpark`), an uploaded one as it was trained.
pub fn team_for(stored: &StoredPolicy, world: &World) -> Result<TeamPolicy, PolicyError> {
    let team = TeamPolicy::new(
        stored.policy.clone(),
        &world.arena,
        world.robots.len(),
        &world.config.physics,
        stored.every,
    )?;
    Ok(if stored.shipped() {
        team.unparked()
    } else {
        team
    })
}

/// `kept` as the server holds it: read and checked again, one inference timed on this
/// machine, owned as when it was uploaded.
pub fn from_kept(kept: &KeptPolicy) -> Result<StoredPolicy, PolicyError> {
    let policy = Policy::from_onnx(&kept.model, &Limits::default())?;
    Ok(StoredPolicy {
        inference_us: time_inference(&policy),
        memory: memory_of(&policy),
        disk: kept.model.len() as u64,
        policy: Arc::new(policy),
        owner: Owner {
            token: SecretHash::from_hex(&kept.token),
            client: ClientKey::parse(&kept.client),
            reads_live: true,
        },
        every: kept.every.clamp(1, MAX_EVERY),
    })
}
