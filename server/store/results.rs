//! What each person did in a match, read from its events: the statistics people expect from
//! a game (matches, wins, tags, longest survival), per player name.
//!
//! Names are not accounts: anyone may play as any name, and a name's totals are those of
//! everyone who used it.

use lasertag_core::sim::AgentId;
use lasertag_core::world::{EventKind, Side, World};

/// One name's part in one match.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlayerResult {
    pub name: String,
    /// Robots they tagged.
    pub tags: u32,
    /// Their longest stay in the match without being tagged (ticks): from taking a slot to
    /// being tagged, leaving, or the end.
    pub survived_ticks: u64,
    /// Whether the opponents won with them still in the match.
    pub won: bool,
}

/// Each name that played `world` (which has ended), in the order they first joined.
pub fn of(world: &World) -> Vec<PlayerResult> {
    let mut results: Vec<PlayerResult> = Vec::new();
    // The name in each slot now, and since when.
    let mut seated: Vec<Option<(String, u64)>> = vec![None; world.opponents.len()];
    let close = |results: &mut Vec<PlayerResult>, name: &str, from: u64, to: u64| {
        if let Some(r) = results.iter_mut().find(|r| r.name == name) {
            r.survived_ticks = r.survived_ticks.max(to.saturating_sub(from));
        }
    };
    let mut winner = None;
    for e in world.events() {
        match &e.kind {
            EventKind::PlayerJoined {
                opponent: AgentId::Opponent(slot),
                name,
            } => {
                if !results.iter().any(|r| &r.name == name) {
                    results.push(PlayerResult {
                        name: name.clone(),
                        tags: 0,
                        survived_ticks: 0,
                        won: false,
                    });
                }
                if let Some(s) = seated.get_mut(*slot) {
                    *s = Some((name.clone(), e.tick));
                }
            }
            EventKind::PlayerLeft {
                opponent: AgentId::Opponent(slot),
                ..
            }
            | EventKind::Tag {
                target: AgentId::Opponent(slot),
                ..
            } => {
                if let Some((name, from)) = seated.get_mut(*slot).and_then(Option::take) {
                    close(&mut results, &name, from, e.tick);
                }
            }
            EventKind::RobotTagged {
                by: AgentId::Opponent(slot),
                ..
            } => {
                if let Some(Some((name, _))) = seated.get(*slot)
                    && let Some(r) = results.iter_mut().find(|r| &r.name == name)
                {
                    r.tags += 1;
                }
            }
            EventKind::Finished { winner: w, .. } => winner = *w,
            _ => {}
        }
    }
    for (name, from) in seated.into_iter().flatten() {
        close(&mut results, &name, from, world.tick);
        if winner == Some(Side::Opponents)
            && let Some(r) = results.iter_mut().find(|r| r.name == name)
        {
            r.won = true;
        }
    }
    results
}
