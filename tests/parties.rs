//! Parties over a real server: a room made, joined by its code, changed by its members and
//! its host, started with every member seated (each told their seat on the room's socket),
//! waiting again after the match; guessing codes refused; and a room that outlives a
//! `kill -9` of the real binary with its members and their tokens.

mod common;
#[path = "common/process.rs"]
mod process;

use std::time::Duration;

use common::{ADMIN, Got, TestServer, Ws};
use serde_json::{Value, json};

async fn party_ws(s: &TestServer, code: &str, token: &str) -> Ws {
    let url = format!("ws://{}/ws/parties/{code}?token={token}", s.addr);
    let (stream, _) = tokio_tungstenite::connect_async(url)
        .await
        .expect("the room's socket opens");
    Ws { stream }
}

/// The next `party` message whose room satisfies `ok`.
async fn room_until(ws: &mut Ws, ok: impl Fn(&Value) -> bool) -> Value {
    loop {
        let v = ws.next_of("party").await;
        if ok(&v) {
            return v;
        }
    }
}

async fn patch(s: &TestServer, path: &str, token: &str, body: Value) -> common::Reply {
    let r = reqwest::Client::new()
        .patch(s.url(path))
        .bearer_auth(token)
        .json(&body)
        .send()
        .await
        .unwrap();
    let status = r.status().as_u16();
    common::Reply {
        status,
        body: r.json().await.unwrap_or(Value::Null),
    }
}

fn text(v: &Value, key: &str) -> String {
    v[key].as_str().unwrap_or_default().to_string()
}

#[tokio::test]
async fn friends_gather_in_a_room_start_together_and_come_back_for_a_rematch() {
    let s = TestServer::with_admin().await;
    let made = s.post("/api/parties", &json!({"name": "alice"})).await;
    assert_eq!(made.status, 201, "{}", made.body);
    let code = text(&made.body, "code");
    assert_eq!(code.len(), 6);
    assert!(
        code.chars()
            .all(|c| "ABCDEFGHJKMNPQRSTUVWXYZ23456789".contains(c)),
        "{code}"
    );
    assert!(text(&made.body, "invite_url").ends_with(&format!("/#/party/{code}")));
    let (alice, alice_token) = (
        text(&made.body, "member_id"),
        text(&made.body, "member_token"),
    );

    // Friends join by the code as typed (lower case too).
    let bob = s
        .post(
            &format!("/api/parties/{}/members", code.to_lowercase()),
            &json!({"name": "bob"}),
        )
        .await;
    assert_eq!(bob.status, 201, "{}", bob.body);
    let (bob, bob_token) = (
        text(&bob.body, "member_id"),
        text(&bob.body, "member_token"),
    );
    let carol = s
        .post(
            &format!("/api/parties/{code}/members"),
            &json!({"name": "carol"}),
        )
        .await;
    let (carol, carol_token) = (
        text(&carol.body, "member_id"),
        text(&carol.body, "member_token"),
    );

    let mut alice_ws = party_ws(&s, &code, &alice_token).await;
    let mut bob_ws = party_ws(&s, &code, &bob_token).await;
    let mut carol_ws = party_ws(&s, &code, &carol_token).await;
    let room = room_until(&mut alice_ws, |r| {
        r["members"].as_array().unwrap().len() == 3
            && r["members"]
                .as_array()
                .unwrap()
                .iter()
                .all(|m| m["connected"] == true)
    })
    .await;
    assert_eq!(room["status"], "waiting");
    assert_eq!(room["host"], alice.as_str());
    assert_eq!(room["rated"], false, "three people never rate: {room}");

    // Members choose their own side and readiness; only the host changes settings.
    let members = format!("/api/parties/{code}/members");
    assert_eq!(
        patch(
            &s,
            &format!("{members}/{bob}"),
            &bob_token,
            json!({"side": "robots"})
        )
        .await
        .status,
        200
    );
    let r = patch(
        &s,
        &format!("{members}/{alice}"),
        &carol_token,
        json!({"ready": true}),
    )
    .await;
    common::assert_error(&r, 403, "own");
    let r = patch(
        &s,
        &format!("{members}/{carol}"),
        &carol_token,
        json!({"settings": {"minutes": 3}}),
    )
    .await;
    common::assert_error(&r, 403, "host");
    let r = patch(
        &s,
        &format!("{members}/{alice}"),
        &alice_token,
        json!({"settings": {"map": "office", "difficulty": "elite", "minutes": 3}}),
    )
    .await;
    assert_eq!(r.status, 200, "{}", r.body);
    assert_eq!(r.body["settings"]["difficulty"], "elite");
    let r = patch(
        &s,
        &format!("{members}/{alice}"),
        &alice_token,
        json!({"settings": {"map": "atlantis"}}),
    )
    .await;
    common::assert_error(&r, 400, "atlantis");

    // Start names who is not ready.
    let start = format!("/api/parties/{code}/start");
    for (id, token) in [(&alice, &alice_token), (&bob, &bob_token)] {
        let r = patch(
            &s,
            &format!("{members}/{id}"),
            token,
            json!({"ready": true}),
        )
        .await;
        assert_eq!(r.status, 200, "{}", r.body);
    }
    let r = s.post_as(&start, &json!({}), Some(&alice_token)).await;
    common::assert_error(&r, 409, "carol");
    patch(
        &s,
        &format!("{members}/{carol}"),
        &carol_token,
        json!({"ready": true}),
    )
    .await;
    let r = s.post_as(&start, &json!({}), Some(&bob_token)).await;
    common::assert_error(&r, 403, "host");
    let r = s.post_as(&start, &json!({}), Some(&alice_token)).await;
    assert_eq!(r.status, 201, "{}", r.body);
    let match_id = text(&r.body, "match_id");

    // Every member's socket is told their own seat, and the seat plays.
    let mut bodies = Vec::new();
    for (ws, team) in [
        (&mut alice_ws, "opponents"),
        (&mut bob_ws, "robots"),
        (&mut carol_ws, "opponents"),
    ] {
        let seat = ws.next_of("start").await;
        assert_eq!(seat["match_id"], match_id.as_str());
        assert_eq!(seat["team"], team);
        let mut play = s.ws(&match_id, seat["token"].as_str()).await.unwrap();
        let welcome = play.next_of("welcome").await;
        assert_eq!(welcome["role"], "player", "{welcome}");
        bodies.push(welcome["you"].as_str().unwrap().to_string());
    }
    assert!(
        bodies[0].starts_with('o') && bodies[2].starts_with('o'),
        "{bodies:?}"
    );
    assert!(bodies[1].starts_with('r'), "{bodies:?}");
    let listed = s.get(&format!("/api/parties/{code}")).await;
    assert_eq!(listed.body["status"], "playing");
    assert_eq!(listed.body["match_id"], match_id.as_str());

    // The match ends: the room waits again with the same sides, nobody ready.
    let r = s
        .delete_as(&format!("/api/matches/{match_id}"), Some(ADMIN))
        .await;
    assert!(r.status < 300, "{}", r.body);
    let room = room_until(&mut bob_ws, |r| r["status"] == "waiting").await;
    assert!(
        room["members"]
            .as_array()
            .unwrap()
            .iter()
            .all(|m| m["ready"] == false)
    );
    let bob_now = room["members"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["id"] == bob.as_str())
        .unwrap()
        .clone();
    assert_eq!(bob_now["side"], "robots");

    // The host removes carol: her socket is closed with the room's code for it.
    let r = s
        .delete_as(&format!("{members}/{carol}"), Some(&alice_token))
        .await;
    assert_eq!(r.status, 200, "{}", r.body);
    loop {
        match carol_ws.next().await {
            Got::Json(_) => continue,
            Got::Closed { code, .. } => {
                assert_eq!(code, 4403);
                break;
            }
            Got::Ended => panic!("closed without a code"),
        }
    }
    let r = s
        .delete_as(&format!("{members}/{alice}"), Some(&alice_token))
        .await;
    common::assert_error(&r, 409, "host");

    // The invite as a QR code.
    let qr = reqwest::get(s.url(&format!("/api/parties/{code}/invite.svg")))
        .await
        .unwrap();
    assert_eq!(qr.status(), 200);
    assert_eq!(qr.headers()["content-type"], "image/svg+xml");
    assert!(qr.text().await.unwrap().contains("<svg"));
}

#[tokio::test]
async fn a_full_room_refuses_and_guessing_codes_is_refused_long_before_it_finds_one() {
    let s = TestServer::start().await;
    let made = s.post("/api/parties", &json!({"name": "host"})).await;
    let code = text(&made.body, "code");
    for i in 1..8 {
        let r = s
            .post(
                &format!("/api/parties/{code}/members"),
                &json!({"name": format!("p{i}")}),
            )
            .await;
        assert_eq!(r.status, 201, "{}", r.body);
    }
    let r = s
        .post(
            &format!("/api/parties/{code}/members"),
            &json!({"name": "late"}),
        )
        .await;
    common::assert_error(&r, 409, "full");
    let r = s
        .post(
            &format!("/api/parties/{code}/members"),
            &json!({"name": ""}),
        )
        .await;
    assert_eq!(r.status, 400, "{}", r.body);

    let mut statuses = Vec::new();
    for _ in 0..30 {
        statuses.push(s.get("/api/parties/ZZZZZZ").await.status);
    }
    assert_eq!(statuses[0], 404);
    let first_429 = statuses.iter().position(|s| *s == 429).expect("refused");
    assert!(first_429 <= 11, "{statuses:?}");
    // Once refused, the real code is refused too: a guesser's hits are not free.
    assert_eq!(s.get(&format!("/api/parties/{code}")).await.status, 429);
}

#[tokio::test]
async fn a_room_outlives_a_kill_of_its_server_with_its_members_and_tokens() {
    let dir = common::temp_dir("parties-restart");
    let client = reqwest::Client::new();
    let args = ["--no-showcase", "--data-dir", &dir.display().to_string()];
    let mut a = process::Server::start(&args);
    let post = |s: &process::Server, path: &str, body: Value| {
        let r = client.post(s.url(path)).json(&body).send();
        async move {
            let r = r.await.unwrap();
            (r.status().as_u16(), r.json::<Value>().await.unwrap())
        }
    };
    let (status, made) = post(&a, "/api/parties", json!({"name": "alice"})).await;
    assert_eq!(status, 201, "{made}");
    let code = text(&made, "code");
    let (status, bob) = post(
        &a,
        &format!("/api/parties/{code}/members"),
        json!({"name": "bob"}),
    )
    .await;
    assert_eq!(status, 201, "{bob}");
    let bob_token = text(&bob, "member_token");
    let r = client
        .patch(a.url(&format!(
            "/api/parties/{code}/members/{}",
            text(&bob, "member_id")
        )))
        .bearer_auth(&bob_token)
        .json(&json!({"side": "robots", "ready": true}))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    // The store's writer commits within milliseconds.
    tokio::time::sleep(Duration::from_millis(500)).await;
    a.child.kill().expect("SIGKILL");
    a.child.wait().expect("the server dies");

    let b = process::Server::start(&args);
    let room: Value = client
        .get(b.url(&format!("/api/parties/{code}")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let members = room["members"].as_array().unwrap();
    assert_eq!(members.len(), 2, "{room}");
    assert_eq!(members[1]["name"], "bob");
    assert_eq!(members[1]["side"], "robots");
    assert_eq!(members[1]["ready"], true);
    // Bob's token still opens his room's socket.
    let url = format!(
        "{}?token={bob_token}",
        b.url(&format!("/ws/parties/{code}"))
    )
    .replacen("http://", "ws://", 1);
    let (stream, _) = tokio_tungstenite::connect_async(url)
        .await
        .expect("the socket opens");
    let mut ws = Ws { stream };
    let first = ws.next_of("party").await;
    assert_eq!(first["code"], code.as_str());
    // A wrong token is refused before the upgrade.
    let bad = format!("{}?token=nope", b.url(&format!("/ws/parties/{code}")))
        .replacen("http://", "ws://", 1);
    assert!(tokio_tungstenite::connect_async(bad).await.is_err());
}
