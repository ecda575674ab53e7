//! The rooms' rules, without a server.

use super::room::*;
use super::rooms::*;
use crate::access::ClientKey;
use crate::config::Config;
use crate::game::view::Team;
use crate::names::{JoinName, Name};
use crate::store::KeptParty;
use lasertag_core::difficulty::Difficulty;
use std::collections::BTreeMap;
use std::net::{IpAddr, Ipv4Addr};
use std::time::{Duration, Instant, SystemTime};

fn client(n: u8) -> ClientKey {
    ClientKey::of(IpAddr::V4(Ipv4Addr::new(10, 0, 0, n)))
}

fn name(s: &str) -> JoinName {
    JoinName::unclaimed(Name::parse(s).unwrap())
}

fn settings() -> PartySettings {
    PartySettings {
        map: "office".into(),
        difficulty: Difficulty::Elite,
        minutes: 3,
    }
}

#[test]
fn codes_have_no_look_alikes_and_read_back_however_typed() {
    for _ in 0..200 {
        let code = random_code();
        assert_eq!(code.len(), CODE_LEN);
        assert!(!code.contains(['0', 'O', '1', 'I', 'L']), "{code}");
        assert_eq!(normalise_code(&code.to_lowercase()), Some(code.clone()));
    }
    assert_eq!(normalise_code("abc-234"), Some("ABC234".into()));
    assert_eq!(normalise_code("ABC23O"), None, "O is not in the alphabet");
    assert_eq!(normalise_code("ABC2345"), None);
}

#[test]
fn the_host_starts_when_everyone_is_ready_and_the_room_waits_again_after() {
    let parties = Parties::new(&Config::default(), None);
    let (code, host, host_token) = parties.create(name("ann"), client(1), settings()).unwrap();
    let (bob, bob_token) = parties.join(&code, name("bob"), client(2)).unwrap();
    let ready = Change {
        ready: Some(true),
        ..Change::default()
    };
    // Bob cannot make the host ready, nor change the settings.
    assert!(matches!(
        parties.change(&code, &host, &bob_token, client(2), ready.clone()),
        Err(PartyError::NotYours("ready"))
    ));
    let minutes = Change {
        minutes: Some(5),
        ..Change::default()
    };
    assert!(matches!(
        parties.change(&code, &bob, &bob_token, client(2), minutes.clone()),
        Err(PartyError::NotHost(_))
    ));
    parties
        .change(&code, &host, &host_token, client(1), minutes)
        .unwrap();
    // The host sets bob's side; only the host may start, and not before bob is ready.
    let robots = Change {
        side: Some(Team::Robots),
        ..Change::default()
    };
    let view = parties
        .change(&code, &bob, &host_token, client(1), robots)
        .unwrap();
    assert_eq!(view.party.member(&bob).unwrap().side, Team::Robots);
    parties
        .change(&code, &host, &host_token, client(1), ready.clone())
        .unwrap();
    assert!(matches!(
        parties.begin_start(&code, &bob_token, client(2)),
        Err(PartyError::NotHost(_))
    ));
    match parties.begin_start(&code, &host_token, client(1)) {
        Err(PartyError::NotReady(who)) => assert_eq!(who, "bob"),
        other => panic!("{other:?}"),
    }
    parties
        .change(&code, &bob, &bob_token, client(2), ready)
        .unwrap();
    let party = parties.begin_start(&code, &host_token, client(1)).unwrap();
    assert_eq!(party.settings.minutes, 5);
    assert!(matches!(
        parties.begin_start(&code, &host_token, client(1)),
        Err(PartyError::Playing(_))
    ));
    let seats = BTreeMap::from([(bob.clone(), ("t".to_string(), Team::Robots))]);
    parties.started(&code, "m-1", seats);
    let view = parties.get(&code, None).unwrap();
    assert_eq!(view.party.match_id.as_deref(), Some("m-1"));
    assert_eq!(view.started.as_ref().unwrap().serial, 1);
    // The match ends: the room waits again, sides kept, nobody ready.
    parties.sweep(Instant::now(), |_| false);
    let view = parties.get(&code, None).unwrap();
    assert_eq!(view.party.match_id, None);
    assert!(view.party.members.iter().all(|m| !m.ready));
    assert_eq!(view.party.member(&bob).unwrap().side, Team::Robots);
}

#[test]
fn guessing_codes_is_refused_long_before_it_finds_one() {
    let parties = Parties::new(&Config::default(), None);
    let (code, _, _) = parties.create(name("ann"), client(1), settings()).unwrap();
    let mut refused_after = None;
    for i in 0..100 {
        match parties.get("ZZZZZZ", Some(client(9))) {
            Err(PartyError::NoParty(_)) => {}
            Err(PartyError::TooManyMisses(_)) => {
                refused_after = Some(i);
                break;
            }
            other => panic!("{other:?}"),
        }
    }
    let after = refused_after.expect("refused");
    assert!(after <= Config::default().party_misses_per_minute as usize);
    // Refused hits too, once the misses are spent; another address is not.
    assert!(matches!(
        parties.get(&code, Some(client(9))),
        Err(PartyError::TooManyMisses(_))
    ));
    assert!(parties.get(&code, Some(client(3))).is_ok());
}

#[test]
fn a_full_room_refuses_and_a_removed_member_is_gone() {
    let parties = Parties::new(&Config::default(), None);
    let (code, _, host_token) = parties.create(name("ann"), client(1), settings()).unwrap();
    let mut last = None;
    for i in 1..MAX_MEMBERS {
        last = Some(
            parties
                .join(&code, name(&format!("p{i}")), client(2))
                .unwrap(),
        );
    }
    assert!(matches!(
        parties.join(&code, name("late"), client(2)),
        Err(PartyError::Full(_))
    ));
    let (id, token) = last.unwrap();
    let view = parties.remove(&code, &id, &host_token, client(1)).unwrap();
    assert_eq!(view.party.members.len(), MAX_MEMBERS - 1);
    assert!(matches!(
        parties.subscribe(&code, &token, client(2)),
        Err(PartyError::NotMember(_))
    ));
}

#[test]
fn a_room_nobody_is_connected_to_lapses_but_not_while_it_plays() {
    let parties = Parties::new(&Config::default(), None);
    let (a, _, _) = parties.create(name("ann"), client(1), settings()).unwrap();
    let (b, _, token) = parties.create(name("bob"), client(2), settings()).unwrap();
    parties.begin_start(&b, &token, client(2)).unwrap_err(); // bob is not ready
    parties.started(&b, "m-2", BTreeMap::new());
    let later = Instant::now() + LAPSE + Duration::from_secs(1);
    parties.sweep(later, |id| id == "m-2");
    assert!(parties.get(&a, None).is_err(), "lapsed");
    assert!(parties.get(&b, None).is_ok(), "its match runs");
}

#[test]
fn a_kept_room_comes_back_with_its_tokens() {
    let parties = Parties::new(&Config::default(), None);
    let (code, host, token) = parties.create(name("ann"), client(1), settings()).unwrap();
    let record = {
        let rooms = parties.rooms();
        rooms[&code].party.record(SystemTime::now())
    };
    let again = Parties::new(&Config::default(), None);
    let kept = KeptParty {
        code: code.clone(),
        doc: record.to_doc(),
    };
    assert_eq!(again.restore(vec![kept]), 1);
    let (member, _) = again.subscribe(&code, &token, client(1)).unwrap();
    assert_eq!(member, host);
}
