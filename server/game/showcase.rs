//! The showcase: a real-time match that is always running, so that anyone who opens the
//! server sees play at once. When it ends, a fresh one (new seed) starts a few seconds later.
//! People may take its bots, so its seed is secret, drawn from the operating system's random
//! source (see `view::people_may_play`). It starts its spectators' delay in the past (its
//! first 30 s of play run at once, on a seed whose robots tag nobody in them), so that its
//! delayed view moves from the first second.
//! While people hold every slot of every running showcase, another starts beside them (at
//! most [`MAX_SHOWCASES`], within the server's budget), and a visitor who asks for a seat
//! ([`join_or_create`]) starts it at once, so that a visitor always finds a free one.

use std::sync::Arc;
use std::time::Duration;

use crate::access::{ClientKey, Owner};
use crate::game::admission::{self, NoRoom};
use crate::game::view::{Clock, Joined, MatchMeta, Team};
use crate::game::{MatchError, MatchHandle, Registry, random_id, random_seed};
use crate::names::JoinName;
use lasertag_core::bots::BotKind;
use lasertag_core::planner::PlannerKind;
use lasertag_core::sim::TICK_HZ;
use lasertag_core::world::{ControlKind, MatchConfig};
use lasertag_core::world::{MatchStatus, World};

/// Preferred map of the showcase, when the server has it; otherwise the first map. The
/// largest shipped map: a match there lasts (on `office` two coordinated robots tag three
/// bots within a minute in most seeds, too soon for a visitor who comes after the head
/// start to find a bot to take over).
const SHOWCASE_MAP: &str = "warehouse";
/// How long a finished showcase stays up (so its end can be seen) before the next starts.
const LINGER: Duration = Duration::from_secs(10);
/// Bots of a showcase.
const SHOWCASE_BOTS: usize = 5;
/// A showcase runs its delay's worth of play at once (see `start`) only with a seed that
/// leaves at least this many bots untagged by then and the match still running this long
/// after it (on `warehouse`, 50 of 60 seeds), so that a visitor who opens it then finds
/// bots to take over in a match that goes on.
const FREE_AFTER_HEAD_START: usize = 3;
const RUNNING_AFTER_HEAD_START_S: u64 = 10;
/// Seeds tried for such a showcase; when none is, it starts without a head start (its
/// spectators then count down to the delayed view, as in any young delayed match).
const SEED_TRIES: usize = 6;

/// Starts a showcase: the first one whatever the server holds (a visitor must find play),
/// every other one (`priced`) only when admission has room for it, as for any match.
async fn start(registry: &Registry, priced: bool) -> Result<String, NoShowcase> {
    let arena = {
        let maps = registry.maps.read().unwrap_or_else(|e| e.into_inner());
        maps.get(SHOWCASE_MAP)
            .or_else(|| maps.iter().next())
            .ok_or(NoShowcase::NoMap)?
            .arena
            .clone()
    };
    let base = MatchConfig {
        robots: 2,
        // Bots that run from the robots: a match that lasts long enough to watch, and a
        // belief that splits into several roles.
        opponents: SHOWCASE_BOTS,
        opponent_control: ControlKind::Bot,
        opponent_bot: BotKind::Evade,
        planner: PlannerKind::Coordinated,
        ..MatchConfig::default()
    };
    let map = arena.def.name.clone();
    let delay = (crate::game::delay::SPECTATOR_DELAY_S * TICK_HZ as f64) as u64;
    // Off the async workers: the planner's views of a map take tens of milliseconds to build,
    // and a try runs up to 40 s of play. Without people a match is its seed's alone, so a
    // probe of a seed shows what the showcase's first seconds will be.
    let (world, head_start) = tokio::task::spawn_blocking(move || {
        let horizon = delay + RUNNING_AFTER_HEAD_START_S * TICK_HZ as u64;
        let untagged = |w: &World| w.opponents.iter().filter(|o| !o.tagged).count();
        let mut config = base.clone();
        for _ in 0..SEED_TRIES {
            config = MatchConfig {
                seed: random_seed(),
                ..base.clone()
            };
            let mut probe = World::new(arena.clone(), config.clone()).ok()?;
            let run_to = |probe: &mut World, tick: u64| {
                while probe.tick < tick && probe.step() {}
            };
            run_to(&mut probe, delay);
            if untagged(&probe) < FREE_AFTER_HEAD_START {
                continue;
            }
            run_to(&mut probe, horizon);
            if probe.status == MatchStatus::Running {
                return Some((World::new(arena, config).ok()?, delay));
            }
        }
        Some((World::new(arena, config).ok()?, 0))
    })
    .await
    .ok()
    .flatten()
    .ok_or(NoShowcase::NoMap)?;
    let meta = MatchMeta {
        // As long as any match's id: the history (shared by a fleet) keeps every showcase.
        id: format!("{SHOWCASE_PREFIX}{}", random_id(8)),
        map,
        clock: Clock::Realtime,
        players: 0,
        spectators: 0,
        free_slots: 0,
        free_pursuer_slots: 0,
        // Anyone who opens the server can take one of the showcase's bots with one click.
        bots_joinable: true,
        // People play it: its truth is shown late, as in any match with people.
        spectator_delay_ticks: delay,
        // Its delay's worth of play is made at once, so that a visitor watches it move from
        // the first second (about 0.3 s of computing for 30 s of play).
        head_start_ticks: head_start,
        difficulty: None,
        rated: false,
    };
    if !priced {
        return Ok(registry.start(world, meta).id);
    }
    let price = {
        let maps = registry.maps.read().unwrap_or_else(|e| e.into_inner());
        let def = &maps.get(&meta.map).ok_or(NoShowcase::NoMap)?.arena.def;
        admission::held_back(&world.config, delay) + admission::match_on(def, &world.config)
    };
    Ok(registry
        .try_start(world, meta, Owner::default(), price)
        .map_err(NoShowcase::NoRoom)?
        .id)
}

/// Why no showcase started.
#[derive(Debug, thiserror::Error)]
pub enum NoShowcase {
    #[error("the server has no map to run a showcase on")]
    NoMap,
    #[error(transparent)]
    NoRoom(NoRoom),
}

/// Most showcases at once. One more starts when every running one is full (the keeper
/// checks every 2 s, and a visitor's join-or-create at once), within the server's budget
/// like any match: with `--max-seats-per-address` 2 and five bots each, 40 addresses must
/// hold seats before a visitor finds none.
pub const MAX_SHOWCASES: usize = 16;

/// How a showcase's id begins.
pub const SHOWCASE_PREFIX: &str = "showcase-";

/// One showcase the keeper started, and when spectators saw it end.
struct Round {
    id: String,
    finished_at: Option<tokio::time::Instant>,
}

/// The showcases running now (not those started by a person, which have an owner).
fn showcases(registry: &Registry) -> Vec<MatchHandle> {
    registry
        .all()
        .into_iter()
        .filter(|h| h.id.starts_with(SHOWCASE_PREFIX) && h.owner.token.is_none())
        .collect()
}

/// Whether spectators have seen the showcase end, and its free slots.
fn state_of(h: &MatchHandle) -> (bool, usize) {
    (
        h.hub.spectate.borrow().status == MatchStatus::Finished,
        h.hub.summary.borrow().meta.free_slots,
    )
}

/// Keeps one showcase match running for as long as the server runs, and another beside it
/// while every running one is full (people hold all its slots), up to [`MAX_SHOWCASES`].
/// It also ends, once seen, the ones [`join_or_create`] started.
pub async fn keep_running(registry: Arc<Registry>) {
    // The showcases a restart resumed carry on; a new one starts only when none did.
    let mut rounds: Vec<Round> = Vec::new();
    adopt(&registry, &mut rounds);
    if rounds.is_empty() {
        match start(&registry, false).await {
            Ok(first) => rounds.push(Round {
                id: first,
                finished_at: None,
            }),
            Err(e) => {
                tracing::warn!("no showcase: {e}");
                return;
            }
        }
    }
    loop {
        tokio::time::sleep(Duration::from_secs(2)).await;
        if registry.draining.is_cancelled() {
            return; // no new showcase while the server drains or stops
        }
        adopt(&registry, &mut rounds);
        let now = tokio::time::Instant::now();
        let mut full = 0;
        for r in &mut rounds {
            let (finished, free) = match registry.get(&r.id) {
                // Finished as spectators see it: they watch the end before the next round.
                Some(h) => state_of(&h),
                None => (true, 0), // deleted by someone: bring it back
            };
            if finished {
                r.finished_at.get_or_insert(now);
            } else if free == 0 {
                full += 1;
            }
        }
        // Ended ones go once their end has been seen.
        let mut gone = Vec::new();
        rounds.retain(|r| {
            let stay = r.finished_at.is_none_or(|t| now - t < LINGER);
            if !stay {
                gone.push(r.id.clone());
            }
            stay
        });
        for id in gone {
            registry.remove(&id).await;
        }
        if registry.draining.is_cancelled() {
            return;
        }
        let running = rounds.iter().filter(|r| r.finished_at.is_none()).count();
        // A fresh round when none runs or lingers; another beside the running ones when
        // all are full.
        let wanted = rounds.is_empty() || (running > 0 && full == running);
        if wanted && rounds.len() < MAX_SHOWCASES {
            let _one = registry.showcase_starting.lock().await;
            match start(&registry, !rounds.is_empty()).await {
                Ok(id) => rounds.push(Round {
                    id,
                    finished_at: None,
                }),
                Err(NoShowcase::NoMap) => return,
                // The server is full: the next round tries again.
                Err(NoShowcase::NoRoom(e)) => tracing::info!("no room for another showcase: {e}"),
            }
        }
    }
}

/// Takes into `rounds` the showcases it does not know (resumed ones, and those
/// [`join_or_create`] started).
fn adopt(registry: &Registry, rounds: &mut Vec<Round>) {
    for h in showcases(registry) {
        if !rounds.iter().any(|r| r.id == h.id) {
            rounds.push(Round {
                id: h.id,
                finished_at: None,
            });
        }
    }
}

/// Why a visitor found no showcase seat.
#[derive(Debug, thiserror::Error)]
pub enum NoSeat {
    #[error(transparent)]
    Join(#[from] MatchError),
    #[error(transparent)]
    NoShowcase(#[from] NoShowcase),
    #[error("every showcase's seats are taken ({MAX_SHOWCASES} showcases run); try again shortly")]
    AllFull,
}

/// Seats `name` in a running showcase with a free slot (the one with most free slots
/// first), or, when every one is full, in one more started for it (join-or-create, as
/// Colyseus's `joinOrCreate` does): a visitor finds a seat while the server has room, however
/// many addresses hold the others. Answers the showcase's id and the seat.
pub async fn join_or_create(
    registry: &Registry,
    name: JoinName,
    client: ClientKey,
) -> Result<(String, Joined), NoSeat> {
    if let Some(seated) = join_any(registry, &name, client).await? {
        return Ok(seated);
    }
    // One start at a time: visitors who found every seat taken together share the one
    // that starts, rather than each starting their own.
    let _one = registry.showcase_starting.lock().await;
    if let Some(seated) = join_any(registry, &name, client).await? {
        return Ok(seated);
    }
    let running = showcases(registry)
        .iter()
        .filter(|h| !state_of(h).0)
        .count();
    if running >= MAX_SHOWCASES {
        return Err(NoSeat::AllFull);
    }
    let id = start(registry, running > 0).await?;
    let handle = registry
        .get(&id)
        .ok_or_else(|| MatchError::Gone(id.clone()))?;
    let joined = handle.join(name, Team::Opponents, Some(client)).await?;
    Ok((id, joined))
}

/// Seats `name` in the first running showcase that takes it, most free slots first; `None`
/// when every one is full (or ended while asked).
async fn join_any(
    registry: &Registry,
    name: &JoinName,
    client: ClientKey,
) -> Result<Option<(String, Joined)>, MatchError> {
    let mut open: Vec<(usize, MatchHandle)> = showcases(registry)
        .into_iter()
        .filter_map(|h| {
            let (finished, free) = state_of(&h);
            (!finished && free > 0).then_some((free, h))
        })
        .collect();
    open.sort_by_key(|(free, _)| std::cmp::Reverse(*free));
    for (_, h) in open {
        match h.join(name.clone(), Team::Opponents, Some(client)).await {
            Ok(joined) => return Ok(Some((h.id.clone(), joined))),
            Err(MatchError::Full(_) | MatchError::Finished(_) | MatchError::Gone(_)) => continue,
            Err(e) => return Err(e),
        }
    }
    Ok(None)
}
