//! People on the robot team (`pursuer_slots`) over a real server: joining a robot, driving
//! it from a WebSocket with the team's belief live, its sightings feeding the team's
//! tracker, its tag, and the fog on both sides of a match people play on both teams (a
//! tagged player's too: it watches through its teammates' eyes).

mod common;

use std::f64::consts::PI;
use std::time::Duration;

use common::{TestServer, Ws, assert_error, duel_map, ids, shipped_arena};
use nalgebra::Point2;
use serde_json::{Value, json};

/// Joins `id` on `team`: (the agent taken, its token).
async fn join_team(s: &TestServer, id: &str, name: &str, team: &str) -> (String, String) {
    let r = s
        .post(
            &format!("/api/matches/{id}/players"),
            &json!({"name": name, "team": team}),
        )
        .await;
    assert_eq!(r.status, 201, "{}", r.body);
    let agent = r.body["robot_id"]
        .as_str()
        .or(r.body["opponent_id"].as_str())
        .unwrap();
    (
        agent.to_string(),
        r.body["token"].as_str().unwrap().to_string(),
    )
}

/// Match `id` as the listing shows it to the owner (`token`) or anybody.
async fn listed(s: &TestServer, id: &str, token: Option<&str>) -> Value {
    let all = s.get_as("/api/matches", token).await.body;
    all.as_array()
        .unwrap()
        .iter()
        .find(|m| m["id"] == id)
        .cloned()
        .unwrap()
}

/// The messages up to the snapshot of tick `tick` (or later): that snapshot and the events
/// that came before it (a frame's events follow its snapshot: those of tick `tick` come
/// with the next one).
async fn until_tick(ws: &mut Ws, tick: u64) -> (Value, Vec<Value>) {
    let mut events = Vec::new();
    loop {
        let v = ws.json().await;
        match v["type"].as_str() {
            Some("event") => events.push(v),
            Some("snapshot") if v["tick"].as_u64().unwrap() >= tick => return (v, events),
            _ => {}
        }
    }
}

#[tokio::test]
async fn a_person_drives_a_robot_sees_through_its_laser_and_tags() {
    let s = TestServer::start().await;
    // r1, the seat, stands at (1, 2) facing west, with o1 4 m behind it; r0 (idle) faces
    // the east wall, o0 behind it: nobody sees anybody until the person turns round.
    let id = s
        .create_match(json!({"map": duel_map(), "robots": 2, "opponents": 2,
            "opponent_control": "api", "planner": "idle", "pursuer_slots": 1,
            "clock": "manual", "time_limit_s": 60,
            "robot_starts": [[13.0, 1.0, 0.0], [1.0, 2.0, PI]],
            "opponent_starts": [[10.0, 7.0], [5.0, 2.0]]}))
        .await;
    let owner = s.owner_token(&format!("/api/matches/{id}"));
    let summary = listed(&s, &id, owner.as_deref()).await;
    assert_eq!(summary["pursuer_slots"], 1);
    assert_eq!(summary["free_pursuer_slots"], 1);
    assert_eq!(summary["robot_planners"], json!(["idle", "person"]));
    // People play it: delayed for the public, its seed secret.
    assert!(summary["spectator_delay_s"].as_f64().unwrap() > 0.0);
    assert!(
        summary["seed"].is_u64(),
        "the owner sees the seed: {summary}"
    );
    let public = listed(&s, &id, None).await;
    assert!(public["seed"].is_null(), "{public}");
    // The owner's API does not take the person's body.
    let r = s
        .post(
            &format!("/api/matches/{id}/robots/r1/command"),
            &json!({"forward": 1.0, "turn": 0.0}),
        )
        .await;
    assert_error(&r, 409, "pursuer slot");

    let (me, token) = join_team(&s, &id, "alice", "robots").await;
    assert_eq!(me, "r1");
    let r = s
        .post(
            &format!("/api/matches/{id}/players"),
            &json!({"name": "bob", "team": "robots"}),
        )
        .await;
    assert_error(&r, 409, "no free pursuer slot");
    let r = s
        .post(
            &format!("/api/matches/{id}/players"),
            &json!({"name": "bob", "team": "hunters"}),
        )
        .await;
    assert_eq!(r.status, 400, "{}", r.body);
    assert_eq!(listed(&s, &id, None).await["free_pursuer_slots"], 0);

    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    let welcome = ws.json().await;
    assert_eq!(welcome["you"], "r1");
    assert_eq!(welcome["team"], "robots");
    assert_eq!(
        welcome["belief"], true,
        "a person on the team hunts with its belief"
    );
    assert_eq!(
        welcome["kinematics"]["turn_rate"], 2.0,
        "a robot's turn rate"
    );
    s.step(&id, 1).await;
    let (snap, _) = until_tick(&mut ws, 1).await;
    assert_eq!(snap["view"], "player");
    assert_eq!(snap["you"], "r1");
    assert_eq!(ids(&snap["robots"]), ["r0", "r1"].map(String::from).into());
    assert!(ids(&snap["opponents"]).is_empty(), "{snap}");
    let r1 = snap["robots"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["id"] == "r1")
        .unwrap();
    assert_eq!(
        r1["scan"].as_array().unwrap().len(),
        181,
        "its own laser's ranges"
    );
    assert_eq!(r1["name"], "alice");
    let r0 = snap["robots"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["id"] == "r0")
        .unwrap();
    assert!(r0.get("scan").is_none() && r0.get("goal").is_none(), "{r0}");
    // She turns round at the robot's full turn rate (0.1 rad a tick): 31 ticks face east.
    ws.send_json(&json!({"type": "input", "forward": 0.0, "turn": 1.0}))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(100)).await;
    s.step(&id, 31).await;
    let (snap, _) = until_tick(&mut ws, 32).await;
    // o1, as the team's detector tells it: where, not who or which way it faces.
    assert_eq!(
        ids(&snap["opponents"]),
        ["o?"].map(String::from).into(),
        "{snap}"
    );
    let seen = &snap["opponents"][0];
    assert!(
        seen.get("theta").is_none() && seen.get("control").is_none() && seen.get("name").is_none(),
        "{seen}"
    );
    let belief = &snap["belief"];
    assert_eq!(
        belief["tick"], snap["tick"],
        "the team's belief, live: {snap}"
    );
    assert_eq!(belief["roles"].as_array().unwrap().len(), 2, "{belief}");
    ws.send_json(&json!({"type": "input", "forward": 0.0, "turn": 0.0}))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(100)).await;
    s.step(&id, 1).await;
    let (_, events) = until_tick(&mut ws, 33).await;
    assert!(
        events.iter().any(|e| e["kind"] == "role_split"),
        "her sighting splits a role, and she is told at once: {events:?}"
    );
    // The trigger: o1 is tagged by r1.
    ws.send_json(&json!({"type": "input", "forward": 0.0, "turn": 0.0, "tag": true}))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(100)).await;
    s.step(&id, 2).await;
    until_tick(&mut ws, 35).await;
    s.step(&id, 1).await;
    let (snap, events) = until_tick(&mut ws, 36).await;
    assert!(
        events
            .iter()
            .any(|e| e["kind"] == "tag" && e["by"] == "r1" && e["target"] == "o?"),
        "{events:?}"
    );
    assert_eq!(snap["score"]["tags"], 1);
    let log = s.events(&id).await;
    assert!(
        log.iter()
            .any(|e| e["kind"] == "player_joined" && e["robot"] == "r1" && e["name"] == "alice"),
        "{log:?}"
    );

    // Ended, the replay shows the match as she saw it from r1: her laser's view, the belief.
    assert_eq!(s.delete(&format!("/api/matches/{id}")).await.status, 204);
    let url = format!("ws://{}/ws/replays/{id}?as=r1&tick=1", s.addr);
    let (stream, _) = tokio_tungstenite::connect_async(url).await.unwrap();
    let mut replay = Ws { stream };
    let welcome = replay.json().await;
    assert_eq!(welcome["view"], "r1", "{welcome}");
    assert_eq!(welcome["name"], "alice");
    assert_eq!(welcome["belief"], true);
    let snap = replay.next_of("snapshot").await;
    assert_eq!(snap["view"], "player", "{snap}");
    assert!(
        ids(&snap["opponents"]).is_empty(),
        "facing west at tick 1: {snap}"
    );
    assert!(snap["belief"]["roles"].is_array(), "{snap}");
    let state = s
        .get(&format!("/api/replays/{id}/state?tick=30"))
        .await
        .body;
    assert_eq!(
        state["robot_planners"],
        json!(["idle", "person"]),
        "{state}"
    );
}

/// Whether a robot at `me` facing `theta` has `at` in its laser's view on `arena`.
fn in_laser(arena: &lasertag_core::sim::arena::Arena, me: [f64; 3], at: [f64; 2]) -> bool {
    let (dx, dy) = (at[0] - me[0], at[1] - me[1]);
    let bearing = (dy.atan2(dx) - me[2] + PI).rem_euclid(2.0 * PI) - PI;
    dx.hypot(dy) <= 8.0
        && bearing.abs() <= PI / 2.0
        && arena.line_of_sight(
            Point2::new(me[0] as f32, me[1] as f32),
            Point2::new(at[0] as f32, at[1] as f32),
        )
}

/// Whether a body at `c` comes within reach of the sight line from `a` to `b` (0.6 m: its
/// radius and the other's, and a margin), so that it may hide `b` in part or whole.
fn near_line(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> bool {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = (((c[0] - a[0]) * dx + (c[1] - a[1]) * dy) / len2).clamp(0.0, 1.0);
    let (px, py) = (a[0] + t * dx, a[1] + t * dy);
    (c[0] - px).hypot(c[1] - py) < 0.6
}

/// `at` moved `d` metres across the line from `from` to it (either side of a disc there).
fn across(from: [f64; 2], at: [f64; 2], d: f64) -> [f64; 2] {
    let (dx, dy) = (at[0] - from[0], at[1] - from[1]);
    let len = dx.hypot(dy).max(1e-9);
    [at[0] - dy / len * d, at[1] + dx / len * d]
}

fn xy(v: &Value) -> [f64; 2] {
    [v["x"].as_f64().unwrap(), v["y"].as_f64().unwrap()]
}

#[tokio::test]
async fn the_fog_holds_on_both_sides_of_a_versus_match() {
    let s = TestServer::start().await;
    let arena = shipped_arena("office");
    // Versus: alice hunts on r1 beside a planned r0; bob is the hunted, o0.
    let id = s
        .create_match(json!({"map": "office", "robots": 2, "opponents": 1,
            "opponent_control": "human", "planner": "baseline", "pursuer_slots": 1,
            "clock": "manual", "time_limit_s": 40,
            "robot_starts": [[22.0, 1.5, 0.0], [7.0, 8.0, std::f64::consts::PI]],
            "opponent_starts": [[3.0, 8.0]]}))
        .await;
    let (alice_is, alice_token) = join_team(&s, &id, "alice", "robots").await;
    let (bob_is, bob_token) = join_team(&s, &id, "bob", "opponents").await;
    assert_eq!((alice_is.as_str(), bob_is.as_str()), ("r1", "o0"));
    let mut alice = s.ws(&id, Some(&alice_token)).await.unwrap();
    let mut bob = s.ws(&id, Some(&bob_token)).await.unwrap();
    let (mut alice_saw, mut alice_missed, mut bob_saw, mut bob_missed) = (0, 0, 0, 0);
    for t in 0..600u64 {
        if t % 40 == 0 {
            // Both wander: forward, turning one way then the other.
            let turn = if (t / 40) % 2 == 0 { 0.6 } else { -0.4 };
            for ws in [&mut alice, &mut bob] {
                ws.send_json(&json!({"type": "input", "forward": 1.0, "turn": turn}))
                    .await
                    .unwrap();
            }
            tokio::time::sleep(Duration::from_millis(30)).await;
        }
        let truth = s.step(&id, 1).await;
        let tick = truth["tick"].as_u64().unwrap();
        let (a, _) = until_tick(&mut alice, tick).await;
        let (b, _) = until_tick(&mut bob, tick).await;
        let robot = truth["robots"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["id"] == "r1")
            .unwrap();
        let me = [xy(robot)[0], xy(robot)[1], robot["theta"].as_f64().unwrap()];
        let opp = &truth["opponents"][0];
        if opp["tagged"] == true || truth["status"] == "finished" {
            break;
        }
        // Alice's socket: an anonymous sighting exactly when r1's laser has o0 (skipping
        // what millimetre rounding or the disc's width could flip: the edges of the range,
        // the field of view and the walls, and r0's body near the line).
        let at = xy(opp);
        let expected = in_laser(&arena, me, at);
        let r0 = xy(&truth["robots"][0]);
        let steady = [
            (0.003, 0.0, 0.0),
            (-0.003, 0.0, 0.0),
            (0.0, 0.003, 0.0),
            (0.0, 0.0, 0.002),
            (0.0, 0.0, -0.002),
        ]
        .iter()
        .all(|(dx, dy, dt)| in_laser(&arena, [me[0] + dx, me[1] + dy, me[2] + dt], at) == expected)
            && [-0.26, 0.26]
                .iter()
                .all(|d| in_laser(&arena, me, across([me[0], me[1]], at, *d)) == expected)
            && !near_line([me[0], me[1]], at, r0);
        if steady {
            assert_eq!(
                ids(&a["opponents"]).contains("o?"),
                expected,
                "tick {tick}: alice on r1 at {me:?}, o0 at {at:?}"
            );
            assert!(
                !ids(&a["opponents"]).contains("o0"),
                "who it is stays hidden"
            );
            if expected {
                alice_saw += 1
            } else {
                alice_missed += 1
            }
        }
        assert_eq!(ids(&a["robots"]).len(), 2, "her own team, always");
        // Bob's socket: each robot exactly when in his line of sight.
        for r in truth["robots"].as_array().unwrap() {
            let los = |p: [f64; 2]| {
                arena.line_of_sight(
                    Point2::new(at[0] as f32, at[1] as f32),
                    Point2::new(p[0] as f32, p[1] as f32),
                )
            };
            let p = xy(r);
            let expected = los(p);
            // The other robot's body may hide this one: not counted then.
            let other = truth["robots"]
                .as_array()
                .unwrap()
                .iter()
                .find(|o| o["id"] != r["id"])
                .map(xy);
            let steady = [(0.003, 0.0), (-0.003, 0.0), (0.0, 0.003), (0.0, -0.003)]
                .iter()
                .all(|(dx, dy)| los([p[0] + dx, p[1] + dy]) == expected)
                && other.is_none_or(|c| !near_line(at, p, c));
            if steady {
                let rid = r["id"].as_str().unwrap();
                assert_eq!(
                    ids(&b["robots"]).contains(rid),
                    expected,
                    "tick {tick}: {rid} for bob"
                );
                if expected {
                    bob_saw += 1
                } else {
                    bob_missed += 1
                }
            }
        }
        assert!(
            b.get("belief").is_none(),
            "bob has no belief unless he asks"
        );
    }
    assert!(
        alice_saw > 0 && alice_missed > 0 && bob_saw > 0 && bob_missed > 0,
        "alice saw {alice_saw}, missed {alice_missed}; bob saw {bob_saw}, missed {bob_missed}"
    );
}

#[tokio::test]
async fn one_address_plays_one_side_of_a_match() {
    let s = TestServer::start_with(lasertag::config::Config {
        both_sides_per_address: false,
        ..common::test_config()
    })
    .await;
    let id = s
        .create_match(json!({"map": "office", "robots": 2, "opponents": 2,
            "opponent_control": "human", "pursuer_slots": 1}))
        .await;
    let (me, _) = join_team(&s, &id, "alice", "robots").await;
    assert_eq!(me, "r1");
    // Seen from both sides, the hunted would read the hunters' belief live.
    let r = s
        .post(
            &format!("/api/matches/{id}/players"),
            &json!({"name": "mallory", "team": "opponents"}),
        )
        .await;
    assert_error(&r, 409, "one address plays one side");
    // Another match is another match.
    let other = s
        .create_match(json!({"map": "office", "opponent_control": "human"}))
        .await;
    let (o, _) = join_team(&s, &other, "alice", "opponents").await;
    assert_eq!(o, "o0");
}

#[tokio::test]
async fn over_a_late_radio_a_hunter_sees_their_own_robots_belief() {
    let s = TestServer::start().await;
    // Each robot keeps its own tracker: the hunter is shown r1's, not the team's pooled one.
    let id = s
        .create_match(json!({"map": "office", "robots": 2, "opponents": 2,
            "opponent_control": "api", "pursuer_slots": 1, "clock": "manual",
            "radio": {"latency_ticks": 5, "loss": 0.2}}))
        .await;
    let (_, token) = join_team(&s, &id, "alice", "robots").await;
    let mut ws = s.ws(&id, Some(&token)).await.unwrap();
    ws.json().await;
    s.step(&id, 8).await;
    let (snap, _) = until_tick(&mut ws, 8).await;
    let shown = &snap["belief"];
    assert!(shown.is_object(), "{snap}");
    let own = s
        .get(&format!("/api/matches/{id}/belief?robot=r1"))
        .await
        .body;
    let pooled = s.get(&format!("/api/matches/{id}/belief")).await.body;
    // Each role's particles: a count in a snapshot, the particles themselves over REST.
    let particles = |b: &Value| -> Vec<u64> {
        b["roles"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| {
                let p = &r["particles"];
                p.as_u64()
                    .unwrap_or_else(|| p.as_array().unwrap().len() as u64)
            })
            .collect()
    };
    assert_eq!(
        particles(shown),
        particles(&own),
        "shown {shown}, r1's {own}"
    );
    assert_ne!(
        particles(shown),
        particles(&pooled),
        "the pooled belief sums both trackers"
    );
}

/// An open room: r0 at the west end facing east, o0 3 m ahead of it and o1 3 m behind o0
/// on the same line, every seat held by a person.
#[tokio::test]
async fn bodies_hide_what_is_behind_them_and_the_robots_learn_no_names() {
    let s = TestServer::start().await;
    let id = s
        .create_match(
            json!({"map": {"name": "open-room", "width": 14.0, "height": 8.0,
                "obstacles": [], "robot_spawns": [[2.0, 4.0, 0.0]],
                "opponent_spawns": [[5.0, 4.0], [8.0, 4.0]]},
            "robots": 1, "opponents": 2, "opponent_control": "human", "pursuer_slots": 1,
            "clock": "manual", "time_limit_s": 60,
            "robot_starts": [[2.0, 4.0, 0.0]], "opponent_starts": [[5.0, 4.0], [8.0, 4.0]]}),
        )
        .await;
    let (robot, robot_token) = join_team(&s, &id, "alice", "robots").await;
    let (front, _) = join_team(&s, &id, "bob", "opponents").await;
    let (back, back_token) = join_team(&s, &id, "carol", "opponents").await;
    assert_eq!(
        (robot.as_str(), front.as_str(), back.as_str()),
        ("r0", "o0", "o1")
    );
    let mut alice = s.ws(&id, Some(&robot_token)).await.unwrap();
    let mut carol = s.ws(&id, Some(&back_token)).await.unwrap();
    s.step(&id, 1).await;

    // Alice's laser meets o0 and stops there: one sighting, without who or which way.
    let (snap, _) = until_tick(&mut alice, 1).await;
    let seen = snap["opponents"].as_array().unwrap();
    assert_eq!(seen.len(), 1, "o1 stands behind o0: {snap}");
    assert_eq!(seen[0]["id"], "o?", "{snap}");
    assert!(
        (seen[0]["x"].as_f64().unwrap() - 5.0).abs() < 0.01,
        "{snap}"
    );
    for hidden in ["theta", "control", "name"] {
        assert!(seen[0].get(hidden).is_none(), "{hidden} sent: {snap}");
    }
    let text = snap.to_string();
    assert!(!text.contains("bob") && !text.contains("carol"), "{text}");

    // Carol, behind o0, sees her teammate but not the robot o0's body hides.
    let (snap, _) = until_tick(&mut carol, 1).await;
    assert!(ids(&snap["robots"]).is_empty(), "r0 is behind o0: {snap}");
    assert_eq!(
        ids(&snap["opponents"]),
        ["o0", "o1"].map(String::from).into()
    );
}

/// A room split by a wall: r0 (a person's seat) at the west end facing east with o0 3 m
/// ahead of it; o1 east of the wall, where it cannot see r0. Once r0 tags o0, o0's player
/// watches on live through o1's eyes: never the truth (r0 stays hidden), never back in time.
#[tokio::test]
async fn after_the_tag_a_player_watches_live_through_its_teammates_eyes() {
    let s = TestServer::start().await;
    let id = s
        .create_match(
            json!({"map": {"name": "split-room", "width": 14.0, "height": 8.0,
                "obstacles": [[[9.0, 0.0], [10.0, 0.0], [10.0, 6.0], [9.0, 6.0]]],
                "robot_spawns": [[2.0, 4.0, 0.0]],
                "opponent_spawns": [[5.0, 4.0], [12.0, 2.0]]},
            "robots": 1, "opponents": 2, "opponent_control": "human", "pursuer_slots": 1,
            "clock": "manual", "time_limit_s": 60,
            "robot_starts": [[2.0, 4.0, 0.0]], "opponent_starts": [[5.0, 4.0], [12.0, 2.0]]}),
        )
        .await;
    let (_, robot_token) = join_team(&s, &id, "alice", "robots").await;
    let (tagged, bob_token) = join_team(&s, &id, "bob", "opponents").await;
    let (_, carol_token) = join_team(&s, &id, "carol", "opponents").await;
    assert_eq!(tagged, "o0");
    let mut alice = s.ws(&id, Some(&robot_token)).await.unwrap();
    let mut bob = s.ws(&id, Some(&bob_token)).await.unwrap();
    let _carol = s.ws(&id, Some(&carol_token)).await.unwrap();
    s.step(&id, 1).await;
    let (before, _) = until_tick(&mut bob, 1).await;
    assert_eq!(before["view"], "player");
    assert_eq!(ids(&before["robots"]), ["r0"].map(String::from).into());
    until_tick(&mut alice, 1).await;
    alice
        .send_json(&json!({"type": "input", "forward": 0.0, "turn": 0.0, "tag": true}))
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(100)).await;
    let mut last_tick = 1;
    let mut watched = 0;
    for _ in 0..40 {
        let truth = s.step(&id, 1).await;
        let tick = truth["tick"].as_u64().unwrap();
        let (snap, _) = until_tick(&mut bob, tick).await;
        let snap_tick = snap["tick"].as_u64().unwrap();
        assert!(
            snap_tick >= last_tick,
            "the clock went back: {snap_tick} < {last_tick}"
        );
        last_tick = snap_tick;
        if truth["opponents"][0]["tagged"] != true {
            continue;
        }
        // Live, in the teammates' view: o1 (and its own tagged body), never r0, which
        // only o0 could see.
        assert_eq!(snap_tick, tick, "{snap}");
        assert_eq!(snap["view"], "teammates", "{snap}");
        assert!(
            ids(&snap["robots"]).is_empty(),
            "r0 is out of o1's sight: {snap}"
        );
        assert!(ids(&snap["opponents"]).contains("o1"), "{snap}");
        watched += 1;
    }
    assert!(
        watched > 10,
        "o0 was never tagged ({watched} ticks watched)"
    );
    // The page stops sending keys; a key sent anyway is refused, naming why.
    bob.send_json(&json!({"type": "input", "forward": 1.0, "turn": 0.0, "tag": false}))
        .await
        .unwrap();
    let error = loop {
        let v = bob.json().await;
        if v["type"] == "error" {
            break v;
        }
    };
    assert!(
        error["error"].as_str().unwrap().contains("tagged"),
        "{error}"
    );
}
