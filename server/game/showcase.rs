//! The showcase: a real-time match that is always running, so that anyone who opens the
//! server sees play at once. When it ends, a fresh one (new seed) starts a few seconds later.
//! People may take its bots, so its seed is secret, drawn from the operating system's random
//! source (see `view::people_may_play`). It starts its spectators' delay in the past (its
//! first 30 s of play run at once, on a seed whose robots tag nobody in them), so that its
//! delayed view moves from the first second.
//! While people hold every slot of every running showcase, another starts beside them (at
//! most [`MAX_SHOWCASES`]), so that a visitor always finds a free one.

use std::sync::Arc;
use std::time::Duration;

use crate::game::view::{Clock, MatchMeta};
use crate::game::{Registry, random_id, random_seed};
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

async fn start(registry: &Registry) -> Option<String> {
    let arena = {
        let maps = registry.maps.read().unwrap_or_else(|e| e.into_inner());
        maps.get(SHOWCASE_MAP)
            .or_else(|| maps.iter().next())?
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
                while probe.tick < tick && probe.status == MatchStatus::Running {
                    probe.step();
                }
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
    .ok()??;
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
    Some(registry.start(world, meta).id)
}

/// Most showcases at once: each one more starts only when every running one has no free
/// slot, so a few addresses holding seats (at most `--max-seats-per-address` each) cannot
/// lock a visitor out unless they fill them all.
pub const MAX_SHOWCASES: usize = 6;

/// How a showcase's id begins.
const SHOWCASE_PREFIX: &str = "showcase-";

/// One showcase the keeper started, and when spectators saw it end.
struct Round {
    id: String,
    finished_at: Option<tokio::time::Instant>,
}

/// Keeps one showcase match running for as long as the server runs, and another beside it
/// while every running one is full (people hold all its slots), up to [`MAX_SHOWCASES`].
pub async fn keep_running(registry: Arc<Registry>) {
    // The showcases a restart resumed carry on; a new one starts only when none did.
    let mut rounds: Vec<Round> = registry
        .all()
        .into_iter()
        .filter(|h| h.id.starts_with(SHOWCASE_PREFIX) && h.owner.token.is_none())
        .map(|h| Round {
            id: h.id,
            finished_at: None,
        })
        .collect();
    if rounds.is_empty() {
        let Some(first) = start(&registry).await else {
            tracing::warn!("no map to run a showcase match on");
            return;
        };
        rounds.push(Round {
            id: first,
            finished_at: None,
        });
    }
    loop {
        tokio::time::sleep(Duration::from_secs(2)).await;
        if registry.draining.is_cancelled() {
            return; // no new showcase while the server drains or stops
        }
        let now = tokio::time::Instant::now();
        let mut full = 0;
        for r in &mut rounds {
            let (finished, free) = match registry.get(&r.id) {
                // Finished as spectators see it: they watch the end before the next round.
                Some(h) => (
                    h.hub.spectate.borrow().status == MatchStatus::Finished,
                    h.hub.summary.borrow().meta.free_slots,
                ),
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
            match start(&registry).await {
                Some(id) => rounds.push(Round {
                    id,
                    finished_at: None,
                }),
                None => return,
            }
        }
    }
}
