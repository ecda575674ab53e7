//! What a replay socket sends for one tick: the snapshot the live sockets sent (a
//! spectator's, or a player's fogged view), with the belief when it is due and the events
//! since the last one. Pure and blocking: it runs in the connection's jobs, off the async
//! workers, on the world a [`crate::game::replay::Cursor`] is at.

use axum::extract::ws::Message;

use crate::game::replay::Replay;
use crate::game::view::{BELIEF_EVERY, Frame, SeatView, SeatViews, visible_to};
use crate::http::socket::schedule::due;
use crate::protocol::{compact, ws as wire};
use lasertag_core::sim::AgentId;
use lasertag_core::world::{EventKind, MatchStatus, World};

/// How one snapshot is to be made: everything a blocking job needs to know.
#[derive(Debug, Clone, Copy)]
pub struct Show {
    /// The player whose view is shown (an opponent, or a robot a person drove), or everything.
    pub view: Option<AgentId>,
    pub compact: bool,
    /// Whether the belief is switched on, and the tick of the last snapshot that carried it.
    pub belief: bool,
    pub belief_at: Option<u64>,
    /// Send the belief whatever its age (a seek: the page must show that tick's).
    pub fresh: bool,
    /// Events after this `seq` go out with the snapshot (none after a seek).
    pub events_after: Option<u64>,
}

/// A snapshot and what goes with it, made off the async workers.
pub struct Shown {
    pub tick: u64,
    pub messages: Vec<Message>,
    pub last_seq: u64,
    pub belief_at: Option<u64>,
    /// No tick follows this one.
    pub at_end: bool,
}

/// The people seated at `world`'s opponents and robots, from its joins and leaves (frames
/// show their names as the live ones did).
pub fn seats(world: &World) -> SeatViews {
    let mut seats = SeatViews {
        opponents: vec![None; world.opponents.len()],
        robots: vec![None; world.robots.len()],
    };
    for e in world.events() {
        let (agent, view) = match &e.kind {
            EventKind::PlayerJoined { agent, name } => (
                agent,
                Some(SeatView {
                    name: name.as_str().into(),
                    connected: true,
                    ack: 0,
                }),
            ),
            EventKind::PlayerLeft { agent, .. } => (agent, None),
            _ => continue,
        };
        let place = match agent {
            AgentId::Opponent(i) => seats.opponents.get_mut(*i),
            AgentId::Robot(i) => seats.robots.get_mut(*i),
        };
        if let Some(place) = place {
            *place = view;
        }
    }
    seats
}

/// Whether a replay can go on past `world`.
pub fn at_end(replay: &Replay, world: &World) -> bool {
    world.tick >= replay.last_tick || world.status == MatchStatus::Finished
}

/// The snapshot of `world` as `show` asks, and its events.
pub fn show(replay: &Replay, world: &World, show: Show) -> Shown {
    let tick = world.tick;
    let belief = show.belief
        && due(
            show.belief_at,
            tick,
            BELIEF_EVERY,
            show.fresh || at_end(replay, world),
        );
    let all = world.events().len() as u64;
    let since = show.events_after.unwrap_or(all).min(all);
    let robot_tags = world.events()[..since as usize]
        .iter()
        .filter(|e| matches!(e.kind, EventKind::RobotTagged { .. }))
        .count() as u32;
    let frame = Frame::build(world, &seats(world), since, robot_tags, belief);
    let visible = show
        .view
        .and_then(|you| visible_to(&frame, &world.arena, you).map(|v| (you, v)));
    let snapshot = match (&visible, show.compact) {
        (None, false) => Message::Text(wire::spectator_snapshot(&frame, belief)),
        (None, true) => Message::Binary(wire::spectator_compact(&frame, belief, true)),
        (Some((you, v)), false) => Message::Text(wire::player_snapshot(
            &frame,
            *you,
            v,
            belief.then_some(&frame),
        )),
        (Some((you, v)), true) => {
            let own = frame.own_belief(*you);
            let belief = own.or(frame.belief.as_deref()).filter(|_| belief);
            Message::Binary(compact::snapshot(&frame, Some(*you), Some(v), belief, false).into())
        }
    };
    let mut messages = vec![snapshot];
    messages.extend(frame.events.iter().map(|e| Message::Text(wire::event(e))));
    Shown {
        tick,
        messages,
        last_seq: all,
        belief_at: if belief { Some(tick) } else { show.belief_at },
        at_end: at_end(replay, world),
    }
}
