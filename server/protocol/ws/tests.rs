//! Unit tests of the WebSocket messages: parsing, and what players are told.

use super::*;

#[test]
fn the_robot_team_is_told_of_an_opponents_shot_without_who_fired() {
    use lasertag_core::world::EventKind;
    let shot = Event {
        seq: 3,
        tick: 40,
        kind: EventKind::Shot {
            by: AgentId::Opponent(1),
            hit: Some(AgentId::Robot(0)),
        },
    };
    let told = event_seen(&shot, true);
    assert!(told.as_str().contains(r#""by":"o?""#), "{}", told.as_str());
    assert!(told.as_str().contains(r#""hit":"r0""#), "{}", told.as_str());
    assert!(!told.as_str().contains("o1"), "{}", told.as_str());
    assert!(event_seen(&shot, false).as_str().contains(r#""by":"o1""#));
}

#[test]
fn client_messages_are_parsed_strictly() {
    assert_eq!(
        ClientMessage::parse(r#"{"type":"input","forward":1,"turn":-0.5,"tag":true}"#),
        Ok(ClientMessage::Input {
            forward: 1.0,
            turn: -0.5,
            tag: true,
            seq: None,
            view_tick: None,
        })
    );
    assert_eq!(
        ClientMessage::parse(r#"{"type":"input","forward":0,"turn":1,"seq":7}"#),
        Ok(ClientMessage::Input {
            forward: 0.0,
            turn: 1.0,
            tag: false,
            seq: Some(7),
            view_tick: None,
        })
    );
    assert_eq!(
        ClientMessage::parse(r#"{"type":"belief","on":true}"#),
        Ok(ClientMessage::Belief { on: true })
    );
    let e = ClientMessage::parse(r#"{"type":"input","forward":2,"turn":0}"#)
        .unwrap_err()
        .to_string();
    assert_eq!(e, "forward: 2 must be in -1..=1");
    let e = ClientMessage::parse(r#"{"type":"input","forward":0,"turn":0,"x":1}"#)
        .unwrap_err()
        .to_string();
    assert!(e.contains("unknown field `x`"), "{e}");
    let e = ClientMessage::parse(r#"{"type":"dance"}"#)
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("type: unknown message type"), "{e}");
    let e = ClientMessage::parse(r#"{"type":"input","forward":"fast","turn":0}"#)
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("forward"), "{e}");
    assert!(ClientMessage::parse("not json").is_err());
    assert!(ClientMessage::parse(r#"{"forward":0}"#).is_err());
}
