//! Parties: people who gather in a waiting room before they play together. A room has a
//! short code (what a friend types or scans), a host who chooses the match, members who
//! choose a side and say they are ready, and a socket per member that is told whenever the
//! room changes and, when the host starts, which seat is theirs. After the match the room is
//! waiting again with the same people and sides (a rematch is one click).
//!
//! Rooms live here, in memory, and in the store as one document each
//! (`store::codec::PartyRecord`), written on every change: a restart finds them again with
//! their members' tokens (kept only as hashes). A room nobody is connected to lapses after
//! [`LAPSE`] (not while its match runs).

mod room;
mod rooms;
#[cfg(test)]
mod tests;

pub use room::{
    CODE_ALPHABET, CODE_LEN, LAPSE, MAX_MEMBERS, MINUTES, Member, Party, PartySettings,
    normalise_code, side_name, side_of,
};
pub use rooms::{Change, Parties, PartyError, RoomView, Started};
