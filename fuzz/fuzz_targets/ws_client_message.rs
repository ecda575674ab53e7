//! WebSocket client messages: bytes → `ClientMessage::parse`, the decoder `http::ws` runs on
//! every text message (after the size and rate checks, which do not look inside).
//!
//! Besides "no panic", it checks the decoder's promise: whatever it accepts is in range.
#![no_main]

use lasertag::protocol::ws::ClientMessage;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    // Text frames are UTF-8 by the WebSocket protocol (tungstenite checks it before axum hands
    // them over); binary frames are refused without decoding.
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    match ClientMessage::parse(text) {
        Ok(ClientMessage::Input { forward, turn, .. }) => {
            assert!(forward.is_finite() && (-1.0..=1.0).contains(&forward));
            assert!(turn.is_finite() && (-1.0..=1.0).contains(&turn));
        }
        Ok(ClientMessage::Ping { t }) => assert!(t.is_finite()),
        Ok(ClientMessage::Belief { .. }) => {}
        Err(e) => assert!(!e.is_empty()),
    }
});
