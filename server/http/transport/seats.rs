//! The WebTransport sessions a server carries (`--max-webtransport-sessions`), players
//! first: datagrams matter most to a person playing on a bad link, least to a spectator, who
//! loses nothing on the WebSocket but some smoothness. So a player's session is taken while
//! any spectator holds one: the spectator who came last is told to move (its socket closes as
//! the server's going away would close it, and its page, finding WebTransport full, comes
//! back over its WebSocket), and the player takes its place. A spectator's session is
//! refused once every session is taken; a player's only when players hold them all.

use std::sync::{Arc, Mutex};

use tokio_util::sync::CancellationToken;

/// Who a session is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Player,
    Spectator,
}

impl Kind {
    /// The kind of a socket of this metrics role (`player`, `spectator`, `replay`).
    pub fn of_role(role: &str) -> Kind {
        if role == "player" {
            Kind::Player
        } else {
            Kind::Spectator
        }
    }
}

/// The sessions held, by kind.
#[derive(Debug)]
pub struct Seats {
    cap: usize,
    held: Mutex<Held>,
}

#[derive(Debug, Default)]
struct Held {
    players: usize,
    /// Spectators' sessions, the latest last: each with the token that moves it.
    spectators: Vec<(u64, CancellationToken)>,
    next_id: u64,
}

/// One session's place, given back when it ends.
#[derive(Debug)]
pub struct Seat {
    seats: Arc<Seats>,
    kind: Kind,
    id: u64,
    /// Cancelled when the session must end: the server stops, or (a spectator's) a player
    /// needs its place.
    pub ends: CancellationToken,
}

/// Why a session was not given a place.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "the server carries {cap} WebTransport sessions and holds them all{}; use the WebSocket",
    if *.players { " for players" } else { "" }
)]
pub struct Full {
    pub cap: usize,
    pub players: bool,
}

impl Seats {
    pub fn new(cap: usize) -> Arc<Seats> {
        Arc::new(Seats {
            cap,
            held: Mutex::default(),
        })
    }

    /// A place for a session of `kind`, its end tied to `shutdown`; for a player, a
    /// spectator's when all are held (that spectator is moved).
    pub fn take(self: &Arc<Self>, kind: Kind, shutdown: &CancellationToken) -> Result<Seat, Full> {
        let mut held = self.held.lock().unwrap_or_else(|e| e.into_inner());
        if held.players + held.spectators.len() >= self.cap {
            match kind {
                Kind::Player => match held.spectators.pop() {
                    Some((_, moved)) => moved.cancel(),
                    None => {
                        return Err(Full {
                            cap: self.cap,
                            players: true,
                        });
                    }
                },
                Kind::Spectator => {
                    return Err(Full {
                        cap: self.cap,
                        players: false,
                    });
                }
            }
        }
        let id = held.next_id;
        held.next_id += 1;
        let ends = shutdown.child_token();
        match kind {
            Kind::Player => held.players += 1,
            Kind::Spectator => held.spectators.push((id, ends.clone())),
        }
        Ok(Seat {
            seats: self.clone(),
            kind,
            id,
            ends,
        })
    }

    /// Sessions held now: (players, spectators).
    pub fn held(&self) -> (usize, usize) {
        let held = self.held.lock().unwrap_or_else(|e| e.into_inner());
        (held.players, held.spectators.len())
    }
}

impl Drop for Seat {
    fn drop(&mut self) {
        let mut held = self.seats.held.lock().unwrap_or_else(|e| e.into_inner());
        match self.kind {
            Kind::Player => held.players = held.players.saturating_sub(1),
            // A moved spectator left the list when it was moved.
            Kind::Spectator => held.spectators.retain(|(id, _)| *id != self.id),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn players_take_spectators_places_and_spectators_wait_for_room() {
        let seats = Seats::new(2);
        let stop = CancellationToken::new();
        let first = seats.take(Kind::Spectator, &stop).expect("room");
        let second = seats.take(Kind::Spectator, &stop).expect("room");
        assert!(seats.take(Kind::Spectator, &stop).is_err(), "full");
        // A player moves the spectator who came last.
        let p1 = seats
            .take(Kind::Player, &stop)
            .expect("a spectator's place");
        assert!(second.ends.is_cancelled() && !first.ends.is_cancelled());
        assert_eq!(seats.held(), (1, 1));
        drop(second);
        assert_eq!(seats.held(), (1, 1), "a moved spectator was already out");
        let _p2 = seats.take(Kind::Player, &stop).expect("the other's");
        assert!(first.ends.is_cancelled());
        // Players hold them all: the next player is refused.
        assert_eq!(
            seats.take(Kind::Player, &stop).unwrap_err(),
            Full {
                cap: 2,
                players: true
            }
        );
        drop(first);
        drop(p1);
        assert_eq!(seats.held(), (1, 0));
        let s = seats.take(Kind::Spectator, &stop).expect("room again");
        // The server's shutdown ends every session.
        stop.cancel();
        assert!(s.ends.is_cancelled());
    }
}
