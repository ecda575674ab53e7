//! Fair play, tried as an attacker would: rebuild a match people may join from what is
//! public (`seed-oracle`), and listen on a player's socket for what it cannot see
//! (`events-fog`).

use std::time::{Duration, Instant};

use futures_util::StreamExt;
use serde_json::{Value, json};

use crate::harness::{Ctx, ms_since, send};

/// What a fair-play class found (`classes::Outcome` is made of it).
pub(crate) struct Found {
    pub(crate) status: String,
    pub(crate) request_ms: Option<f64>,
    pub(crate) note: String,
}

/// Every robot's `[x, y]` in a state.
fn robots(state: &Value) -> Vec<[f64; 2]> {
    state["robots"]
        .as_array()
        .map(|rs| {
            rs.iter()
                .map(|r| {
                    [
                        r["x"].as_f64().unwrap_or(f64::NAN),
                        r["y"].as_f64().unwrap_or(f64::NAN),
                    ]
                })
                .collect()
        })
        .unwrap_or_default()
}

/// A match people may join (a human slot nobody has taken, real time), and a stranger who
/// copies it from the listing: the settings it echoes and its seed, as a headless manual
/// match with no people (so live), stepped to the tick of the live truth (read with the
/// owner's token, to measure). How far the copy's robots are from the live ones says
/// whether the public summary is an oracle. The showcase's listed seed is reported too.
pub(crate) async fn seed_oracle(ctx: &Ctx) -> Result<Found, String> {
    let (_, id, token) = ctx
        .create(&json!({"map": "office", "robots": 2, "opponents": 1,
                        "opponent_control": "human"}))
        .await?;
    tokio::time::sleep(Duration::from_secs(1)).await;
    let t = Instant::now();
    let listing = ctx.get("/api/matches").await?;
    let read_ms = ms_since(t);
    let find = |pred: &dyn Fn(&Value) -> bool| {
        listing
            .body
            .as_array()
            .and_then(|l| l.iter().find(|m| pred(m)).cloned())
    };
    let public = find(&|m| m["id"] == id.as_str()).ok_or("the match is not listed")?;
    let showcase = find(&|m| m["id"].as_str().is_some_and(|i| i.starts_with("showcase"))).map_or(
        "no showcase".to_string(),
        |m| {
            format!(
                "the showcase's listed seed: {}",
                m.get("seed").unwrap_or(&json!("absent"))
            )
        },
    );
    let seed = public.get("seed").cloned().unwrap_or(Value::Null);
    let mut copy = json!({"clock": "manual", "opponent_control": "api"});
    for field in [
        "map",
        "robots",
        "opponents",
        "opponent_bot",
        "planner",
        "tracker",
        "coordination",
        "localisation",
        "radio",
        "odometry",
        "localiser",
        "time_limit_s",
    ] {
        if let Some(v) = public.get(field) {
            copy[field] = v.clone();
        }
    }
    if seed.is_u64() {
        copy["seed"] = seed.clone();
    }
    let (_, copy_id, copy_token) = ctx.create(&copy).await?;
    // The live truth now, as only its owner may read it.
    let live = send(Ctx::with_token(
        ctx.http.get(ctx.url(&format!("/api/matches/{id}"))),
        token.as_deref(),
    ))
    .await?;
    let tick = live.body["tick"]
        .as_u64()
        .ok_or_else(|| format!("the live state: {} {}", live.status, live.gist()))?;
    let stepped = ctx
        .post(
            &format!("/api/matches/{copy_id}/step"),
            &json!({"ticks": tick}),
            copy_token.as_deref(),
        )
        .await?;
    let off = robots(&live.body)
        .iter()
        .zip(robots(&stepped.body))
        .map(|(p, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
        .fold(0.0, f64::max);
    let verdict = if seed.is_u64() {
        format!(
            "seed {seed} public: the copy's robots are {off:.4} m off the live ones at tick {tick}"
        )
    } else {
        format!(
            "seed {seed} in the listing: no copy can be made (one guessing seed 0 is {off:.4} m off at tick {tick})"
        )
    };
    Ok(Found {
        status: format!("listing {}, copy step {}", listing.status, stepped.status),
        request_ms: Some(read_ms),
        note: format!("{verdict}; {showcase}"),
    })
}

/// Two rooms with no line of sight between them.
fn two_rooms() -> Value {
    json!({
        "name": "two-rooms", "width": 14.0, "height": 8.0,
        "obstacles": [[[6.5, 0.0], [7.5, 0.0], [7.5, 8.0], [6.5, 8.0]]],
        "robot_spawns": [[10.0, 4.0, 0.0]],
        "opponent_spawns": [[2.0, 4.0], [12.0, 4.0]]
    })
}

/// A player (o0) alone in one room while a robot hunts o1 in the other, the match stepped by
/// its owner a tick at a time with a 1 s (20-tick) delay: the events about the robot and o1
/// (which o0 cannot see) that reached o0's socket before spectators saw their tick.
pub(crate) async fn events_fog(ctx: &Ctx) -> Result<Found, String> {
    let (created, id, token) = ctx
        .create(&json!({"map": two_rooms(), "robots": 1, "opponents": 2,
            "opponent_control": "human", "planner": "coordinated", "clock": "manual",
            "time_limit_s": 60, "spectator_delay_s": 1,
            "robot_starts": [[10.0, 4.0, 0.0]], "opponent_starts": [[2.0, 4.0], [12.0, 4.0]]}))
        .await?;
    let delay = (created.body["spectator_delay_s"].as_f64().unwrap_or(0.0) * 20.0) as u64;
    let join = ctx
        .post(
            &format!("/api/matches/{id}/players"),
            &json!({"name": "ada"}),
            None,
        )
        .await?;
    let player = join.body["token"].as_str().ok_or("no player token")?;
    let url = format!("ws://{}/ws/matches/{id}?token={player}", ctx.addr);
    let (mut ws, _) = tokio_tungstenite::connect_async(url)
        .await
        .map_err(|e| format!("the player's socket: {e}"))?;
    // (tick of the live match when it came, the event)
    let mut heard: Vec<(u64, Value)> = Vec::new();
    let mut now = 0;
    let mut tagged_at = None;
    while Instant::now() < ctx.give_up && now < 600 {
        let step = ctx
            .post(
                &format!("/api/matches/{id}/step"),
                &json!({"ticks": 1}),
                token.as_deref(),
            )
            .await?;
        now = step.body["tick"]
            .as_u64()
            .ok_or("the step answered no tick")?;
        while let Ok(Some(Ok(m))) = tokio::time::timeout(Duration::from_millis(30), ws.next()).await
        {
            if let Ok(v) = serde_json::from_str::<Value>(m.to_text().unwrap_or(""))
                && v["type"] == "event"
            {
                heard.push((now, v));
            }
        }
        let tag = heard
            .iter()
            .find(|(_, e)| e["kind"] == "tag")
            .map(|(_, e)| e.clone());
        if tagged_at.is_none() && step.body["opponents"][1]["tagged"] == true {
            tagged_at = Some(now);
        }
        if tag.is_some() || tagged_at.is_some_and(|t| now > t + delay + 20) {
            break;
        }
    }
    let unseen: Vec<&(u64, Value)> = heard
        .iter()
        .filter(|(_, e)| matches!(e["kind"].as_str(), Some("shot" | "tag")))
        .filter(|(_, e)| e["by"] != "o0" && e["target"] != "o0" && e["hit"] != "o0")
        .collect();
    let early = unseen
        .iter()
        .filter(|(at, e)| e["tick"].as_u64().is_some_and(|t| *at < t + delay))
        .count();
    Ok(Found {
        status: format!("join {}", join.status),
        request_ms: None,
        note: format!(
            "o1 tagged at tick {}; {} shots and tags out of o0's sight reached its socket, {early} of them before spectators saw their tick ({} ticks late)",
            tagged_at.map_or("-".to_string(), |t| t.to_string()),
            unseen.len(),
            delay
        ),
    })
}
