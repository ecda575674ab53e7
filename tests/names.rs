//! Names people keep over the real server (docs/api.md, "Names people keep"): a claim and
//! its token, look-alikes and hidden characters refused, joins under a kept name only with
//! its token, the claim given up, and claims priced per client and for everyone.

mod common;

use std::net::{IpAddr, Ipv4Addr};

use common::{TestServer, assert_error, test_config};
use lasertag::config::Config;
use serde_json::{Value, json};

async fn server(what: &str, config: Config) -> TestServer {
    let store = lasertag::store::Store::open(
        &common::temp_dir(what),
        lasertag::store::Retention {
            max_matches: 1000,
            max_bytes: 1 << 30,
        },
    )
    .expect("the store opens");
    TestServer::start_with_history(config, lasertag::game::replay::History::with_store(store)).await
}

/// A client on the loopback address 127.0.0.`last`: another client to the server.
fn client_at(last: u8) -> reqwest::Client {
    reqwest::Client::builder()
        .local_address(IpAddr::V4(Ipv4Addr::new(127, 0, 0, last)))
        .build()
        .unwrap()
}

async fn send(r: reqwest::RequestBuilder) -> common::Reply {
    let r = r.send().await.unwrap();
    let status = r.status().as_u16();
    let text = r.text().await.unwrap();
    common::Reply {
        status,
        body: serde_json::from_str(&text).unwrap_or(Value::Null),
    }
}

async fn claim(s: &TestServer, from: &reqwest::Client, name: &str) -> common::Reply {
    send(from.post(s.url("/api/names")).json(&json!({"name": name}))).await
}

#[tokio::test]
async fn a_kept_name_is_played_only_with_its_token() {
    let s = server("names-kept", test_config()).await;
    let me = client_at(11);
    let stranger = client_at(12);
    let r = claim(&s, &me, "  victim ").await;
    assert_eq!(r.status, 201, "{}", r.body);
    assert_eq!(r.body["name"], "victim", "kept normalised: {}", r.body);
    let token = r.body["name_token"].as_str().unwrap().to_string();
    assert!(token.len() >= 32, "{token}");

    // The name, a case variant and a Cyrillic look-alike are all taken, naming the kept one.
    for copy in ["victim", "Victim", "vi\u{0441}tim", "ｖｉｃｔｉｍ"] {
        let r = claim(&s, &stranger, copy).await;
        assert_error(&r, 409, "\"victim\"");
    }

    // Joining under it: refused without the token or with another, taken with it; a
    // look-alike with the token plays under the kept spelling.
    let id = common::idle_human_match(&s).await;
    let join = |body: Value| {
        send(
            stranger
                .post(s.url(&format!("/api/matches/{id}/players")))
                .json(&body),
        )
    };
    assert_error(&join(json!({"name": "victim"})).await, 403, "name_token");
    assert_error(
        &join(json!({"name": "vi\u{0441}tim"})).await,
        403,
        "\"victim\"",
    );
    assert_error(
        &join(json!({"name": "victim", "name_token": "not-it"})).await,
        403,
        "not the name_token",
    );
    let r = join(json!({"name": "Victim", "name_token": token})).await;
    assert_eq!(r.status, 201, "{}", r.body);
    s.step(&id, 1).await;
    let events = s.events(&id).await;
    assert!(
        events.iter().any(|e| e["name"] == "victim"),
        "joined as the kept spelling: {events:?}"
    );
    // A free name plays, unrated (nothing to check here but that it is let in).
    let other = common::idle_human_match(&s).await;
    let r = send(
        stranger
            .post(s.url(&format!("/api/matches/{other}/players")))
            .json(&json!({"name": "passer-by"})),
    )
    .await;
    assert_eq!(r.status, 201, "{}", r.body);

    // Giving it up: the token is needed, then anyone may claim it.
    let path = s.url("/api/names/victim");
    assert_eq!(send(stranger.delete(&path)).await.status, 401);
    let r = send(stranger.delete(&path).bearer_auth("not-it")).await;
    assert_error(&r, 403, "not the name_token");
    let r = send(me.delete(&path).bearer_auth(&token)).await;
    assert_eq!(r.status, 204, "{}", r.body);
    assert_error(
        &send(me.delete(&path).bearer_auth(&token)).await,
        404,
        "nobody keeps",
    );
    assert_eq!(claim(&s, &stranger, "victim").await.status, 201);
}

#[tokio::test]
async fn names_that_hide_or_reorder_text_are_refused_naming_the_character() {
    let s = server("names-refused", test_config()).await;
    let me = client_at(13);
    for (sent, what) in [
        ("evil\u{202E}gnp", "bidirectional control (U+202E)"),
        ("a\u{2067}b", "bidirectional control (U+2067)"),
        ("vic\u{200B}tim", "invisible character (U+200B)"),
        ("vic\u{2060}tim", "invisible character (U+2060)"),
        ("one\u{2028}two", "line separator (U+2028)"),
        ("flag\u{E0067}", "tag character (U+E0067)"),
        ("bell\u{7}", "control character (U+0007)"),
        ("abcdefghijklmnopqrstuvwxy", "1 to 24"),
        ("   ", "1 to 24"),
    ] {
        let r = claim(&s, &me, sent).await;
        assert_error(&r, 400, what);
        // A join checks the same rules.
        let id = common::idle_human_match(&s).await;
        let r = send(
            me.post(s.url(&format!("/api/matches/{id}/players")))
                .json(&json!({"name": sent})),
        )
        .await;
        assert_error(&r, 400, what);
    }
    assert_eq!(claim(&s, &me, "李小龍").await.status, 201);
    assert_eq!(claim(&s, &me, "Zoë O'Neil").await.status, 201);
}

#[tokio::test]
async fn claims_are_priced_per_client_and_for_everyone() {
    let s = server(
        "names-priced",
        Config {
            max_names_per_address: 2,
            max_names: 5,
            ..test_config()
        },
    )
    .await;
    let a = client_at(21);
    assert_eq!(claim(&s, &a, "a-one").await.status, 201);
    assert_eq!(claim(&s, &a, "a-two").await.status, 201);
    assert_error(&claim(&s, &a, "a-three").await, 429, "keeps 2 names");
    // Others still claim, up to the server's total.
    for (i, last) in [22u8, 23, 24].into_iter().enumerate() {
        let r = claim(&s, &client_at(last), &format!("other-{i}")).await;
        assert_eq!(r.status, 201, "{}", r.body);
    }
    assert_error(&claim(&s, &client_at(25), "late").await, 503, "5 names");

    // The rate for everyone together.
    let s = server(
        "names-rate",
        Config {
            name_claims_per_minute: 3.0,
            ..test_config()
        },
    )
    .await;
    for i in 0..3u8 {
        let r = claim(&s, &client_at(30 + i), &format!("burst-{i}")).await;
        assert_eq!(r.status, 201, "{}", r.body);
    }
    let r = claim(&s, &client_at(40), "one-too-many").await;
    assert_error(&r, 429, "3 claims of names a minute");
}

#[tokio::test]
async fn a_server_without_history_keeps_no_names_and_plays_every_name() {
    let s = TestServer::start().await;
    let r = s.post("/api/names", &json!({"name": "ada"})).await;
    assert_error(&r, 503, "keeps no history");
    let id = common::idle_human_match(&s).await;
    s.join(&id, "ada").await;
}
