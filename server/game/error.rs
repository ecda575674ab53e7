//! [`MatchError`]: why a match refused a request, in the game's words.

use lasertag_core::world::InputError;

/// Why a match refused a request (`http` turns each into a status).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MatchError {
    /// A change from outside the world refused (an unknown agent, an order it cannot take).
    #[error(transparent)]
    Input(#[from] InputError),
    /// A robot index the match does not have.
    #[error("{0}")]
    NoRobot(String),
    /// A request the match cannot take as it is (a name it cannot seat, …).
    #[error("{0}")]
    Invalid(String),
    /// Stepping asked of a match that runs in real time.
    #[error("match {id} runs in real time; {what} works only on manual-clock matches")]
    Realtime { id: String, what: &'static str },
    /// A step asked while another is running.
    #[error("match {0} is already stepping")]
    Stepping(String),
    #[error("match {0} has finished")]
    Finished(String),
    /// Every seat a person could take is taken (or the server's per-match limit is met).
    #[error("{0}")]
    Full(String),
    /// The asking client holds as much of the match as it may.
    #[error("{0}")]
    Quota(String),
    /// A token that names no player of the match.
    #[error("{0}")]
    NotAPlayer(String),
    #[error("match {0} has ended")]
    Gone(String),
    /// The match has recorded as many orders from outside as it may.
    #[error(transparent)]
    RecordingFull(#[from] crate::game::record::RecordingFull),
    /// The client's share of the server's path-search work is taken for now.
    #[error(
        "{client} has used its share of this server's path search for robots' waypoints ({rate} units a second); try again in {wait_s:.1} s, or give fewer waypoints"
    )]
    WorkShare {
        client: crate::access::ClientKey,
        rate: u64,
        wait_s: f64,
    },
    /// The server's path-search work is taken for now.
    #[error(
        "this server's path search for robots' waypoints ({rate} units a second) is taken; try again in {wait_s:.1} s"
    )]
    WorkBusy { rate: u64, wait_s: f64 },
}
