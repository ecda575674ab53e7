//! What each person did in a match, read from its events: the statistics people expect from
//! a game (matches, wins, tags, longest survival), per player name.
//!
//! Every name is read here; the match keeps the results of kept names only (their person
//! showed the claim's token: `game::task::people`), so a name's totals are its keeper's.

use lasertag_core::sim::AgentId;
use lasertag_core::world::{EventKind, Side, World};

/// One name's part in one match.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlayerResult {
    pub name: String,
    /// Agents of the other side they tagged: robots (as an opponent), opponents (on the
    /// robot team).
    pub tags: u32,
    /// Their longest stay in the match as an opponent without being tagged (ticks): from
    /// taking a slot to being tagged, leaving, or the end. Time on the robot team does not
    /// count (a robot is frozen, never removed).
    pub survived_ticks: u64,
    /// Whether their side won with them still in the match.
    pub won: bool,
    /// Whether this result moves the name's rating when the match is rated: the person
    /// showed the name's token and played (`game::task::people`). `of` leaves it false.
    pub rated: bool,
}

/// Each name that played `world` (which has ended), in the order they first joined.
pub fn of(world: &World) -> Vec<PlayerResult> {
    let mut results: Vec<PlayerResult> = Vec::new();
    // The name in each seat now, and since when.
    let mut seated: Vec<(AgentId, String, u64)> = Vec::new();
    let close =
        |results: &mut Vec<PlayerResult>, agent: AgentId, name: &str, from: u64, to: u64| {
            if let (AgentId::Opponent(_), Some(r)) =
                (agent, results.iter_mut().find(|r| r.name == name))
            {
                r.survived_ticks = r.survived_ticks.max(to.saturating_sub(from));
            }
        };
    let leave = |seated: &mut Vec<(AgentId, String, u64)>, agent: AgentId| {
        let at = seated.iter().position(|(a, ..)| *a == agent)?;
        Some(seated.remove(at))
    };
    let tagger = |seated: &[(AgentId, String, u64)], agent: &AgentId| {
        seated
            .iter()
            .find(|(a, ..)| a == agent)
            .map(|(_, n, _)| n.clone())
    };
    let mut winner = None;
    for e in world.events() {
        match &e.kind {
            EventKind::PlayerJoined { agent, name } => {
                if !results.iter().any(|r| &r.name == name) {
                    results.push(PlayerResult {
                        name: name.clone(),
                        tags: 0,
                        survived_ticks: 0,
                        won: false,
                        rated: false,
                    });
                }
                if let Some((a, n, from)) = leave(&mut seated, *agent) {
                    close(&mut results, a, &n, from, e.tick);
                }
                seated.push((*agent, name.clone(), e.tick));
            }
            EventKind::PlayerLeft { agent, .. }
            | EventKind::Tag {
                target: agent @ AgentId::Opponent(_),
                ..
            } => {
                if let Some((a, name, from)) = leave(&mut seated, *agent) {
                    close(&mut results, a, &name, from, e.tick);
                }
                if let EventKind::Tag { by, .. } = &e.kind
                    && let Some(name) = tagger(&seated, by)
                    && let Some(r) = results.iter_mut().find(|r| r.name == name)
                {
                    r.tags += 1;
                }
            }
            EventKind::RobotTagged { by, .. } => {
                if let Some(name) = tagger(&seated, by)
                    && let Some(r) = results.iter_mut().find(|r| r.name == name)
                {
                    r.tags += 1;
                }
            }
            EventKind::Finished { winner: w, .. } => winner = *w,
            _ => {}
        }
    }
    for (agent, name, from) in seated {
        close(&mut results, agent, &name, from, world.tick);
        let side = match agent {
            AgentId::Opponent(_) => Side::Opponents,
            AgentId::Robot(_) => Side::Robots,
        };
        if winner == Some(side)
            && let Some(r) = results.iter_mut().find(|r| r.name == name)
        {
            r.won = true;
        }
    }
    results
}

#[cfg(test)]
mod tests {
    use super::*;
    use lasertag_core::planner::PlannerKind;
    use lasertag_core::sim::arena::{Arena, MapDef};
    use lasertag_core::world::{ControlKind, MatchConfig, Placement, RobotOrder, WorldInput};
    use nalgebra::Point2;

    #[test]
    fn a_person_on_the_robot_team_is_credited_with_tags_and_the_robots_win() {
        let arena = Arena::new(MapDef {
            name: "room".into(),
            width: 10.0,
            height: 6.0,
            obstacles: vec![],
            robot_spawns: vec![[1.0, 1.0, 0.0]],
            opponent_spawns: vec![Point2::new(9.0, 5.0)],
            landmarks: vec![],
        });
        let config = MatchConfig {
            robots: 1,
            opponents: 1,
            pursuer_slots: 1,
            planner: PlannerKind::Idle,
            opponent_control: ControlKind::Api,
            placement: Placement::Given {
                robots: vec![[1.0, 3.0, 0.0]],
                opponents: vec![[4.0, 3.0]],
            },
            ..MatchConfig::default()
        };
        let mut world = World::new(std::sync::Arc::new(arena), config).unwrap();
        let name = "ada".to_string();
        world
            .apply(&WorldInput::SeatRobot { robot: 0, name })
            .unwrap();
        world.step();
        let fire = RobotOrder::Drive {
            forward: 0.0,
            turn: 0.0,
            tag: true,
        };
        world
            .apply(&WorldInput::Robot {
                robot: 0,
                order: fire,
            })
            .unwrap();
        world.step();
        assert_eq!(world.winner, Some(Side::Robots));
        let results = of(&world);
        assert_eq!(
            results,
            [PlayerResult {
                name: "ada".into(),
                tags: 1,
                survived_ticks: 0,
                won: true,
                rated: false,
            }]
        );
    }
}
