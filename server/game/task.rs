//! The task that owns one match's [`World`].

use std::time::Duration;

use tokio::sync::mpsc;
use tokio::time::MissedTickBehavior;
use tracing::Instrument;

use crate::game::{MatchError, Request, random_id};
use crate::protocol::{self, Clock, Joined, MatchMeta, MatchState};
use crate::sim::world::Control;
use crate::sim::{MatchStatus, TICK_HZ, World};

/// Ticks a manual step runs before it lets other requests in.
const STEP_CHUNK: u64 = 250;

/// A person holding an opponent slot.
#[derive(Debug, Clone)]
struct Player {
    id: String,
    name: String,
    token: String,
}

struct PendingStep {
    remaining: u64,
    reply: tokio::sync::oneshot::Sender<Result<MatchState, MatchError>>,
}

/// Spawns the task for `world` and returns the channel to it. The task ends when the match is
/// stopped or every handle is dropped.
pub fn spawn_match(world: World, meta: MatchMeta) -> mpsc::Sender<Request> {
    let (tx, rx) = mpsc::channel(64);
    let span = tracing::info_span!("match", id = %meta.id);
    tokio::spawn(run(world, meta, rx).instrument(span));
    tx
}

async fn run(mut world: World, mut meta: MatchMeta, mut rx: mpsc::Receiver<Request>) {
    tracing::info!(map = %meta.map, clock = ?meta.clock, "match started");
    let realtime = meta.clock == Clock::Realtime;
    let mut interval = tokio::time::interval(Duration::from_millis(1000 / TICK_HZ as u64));
    // A match that overran its tick (a loaded machine) skips the missed ticks rather than
    // bursting to catch up: the world must not fast-forward under the players' feet.
    interval.set_missed_tick_behavior(MissedTickBehavior::Skip);
    let mut players: Vec<Option<Player>> = vec![None; world.opponents.len()];
    let mut pending: Option<PendingStep> = None;
    loop {
        let running = world.status == MatchStatus::Running;
        tokio::select! {
            biased;
            req = rx.recv() => {
                let Some(req) = req else { break };
                match req {
                    Request::Stop => {
                        world.stop();
                        break;
                    }
                    Request::Summary(reply) => {
                        meta.players = players.iter().flatten().count();
                        let _ = reply.send(protocol::summary(&world, &meta));
                    }
                    Request::State(reply) => { let _ = reply.send(protocol::state(&world, &meta)); }
                    Request::Belief(reply) => { let _ = reply.send(protocol::belief(&world)); }
                    Request::Events { since, reply } => {
                        let events = world.events_since(since).iter().map(protocol::event).collect();
                        let _ = reply.send(protocol::Events { events });
                    }
                    Request::Step { ticks, reply } => {
                        if realtime {
                            let _ = reply.send(Err(MatchError::Conflict(format!(
                                "match {} runs in real time; step works only on manual-clock matches", meta.id
                            ))));
                        } else if pending.is_some() {
                            let _ = reply.send(Err(MatchError::Conflict(format!(
                                "match {} is already stepping", meta.id
                            ))));
                        } else {
                            pending = Some(PendingStep { remaining: ticks, reply });
                        }
                    }
                    Request::Order { opponent, order, reply } => {
                        let result = opponent_index(&opponent, world.opponents.len())
                            .ok_or_else(|| MatchError::NotFound(format!("no opponent {opponent} in match {}", meta.id)))
                            .and_then(|i| world.order_opponent(i, order).map_err(|e| match e {
                                crate::sim::world::OrderError::UnknownOpponent(_) => MatchError::NotFound(e.to_string()),
                                crate::sim::world::OrderError::OutsideArena { .. } => MatchError::BadRequest(e.to_string()),
                                _ => MatchError::Conflict(e.to_string()),
                            }));
                        let _ = reply.send(result);
                    }
                    Request::Join { name, reply } => {
                        let _ = reply.send(join(&mut world, &mut players, name, &meta.id));
                    }
                }
            }
            _ = interval.tick(), if realtime && running => {
                world.step();
                if world.status == MatchStatus::Finished {
                    tracing::info!(tick = world.tick, winner = ?world.winner, "match finished");
                }
            }
            _ = std::future::ready(()), if pending.is_some() => {
                if let Some(mut step) = pending.take() {
                    let n = step.remaining.min(STEP_CHUNK);
                    for _ in 0..n {
                        world.step();
                        if world.status == MatchStatus::Finished {
                            break;
                        }
                    }
                    step.remaining -= n;
                    if step.remaining == 0 || world.status == MatchStatus::Finished {
                        let _ = step.reply.send(Ok(protocol::state(&world, &meta)));
                    } else {
                        pending = Some(step);
                        tokio::task::yield_now().await;
                    }
                }
            }
        }
    }
    tracing::info!(tick = world.tick, "match ended");
}

/// `o3` → 3, when that opponent exists.
fn opponent_index(id: &str, count: usize) -> Option<usize> {
    let n: usize = id.strip_prefix('o')?.parse().ok()?;
    (n < count && id == format!("o{n}")).then_some(n)
}

fn join(
    world: &mut World,
    players: &mut [Option<Player>],
    name: String,
    id: &str,
) -> Result<Joined, MatchError> {
    let name = name.trim().to_string();
    if name.is_empty() || name.chars().count() > 32 || name.chars().any(char::is_control) {
        return Err(MatchError::BadRequest(
            "name: must be 1 to 32 printable characters".into(),
        ));
    }
    if world.status == MatchStatus::Finished {
        return Err(MatchError::Conflict(format!("match {id} has finished")));
    }
    let slot = world
        .opponents
        .iter()
        .enumerate()
        .position(|(i, o)| {
            !o.tagged && matches!(o.control, Control::Human(_)) && players[i].is_none()
        })
        .ok_or_else(|| MatchError::Conflict(format!("match {id} has no free opponent slot")))?;
    let player = Player {
        id: random_id(8),
        name: name.clone(),
        token: random_id(24),
    };
    tracing::info!(player = %player.name, slot, "player joined");
    players[slot] = Some(player.clone());
    world.log_player(slot, name, true);
    Ok(Joined {
        player_id: player.id,
        opponent_id: format!("o{slot}"),
        token: player.token,
    })
}
