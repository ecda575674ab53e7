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
}
