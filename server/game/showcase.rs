//! The showcase: a real-time match that is always running, so that anyone who opens the
//! server sees play at once. When it ends, a fresh one (new seed) starts a few seconds later.

use std::sync::Arc;
use std::time::Duration;

use crate::game::view::{Clock, MatchMeta};
use crate::game::{Registry, random_id};
use lasertag_core::bots::BotKind;
use lasertag_core::planner::PlannerKind;
use lasertag_core::sim::TICK_HZ;
use lasertag_core::world::{ControlKind, MatchConfig};
use lasertag_core::world::{MatchStatus, World};

/// Preferred map of the showcase, when the server has it; otherwise the first map.
const SHOWCASE_MAP: &str = "office";
/// How long a finished showcase stays up (so its end can be seen) before the next starts.
const LINGER: Duration = Duration::from_secs(10);

async fn start(registry: &Registry, round: u64) -> Option<String> {
    let arena = {
        let maps = registry.maps.read().unwrap_or_else(|e| e.into_inner());
        maps.get(SHOWCASE_MAP)
            .or_else(|| maps.iter().next())?
            .arena
            .clone()
    };
    let config = MatchConfig {
        robots: 2,
        // Three bots that run from the robots: a match that lasts long enough to watch, and
        // a belief that splits into several roles.
        opponents: 3,
        opponent_control: ControlKind::Bot,
        opponent_bot: BotKind::Evade,
        planner: PlannerKind::Coordinated,
        seed: round,
        ..MatchConfig::default()
    };
    let map = arena.def.name.clone();
    // Off the async workers: the planner's views of a map take tens of milliseconds to build.
    let world = tokio::task::spawn_blocking(move || World::new(arena, config))
        .await
        .ok()?
        .ok()?;
    let meta = MatchMeta {
        // As long as any match's id: the history (shared by a fleet) keeps every showcase.
        id: format!("showcase-{}", random_id(8)),
        map,
        clock: Clock::Realtime,
        players: 0,
        spectators: 0,
        free_slots: 0,
        // Anyone who opens the server can take one of the showcase's bots with one click.
        bots_joinable: true,
        // People play it: its truth is shown late, as in any match with people.
        spectator_delay_ticks: (crate::game::delay::SPECTATOR_DELAY_S * TICK_HZ as f64) as u64,
    };
    Some(registry.start(world, meta).id)
}

/// Keeps one showcase match running for as long as the server runs.
pub async fn keep_running(registry: Arc<Registry>) {
    let mut round = 0;
    let Some(mut id) = start(&registry, round).await else {
        tracing::warn!("no map to run a showcase match on");
        return;
    };
    loop {
        tokio::time::sleep(Duration::from_secs(2)).await;
        if registry.draining.is_cancelled() {
            return; // no new showcase while the server drains or stops
        }
        let finished = match registry.get(&id) {
            // Finished as spectators see it: they watch the end before the next round.
            Some(h) => h.hub.spectate.borrow().status == MatchStatus::Finished,
            None => true, // deleted by someone: bring it back
        };
        if finished {
            tokio::time::sleep(LINGER).await;
            registry.remove(&id).await;
            if registry.draining.is_cancelled() {
                return;
            }
            round += 1;
            match start(&registry, round).await {
                Some(new) => id = new,
                None => return,
            }
        }
    }
}
