//! Matches survive their server: a server that starts on a store holding matches that were
//! running brings them back, under the same ids, owner and seat tokens, from their last
//! stored tick.
//!
//! A match is a pure function of (map, settings, seed, inputs by tick), and its record
//! streams to the store about once a second (`task/history.rs`), so rebuilding it is
//! re-simulating its inputs: [`rebuild`] does that off the async workers, on threads of a
//! lower priority (`background`), as many at once as the machine has cores, and hands each
//! rebuilt world to [`resume_all`], which starts its task on the runtime. A match with a
//! delayed view is rebuilt to its delay's worth of ticks before where it stopped; its task
//! runs the rest at once, publishing every tick (`Resumed::catch_up`), so that spectators see
//! what they saw before the restart and nothing live. While a match is being rebuilt the
//! registry says so (`Registry::is_resuming`) and requests for it get 503 with
//! `Retry-After`; the server answers everything else from its first second.
//!
//! A record that cannot be rebuilt (a damaged or foreign store) ends that match alone with
//! reason `lost`: the store keeps it as an incomplete replay, the log says why, and
//! `lasertag_matches_resumed_total{outcome="lost"}` counts it.
//!
//! Uploaded policies come back with them: the store keeps each one's model, and a server
//! loads them, as many as its `--max-policies` holds, before it resumes a match
//! ([`restore_policies`]), and a policy it lacks when it adopts a match another server of a
//! fleet ran ([`hold_if_kept`]).

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use lasertag_core::sim::arena::Arena;
use lasertag_core::world::{MatchStatus, World, WorldInput};

use crate::access::{ClientKey, Owner, SecretHash};
use crate::game::admission::{self, Price};
use crate::game::record::Recording;
use crate::game::view::MatchMeta;
use crate::game::{Registry, Resumed, ResumedSeat, policies};
use crate::store::codec::{StoredLive, StoredSettings, decode_checkpoint, decode_inputs};
use crate::store::{KeptPolicy, Store, StoredCheckpoint, Unfinished, Write};

/// Why a stored match could not be brought back.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("match {id} cannot be resumed: {why}")]
pub struct ResumeError {
    pub id: String,
    pub why: String,
}

/// A match rebuilt from its record, ready for its task.
#[derive(Debug)]
pub struct Rebuilt {
    pub world: World,
    pub meta: MatchMeta,
    pub owner: Owner,
    pub price: Price,
    pub resumed: Resumed,
}

/// What [`resume_all`] did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Report {
    pub resumed: usize,
    pub lost: usize,
    /// From the first read of the store to the last match started.
    pub took: Duration,
}

/// Rebuilds the match `left` records: its world at the tick where its task takes over, and
/// everything its task needs besides. Blocking: it re-simulates the match up to there.
/// `ours` is the server's map of the stored map's name, if it has one: its arena (derived
/// tables built once) serves when it is the same map; `spills`: the server has a store for
/// the recording to let go to.
pub fn rebuild(
    left: Unfinished,
    ours: Option<Arc<Arena>>,
    spills: bool,
) -> Result<Rebuilt, ResumeError> {
    let id = left.stored.listed.id.clone();
    let fail = |why: String| ResumeError {
        id: id.clone(),
        why,
    };
    let settings: StoredSettings =
        serde_json::from_str(&left.stored.settings).map_err(|e| fail(format!("settings: {e}")))?;
    let config = settings.config().map_err(|e| fail(e.to_string()))?;
    let live = match &left.live {
        Some(json) => StoredLive::from_json(json).map_err(|e| fail(format!("live record: {e}")))?,
        None => return Err(fail("the store has no owner or seats for it".into())),
    };
    let arena = arena_of(&left.stored.map_document, ours).map_err(|e| fail(format!("map: {e}")))?;
    let mut inputs: Vec<(u64, WorldInput)> = Vec::new();
    for chunk in &left.stored.chunks {
        inputs.extend(decode_inputs(chunk).map_err(|e| fail(e.to_string()))?);
    }
    if inputs.windows(2).any(|w| w[0].0 > w[1].0) {
        return Err(fail("its inputs are out of tick order".into()));
    }
    let until = left.stored.listed.ticks;
    let delay = settings.spectator_delay_ticks;
    // The task replays the delay's worth itself, publishing each tick (see `Resumed`).
    let from = until.saturating_sub(delay);
    let fresh = || World::new(arena.clone(), config.clone()).map_err(|e| fail(e.to_string()));
    let (mut world, mut next, checkpoint_tick) =
        match from_checkpoint(&left.checkpoints, from, inputs.len(), fresh()?) {
            Ok(Some((world, applied, tick))) => (world, applied, Some(tick)),
            Ok(None) => (fresh()?, 0, None),
            Err(why) => {
                tracing::warn!(%id, "rebuilt from tick 0: {why}");
                (fresh()?, 0, None)
            }
        };
    while world.tick < from && world.status == MatchStatus::Running {
        while let Some((t, input)) = inputs.get(next)
            && *t == world.tick
        {
            // An input refused live was never recorded; one refused now changes nothing,
            // as it did not then.
            let _ = world.apply(input);
            next += 1;
        }
        world.step();
    }
    if world.status != MatchStatus::Running && world.tick < until {
        return Err(fail(format!(
            "its record ends at tick {until}, but the match it rebuilds ended at tick {}",
            world.tick
        )));
    }
    let catch_up = inputs[next..].to_vec();
    let owner = Owner {
        token: match &live.owner {
            Some(hex) => Some(
                SecretHash::from_hex(hex).ok_or_else(|| fail("its owner token's hash".into()))?,
            ),
            None => None,
        },
        client: live.client.as_deref().and_then(ClientKey::parse),
        reads_live: live.reads_live,
    };
    let mut seats = Vec::with_capacity(live.seats.len());
    for s in &live.seats {
        seats.push(ResumedSeat {
            seat: s.seat,
            player_id: s.player_id.clone(),
            name: s.name.clone(),
            token: SecretHash::from_hex(&s.token)
                .ok_or_else(|| fail(format!("the token hash of seat {}", s.seat)))?,
            client: s.client.as_deref().and_then(ClientKey::parse),
        });
    }
    let l = &left.stored.listed;
    let meta = MatchMeta {
        head_start_ticks: live.head_start_ticks,
        ..MatchMeta::stored(id.clone(), l.map.clone(), &settings)
    };
    let price = admission::held_back(&config, delay) + admission::match_on(&arena.def, &config);
    let started_at = SystemTime::UNIX_EPOCH + Duration::from_millis(l.started_at_ms.max(0) as u64);
    Ok(Rebuilt {
        world,
        meta,
        owner,
        price,
        resumed: Resumed {
            recording: Recording::stored(spills, inputs),
            catch_up,
            until,
            seats,
            people: live.people.clone(),
            started_at,
            checkpoint_tick,
        },
    })
}

/// The world of the newest of `checkpoints` a rebuild to tick `from` may start from (one no
/// later than `from`, whose inputs the record has: at most `recorded`), restored into
/// `fresh`, with how many inputs it had applied and its tick: `None` when there is none.
/// A checkpoint that cannot be restored (a build whose types differ) is an error: the
/// caller rebuilds from tick 0, which only takes longer.
fn from_checkpoint(
    checkpoints: &[StoredCheckpoint],
    from: u64,
    recorded: usize,
    fresh: World,
) -> Result<Option<(World, usize, u64)>, String> {
    let Some(c) = checkpoints
        .iter()
        .filter(|c| c.tick <= from && c.applied as usize <= recorded)
        .max_by_key(|c| c.tick)
    else {
        return Ok(None);
    };
    let world = decode_checkpoint(fresh, &c.state).map_err(|e| e.to_string())?;
    if world.tick != c.tick {
        return Err(format!(
            "the checkpoint of tick {} holds tick {}",
            c.tick, world.tick
        ));
    }
    Ok(Some((world, c.applied as usize, c.tick)))
}

/// The arena of a stored map: `ours` when it is the same map (so its derived tables are
/// shared), else built from the document.
fn arena_of(document: &str, ours: Option<Arc<Arena>>) -> Result<Arc<Arena>, String> {
    if let Some(arena) = ours
        && crate::maps::import::to_json(&crate::maps::to_file(&arena.def)) == document
    {
        return Ok(arena);
    }
    let def = crate::maps::parse(document).map_err(|e| e.to_string())?;
    Ok(Arc::new(Arena::new(def)))
}

/// The matches the registry's store holds as running, noted as being resumed (requests for
/// them get 503 from now until [`resume_all`] has brought each back). Blocking, one short
/// read: the server calls it before it serves its first request, so that no request finds
/// such a match missing.
pub fn left_running(registry: &Registry) -> Vec<String> {
    if !registry.resumes_matches() {
        return Vec::new();
    }
    let ids = match registry.history.store().map(Store::unfinished) {
        Some(Ok(ids)) => ids,
        Some(Err(e)) => {
            tracing::error!("cannot read the matches left running: {e}");
            return Vec::new();
        }
        None => return Vec::new(),
    };
    registry.resuming(&ids);
    ids
}

/// Brings back the matches `ids` ([`left_running`]), each under its old id, owner and
/// seats; a match whose record cannot be rebuilt ends with reason `lost`.
pub async fn resume_all(registry: Arc<Registry>, ids: Vec<String>) -> Report {
    let started = Instant::now();
    let mut report = Report::default();
    if ids.is_empty() {
        return report;
    }
    tracing::info!(matches = ids.len(), "resuming the matches left running");
    let queue = Arc::new(Mutex::new(VecDeque::from(ids.clone())));
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel();
    let workers = std::thread::available_parallelism().map_or(2, |n| n.get());
    for _ in 0..workers.min(ids.len()) {
        let (queue, tx, registry) = (queue.clone(), tx.clone(), registry.clone());
        let spawned = crate::game::background::spawn("resume", move || {
            loop {
                let next = queue.lock().unwrap_or_else(|e| e.into_inner()).pop_front();
                let Some(id) = next else { break };
                let result = rebuild_one(&registry, &id);
                if tx.send((id, result)).is_err() {
                    break;
                }
            }
        });
        if let Err(e) = spawned {
            tracing::error!("no thread to resume matches on: {e}");
        }
    }
    drop(tx);
    while let Some((id, result)) = rx.recv().await {
        match result {
            Ok(r) => {
                tracing::info!(id, tick = r.resumed.until, "match rebuilt");
                registry.start_resumed(r.world, r.meta, r.owner, r.price, r.resumed);
                registry
                    .metrics
                    .matches_resumed
                    .with_label_values(&["resumed"])
                    .inc();
                report.resumed += 1;
            }
            Err(e) => {
                tracing::error!("{e}; it ends with reason `lost`");
                if let Some(store) = registry.history.store()
                    && store.send(Write::Lost { id: id.clone() }).is_err()
                {
                    tracing::warn!(
                        id,
                        "the history's queue is full: the lost match stays unfinished there"
                    );
                }
                registry.done_resuming(&id);
                registry
                    .metrics
                    .matches_resumed
                    .with_label_values(&["lost"])
                    .inc();
                report.lost += 1;
            }
        }
    }
    // A worker that could not start leaves its matches unread: they are lost to this run.
    for id in ids.iter().filter(|id| registry.is_resuming(id)) {
        tracing::error!(id, "match not resumed: no worker read it");
        registry.done_resuming(id);
    }
    report.took = started.elapsed();
    tracing::info!(
        resumed = report.resumed,
        lost = report.lost,
        took_ms = report.took.as_millis() as u64,
        "matches left running resumed"
    );
    report
}

/// How often a server on a shared store looks for matches other servers can no longer run.
pub const ADOPT_EVERY: Duration = Duration::from_secs(2);
/// Matches one server takes at one look, so that the servers with room share a dead one's.
const ADOPT_AT_ONCE: usize = 8;

/// On a store servers share (a fleet's PostgreSQL): every [`ADOPT_EVERY`], takes the running
/// matches whose server's lease ran out (it died, or was cut off or paused past it) or that
/// a draining server handed to this one, as many as this server has room for, and resumes
/// them as a restart does. The store takes each atomically, its fence one up, so no two
/// servers run a match at once and the one that lost it can write nothing more to it.
pub async fn adopt_forever(registry: Arc<Registry>) {
    if !registry.history.store().is_some_and(Store::adopts) {
        return;
    }
    let mut every = tokio::time::interval(ADOPT_EVERY);
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        every.tick().await;
        if registry.draining.is_cancelled() {
            return;
        }
        let room = registry
            .config
            .max_matches
            .saturating_sub(registry.len())
            .min(ADOPT_AT_ONCE);
        if room == 0 {
            continue;
        }
        let running: Vec<String> = registry.all().into_iter().map(|h| h.id).collect();
        let asker = registry.clone();
        let taken = tokio::task::spawn_blocking(move || {
            asker
                .history
                .store()
                .map(|s| s.adopt(room, running, Duration::from_secs(10)))
        })
        .await;
        let ids = match taken {
            Ok(Some(Ok(ids))) => ids,
            Ok(Some(Err(e))) => {
                tracing::warn!("cannot look for matches to adopt: {e}");
                continue;
            }
            _ => continue,
        };
        if ids.is_empty() {
            continue;
        }
        tracing::info!(
            matches = ids.len(),
            "adopting matches another server can no longer run"
        );
        registry.resuming(&ids);
        resume_all(registry.clone(), ids).await;
    }
}

/// Reads and rebuilds the match `id` (blocking).
fn rebuild_one(registry: &Registry, id: &str) -> Result<Rebuilt, ResumeError> {
    let fail = |why: String| ResumeError {
        id: id.to_string(),
        why,
    };
    let store = registry
        .history
        .store()
        .ok_or_else(|| fail("no store".into()))?;
    let left = store
        .load_unfinished(id)
        .map_err(|e| fail(e.to_string()))?
        .ok_or_else(|| fail("the store no longer has it running".into()))?;
    let ours = registry
        .maps
        .read()
        .unwrap_or_else(|e| e.into_inner())
        .get(&left.stored.listed.map)
        .map(|m| m.arena.clone());
    let rebuilt = rebuild(left, ours, true)?;
    // Its task sets the policy up when it starts: held by then, if the store keeps it.
    if let Some(name) = rebuilt.world.config.policy.as_deref() {
        hold_if_kept(registry, name);
    }
    Ok(rebuilt)
}

/// What [`hold`] did with a kept policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Held {
    /// Loaded: the server holds it now, as uploaded.
    Loaded,
    /// Not loaded: the server holds `--max-policies` already.
    Full,
    /// Not loaded: held already, or the model does not load (logged).
    Not,
}

/// Holds `kept` unless a policy by its name is held already (a shipped one wins over an
/// uploaded one of the same name) or the server holds its most (`--max-policies`, as an
/// upload would find it).
fn hold(registry: &Registry, kept: &KeptPolicy) -> Held {
    let full = || {
        let held = registry.policies.read().unwrap_or_else(|e| e.into_inner());
        !held.contains(&kept.name) && held.len() >= registry.config.max_policies
    };
    // Before the model is read: a full server reads none.
    if full() {
        return Held::Full;
    }
    let stored = match policies::from_kept(kept) {
        Ok(stored) => stored,
        Err(e) => {
            tracing::error!(policy = kept.name, error = %e, "a kept policy does not load");
            return Held::Not;
        }
    };
    let max_us = registry.config.max_policy_inference_us as f64;
    if stored.inference_us > max_us {
        tracing::warn!(
            policy = kept.name,
            inference_us = stored.inference_us,
            "a kept policy is slower here than this server takes uploads; it is held, and priced as timed"
        );
    }
    let mut policies = registry.policies.write().unwrap_or_else(|e| e.into_inner());
    if let Some(held) = policies.get(&kept.name) {
        // Two matches it drives, resumed side by side, both load it: the first one holds it.
        if held.shipped() {
            tracing::warn!(
                policy = kept.name,
                "a kept policy has the name of a shipped one; the shipped one is served"
            );
        }
        return Held::Not;
    }
    // Checked again under the lock: another match's resume may have loaded one meanwhile.
    if policies.len() >= registry.config.max_policies {
        return Held::Full;
    }
    if policies.insert(kept.name.clone(), stored) {
        Held::Loaded
    } else {
        Held::Not
    }
}

/// Loads the policies the registry's store keeps, oldest first, as many as
/// `--max-policies` leaves room for (blocking: a read and each model checked): the server
/// calls it before it resumes matches or serves its first request. A store servers share may
/// keep more than this server holds (another node's `--max-policies` is larger): those are
/// left in the store, with one warning, and one that a match adopted here needs is loaded
/// when there is room ([`hold_if_kept`]). Answers how many it loaded.
pub fn restore_policies(registry: &Registry) -> usize {
    let Some(store) = registry.history.store() else {
        return 0;
    };
    let kept = match store.read(|b| b.kept_policies()) {
        Ok(kept) => kept,
        Err(e) => {
            tracing::error!("cannot read the kept policies: {e}");
            return 0;
        }
    };
    let (mut loaded, mut left) = (0, 0);
    for k in &kept {
        match hold(registry, k) {
            Held::Loaded => loaded += 1,
            Held::Full => left += 1,
            Held::Not => {}
        }
    }
    if left > 0 {
        tracing::warn!(
            left,
            loaded,
            max_policies = registry.config.max_policies,
            "the store keeps more policies than --max-policies lets this server hold: the newest are left there (raise --max-policies to serve them here)"
        );
    }
    loaded
}

/// Takes back the parties' rooms the registry's store keeps (blocking: one read): the server
/// calls it before it serves its first request, so that a page that reconnects finds its
/// room and its member token.
pub fn restore_parties(registry: &Registry) -> usize {
    let Some(store) = registry.history.store() else {
        return 0;
    };
    match store.read(|b| b.kept_parties()) {
        Ok(kept) => registry.parties.restore(kept),
        Err(e) => {
            tracing::error!("cannot read the kept parties: {e}");
            0
        }
    }
}

/// Loads the policy `name` from the store when the registry does not hold it and the store
/// keeps it (blocking): a match adopted from another server of a fleet may be driven by a
/// policy uploaded there after this server started.
pub fn hold_if_kept(registry: &Registry, name: &str) {
    let held = registry
        .policies
        .read()
        .unwrap_or_else(|e| e.into_inner())
        .contains(name);
    if held {
        return;
    }
    match registry
        .history
        .store()
        .map(|s: &Store| s.read(|b| b.kept_policy(name)))
    {
        Some(Ok(Some(kept))) if hold(registry, &kept) == Held::Full => {
            tracing::warn!(
                policy = name,
                max_policies = registry.config.max_policies,
                "a match needs a kept policy, but this server holds --max-policies already: its robots wait (raise --max-policies)"
            );
        }
        Some(Err(e)) => tracing::warn!(policy = name, "cannot read a kept policy: {e}"),
        _ => {}
    }
}
