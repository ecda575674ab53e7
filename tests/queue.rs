//! The queue over a real server: six people who press *Play with others* together are all
//! seated (at most five a match, bots filling for the one left over), each told their seat
//! on the ticket's socket; a ticket leaves; tokens are the tickets'.

mod common;

use common::{Got, TestServer, Ws};
use serde_json::{Value, json};

async fn ticket_ws(s: &TestServer, ticket: &str, token: &str) -> Ws {
    let url = format!("ws://{}/ws/queue/{ticket}?token={token}", s.addr);
    let (stream, _) = tokio_tungstenite::connect_async(url)
        .await
        .expect("the ticket's socket opens");
    Ws { stream }
}

/// The ticket's `matched` message, after any number of `waiting` ones.
async fn matched(ws: &mut Ws) -> (Value, u64) {
    let mut waited = 0;
    loop {
        match ws.next().await {
            Got::Json(v) if v["type"] == "waiting" => {
                assert!(v["people"].as_u64().is_some(), "{v}");
                waited = v["seconds"].as_u64().unwrap();
            }
            Got::Json(v) if v["type"] == "matched" => return (v, waited),
            other => panic!("{other:?}"),
        }
    }
}

#[tokio::test]
async fn six_people_who_queue_together_all_play() {
    let s = TestServer::start_with(lasertag::config::Config {
        // Every test client is 127.0.0.1.
        max_queued_per_address: 100,
        ..common::test_config()
    })
    .await;
    let mut sockets = Vec::new();
    for i in 0..6 {
        let r = s
            .post("/api/queue", &json!({"name": format!("player{i}")}))
            .await;
        assert_eq!(r.status, 202, "{}", r.body);
        let (ticket, token) = (
            r.body["ticket"].as_str().unwrap().to_string(),
            r.body["token"].as_str().unwrap().to_string(),
        );
        assert_eq!(
            s.get_as("/api/queue", None).await.status,
            405,
            "the queue is not listed"
        );
        let r = s
            .delete_as(&format!("/api/queue/{ticket}"), Some("nope"))
            .await;
        assert_eq!(r.status, 403, "{}", r.body);
        sockets.push(ticket_ws(&s, &ticket, &token).await);
    }
    let mut per_match = std::collections::BTreeMap::<String, usize>::new();
    let mut waits = Vec::new();
    for ws in &mut sockets {
        let (seat, waited) = matched(ws).await;
        waits.push(waited);
        let id = seat["match_id"].as_str().unwrap().to_string();
        let mut play = s.ws(&id, seat["token"].as_str()).await.unwrap();
        let welcome = play.next_of("welcome").await;
        assert_eq!(welcome["role"], "player", "{welcome}");
        *per_match.entry(id.clone()).or_default() += 1;
        // An opponent's seat: the people are the hunted.
        assert!(
            welcome["you"].as_str().is_some_and(|y| y.starts_with('o')),
            "{welcome}"
        );
    }
    // A figure for docs/queue.md, not a test: the seconds each waited, as its socket last said.
    println!(
        "six people queued together: seconds waited {waits:?}, people per match {per_match:?}"
    );
    assert!(per_match.values().all(|n| *n <= 5), "{per_match:?}");
    assert_eq!(per_match.values().sum::<usize>(), 6);
}

#[tokio::test]
async fn a_ticket_leaves_and_an_address_holds_few() {
    let s = TestServer::start().await;
    let r = s.post("/api/queue", &json!({"name": "solo"})).await;
    assert_eq!(r.status, 202, "{}", r.body);
    let (ticket, token) = (
        r.body["ticket"].as_str().unwrap().to_string(),
        r.body["token"].as_str().unwrap().to_string(),
    );
    s.post("/api/queue", &json!({"name": "second"})).await;
    let third = s.post("/api/queue", &json!({"name": "third"})).await;
    common::assert_error(&third, 429, "tickets");
    let mut ws = ticket_ws(&s, &ticket, &token).await;
    assert_eq!(ws.json().await["type"], "waiting");
    let r = s
        .delete_as(&format!("/api/queue/{ticket}"), Some(&token))
        .await;
    assert_eq!(r.status, 204, "{}", r.body);
    loop {
        match ws.next().await {
            Got::Json(v) if v["type"] == "waiting" => continue,
            Got::Json(v) => {
                assert_eq!(v["type"], "error", "{v}");
                break;
            }
            other => panic!("{other:?}"),
        }
    }
    let r = s
        .delete_as(&format!("/api/queue/{ticket}"), Some(&token))
        .await;
    assert_eq!(r.status, 404, "{}", r.body);
}
