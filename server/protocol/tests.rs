//! Unit tests of the request shapes: defaults, ranges named by field, and the conversions
//! to the core's types.

use super::*;

#[test]
fn create_match_defaults_and_ranges() {
    let m: CreateMatch = parse(br#"{"map": "office"}"#).unwrap();
    let r = m.validate().unwrap();
    assert_eq!(r.config.robots, 2);
    assert_eq!(r.config.time_limit_ticks, 6000);
    assert_eq!(r.config.tracker.particles_per_role, 1000);
    let m: CreateMatch = parse(br#"{"map": "office", "robots": 9}"#).unwrap();
    assert_eq!(
        m.validate().unwrap_err().to_string(),
        "robots: 9 must be in 1..=8"
    );
    let e = parse::<CreateMatch>(br#"{"map": "office", "robots": "two"}"#)
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("robots: invalid type"), "{e}");
    let e = parse::<CreateMatch>(br#"{"map": "office", "tracker": {"merge": 1}}"#)
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("tracker.merge: invalid type"), "{e}");
    let e = parse::<CreateMatch>(br#"{"map": "office", "colour": 1}"#)
        .unwrap_err()
        .to_string();
    assert!(e.contains("unknown field `colour`"), "{e}");
    let e = parse::<CreateMatch>(br#"{"map": "office", "time_limit_s": 1e999}"#)
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("time_limit_s:"), "{e}");
    let e = parse::<CreateMatch>(br#"{"robots": 2}"#)
        .unwrap_err()
        .to_string();
    assert!(e.contains("missing field `map`"), "{e}");
    assert!(r.config.localisation, "robots localise unless told not to");
    let m: CreateMatch = parse(br#"{"map": "office", "localisation": false}"#).unwrap();
    assert!(!m.validate().unwrap().config.localisation);
}

#[test]
fn opponent_commands_take_exactly_one_field() {
    let c: OpponentCommand = parse(br#"{"stop": true}"#).unwrap();
    assert!(c.order().is_ok());
    let c: OpponentCommand = parse(br#"{"stop": true, "tag": true}"#).unwrap();
    assert!(c.order().is_err());
    let c: OpponentCommand = parse(br#"{}"#).unwrap();
    assert!(c.order().is_err());
}
