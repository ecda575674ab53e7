//! Why a socket ends, and the close code that says so to the client.

/// Close codes (RFC 6455 and IANA's registry): normal, going away, policy violation, message
/// too big, internal error, service restart.
const NORMAL: u16 = 1000;
const GOING_AWAY: u16 = 1001;
const POLICY: u16 = 1008;
pub(super) const TOO_BIG: u16 = 1009;
const INTERNAL: u16 = 1011;
const RESTART: u16 = 1012;

/// Why a connection ends.
#[derive(Debug)]
pub enum End {
    /// The client left or the socket failed: nothing more to send.
    Gone,
    /// Close with this code and reason.
    Close(u16, String),
}

impl End {
    /// The client broke a rule (1008).
    pub fn policy(reason: impl Into<String>) -> End {
        End::Close(POLICY, reason.into())
    }

    /// What the socket showed has ended (1000).
    pub fn normal(reason: impl Into<String>) -> End {
        End::Close(NORMAL, reason.into())
    }

    /// The server is shutting down (1001).
    pub fn going_away() -> End {
        End::Close(GOING_AWAY, "the server is shutting down".into())
    }

    /// A player needed this spectator's WebTransport session: come back (1012, as after a
    /// restart), and the page, finding WebTransport full, does so over its WebSocket.
    pub fn moved_off_webtransport() -> End {
        End::Close(
            RESTART,
            "a player needed this WebTransport session; reconnect over the WebSocket".into(),
        )
    }

    /// The server is stopping, and the next one resumes the match: come back (1012).
    pub fn restarting() -> End {
        End::Close(
            RESTART,
            "the server is restarting; the match goes on: reconnect".into(),
        )
    }

    /// The server failed at what the socket needed (1011).
    pub fn internal(reason: impl Into<String>) -> End {
        End::Close(INTERNAL, reason.into())
    }
}
