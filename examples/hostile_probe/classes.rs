//! The classes of hostile request: each builds its requests, sends them and says what came
//! back.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use crate::harness::{Ctx, empty_map, error_text, joined, ms_since, r3, send, shorten};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;

#[derive(Debug, Clone, Copy)]
pub(crate) enum Class {
    Slivers(usize),
    ExpensiveMatch,
    Landmarks,
    SpawnsAndObstacles,
    Slowloris,
    MatchTable,
    StrangerDelete,
    Wallhack,
    LobbyStall,
    CommandCost,
    InputsGrowth,
    CommandMemory,
    SeedOracle,
    EventsFog,
    SlowExport,
    ConnFlood,
    SeatHold,
    IdleSpectators,
    ReplayCost,
    ReplayMemory,
    DiskMaps,
    SearchPlanner,
    BeliefLoop,
    NameClaims,
    QuicDatagrams,
    QuicSessions,
}

pub(crate) const CLASSES: [Class; 27] = [
    Class::Slivers(64),
    Class::Slivers(256),
    Class::ExpensiveMatch,
    Class::Landmarks,
    Class::SpawnsAndObstacles,
    Class::Slowloris,
    Class::MatchTable,
    Class::StrangerDelete,
    Class::Wallhack,
    Class::LobbyStall,
    Class::CommandCost,
    Class::InputsGrowth,
    Class::CommandMemory,
    Class::SeedOracle,
    Class::EventsFog,
    Class::SlowExport,
    Class::ConnFlood,
    Class::SeatHold,
    Class::IdleSpectators,
    Class::ReplayCost,
    Class::ReplayMemory,
    Class::DiskMaps,
    Class::SearchPlanner,
    Class::BeliefLoop,
    Class::NameClaims,
    Class::QuicDatagrams,
    Class::QuicSessions,
];

impl Class {
    pub(crate) fn name(self) -> String {
        match self {
            Class::Slivers(n) => format!("map-{n}-slivers"),
            Class::ExpensiveMatch => "expensive-match".into(),
            Class::Landmarks => "landmarks".into(),
            Class::SpawnsAndObstacles => "spawns-obstacles".into(),
            Class::Slowloris => "slowloris".into(),
            Class::MatchTable => "match-table".into(),
            Class::StrangerDelete => "stranger-delete".into(),
            Class::Wallhack => "wallhack".into(),
            Class::LobbyStall => "lobby-stall".into(),
            Class::CommandCost => "command-cost".into(),
            Class::InputsGrowth => "inputs-growth".into(),
            Class::CommandMemory => "command-memory".into(),
            Class::SeedOracle => "seed-oracle".into(),
            Class::EventsFog => "events-fog".into(),
            Class::SlowExport => "slow-export".into(),
            Class::ConnFlood => "conn-flood".into(),
            Class::SeatHold => "seat-hold".into(),
            Class::IdleSpectators => "idle-spectators".into(),
            Class::ReplayCost => "replay-cost".into(),
            Class::ReplayMemory => "replay-memory".into(),
            Class::DiskMaps => "disk-maps".into(),
            Class::SearchPlanner => "search-planner".into(),
            Class::BeliefLoop => "belief-loop".into(),
            Class::NameClaims => "name-claims".into(),
            Class::QuicDatagrams => "quic-datagrams".into(),
            Class::QuicSessions => "quic-sessions".into(),
        }
    }

    /// Flags the class's server starts with besides the probe's own: every class runs the
    /// defaults but `disk-maps`, which asks for a small history to see it held.
    pub(crate) fn server_flags(self) -> &'static [&'static str] {
        match self {
            Class::DiskMaps => &["--keep-mb", "1"],
            _ => &[],
        }
    }
}

/// What a class's requests got.
#[derive(Debug, Default)]
pub(crate) struct Outcome {
    pub(crate) status: String,
    pub(crate) request_ms: Option<f64>,
    pub(crate) note: String,
}

impl Outcome {
    /// A report of `doors.rs`'s classes.
    fn of((status, request_ms, note): crate::doors::Report) -> Outcome {
        Outcome {
            status,
            request_ms,
            note,
        }
    }
}

pub(crate) async fn attack(class: Class, ctx: &Ctx) -> Result<Outcome, String> {
    match class {
        Class::Slivers(n) => one_post(ctx, "/api/maps", &slivers(n)).await,
        Class::ExpensiveMatch => {
            let body = json!({"map": empty_map(500.0), "robots": 8, "opponents": 8,
                              "radio": {"loss": 0.5}, "tracker": {"grid_cell": 0.1}});
            one_post(ctx, "/api/matches", &body).await
        }
        Class::Landmarks => landmarks(ctx).await,
        Class::SpawnsAndObstacles => one_post(ctx, "/api/maps", &crowded(2000, 2000)).await,
        Class::Slowloris => slowloris(ctx).await,
        Class::MatchTable => match_table(ctx).await,
        Class::StrangerDelete => stranger_delete(ctx).await,
        Class::Wallhack => wallhack(ctx).await,
        Class::LobbyStall => lobby_stall(ctx).await,
        Class::CommandCost => outcome(crate::costs::command_cost(ctx).await?),
        Class::InputsGrowth => outcome(crate::costs::inputs_growth(ctx).await?),
        Class::CommandMemory => outcome(crate::costs::command_memory(ctx).await?),
        Class::SeedOracle => crate::fair::seed_oracle(ctx).await.map(Outcome::from),
        Class::EventsFog => crate::fair::events_fog(ctx).await.map(Outcome::from),
        Class::SlowExport => crate::doors::slow_export(ctx).await.map(Outcome::of),
        Class::ConnFlood => crate::doors::conn_flood(ctx).await.map(Outcome::of),
        Class::SeatHold => crate::doors::seat_hold(ctx).await.map(Outcome::of),
        Class::IdleSpectators => crate::doors::idle_spectators(ctx).await.map(Outcome::of),
        Class::ReplayCost => crate::history::replay_cost(ctx).await.map(Outcome::of),
        Class::ReplayMemory => crate::history::replay_memory(ctx).await.map(Outcome::of),
        Class::DiskMaps => crate::history::disk_maps(ctx).await.map(Outcome::of),
        Class::SearchPlanner => crate::priced::search_planner(ctx).await.map(Outcome::of),
        Class::BeliefLoop => crate::priced::belief_loop(ctx).await.map(Outcome::of),
        Class::NameClaims => crate::priced::name_claims(ctx).await.map(Outcome::of),
        Class::QuicDatagrams => crate::quic::datagrams(ctx).await.map(Outcome::of),
        Class::QuicSessions => crate::quic::sessions(ctx).await.map(Outcome::of),
    }
}

impl From<crate::fair::Found> for Outcome {
    fn from(f: crate::fair::Found) -> Outcome {
        Outcome {
            status: f.status,
            request_ms: f.request_ms,
            note: f.note,
        }
    }
}

/// A class's statuses, time and note as its outcome.
fn outcome((status, ms, note): (String, f64, String)) -> Result<Outcome, String> {
    Ok(Outcome {
        status,
        request_ms: Some(ms),
        note,
    })
}

/// 500 m, `n` thin obstacles from near (10, 20) to (470, 480): the shape `tests/hostile.rs`
/// sends, a few KB whose long diagonal walls cost the most to build.
pub(crate) fn slivers(n: usize) -> Value {
    let obstacles: Vec<Value> = (0..n)
        .map(|k| {
            let y = r3(20.0 + k as f64 * 0.02);
            json!([
                [10.0, y],
                [470.0, r3(y + 460.0)],
                [470.5, r3(y + 460.0)],
                [10.5, y]
            ])
        })
        .collect();
    json!({"name": "slivers", "width": 500.0, "height": 500.0, "obstacles": obstacles,
           "robot_spawns": [[2.0, 2.0, 0.0]], "opponent_spawns": [[498.0, 2.0]]})
}

/// The shipped office with `n` landmarks spread over it (the R2 low-discrepancy sequence),
/// at whole metres so that 100,000 of them fit in a body under 1 MiB.
pub(crate) fn office_with_landmarks(n: usize) -> Result<Value, String> {
    let mut m: Value = serde_json::from_str(include_str!("../../maps/office.json"))
        .map_err(|e| format!("maps/office.json: {e}"))?;
    let (w, h) = (
        m["width"].as_f64().unwrap_or(24.0),
        m["height"].as_f64().unwrap_or(16.0),
    );
    let (a1, a2) = (0.754_877_666_246_692_8, 0.569_840_290_998_053_3);
    // Whole metres as JSON integers (`12`, not `12.0`): 7 bytes a landmark.
    let landmarks: Vec<[u32; 2]> = (1..=n)
        .map(|k| {
            let k = k as f64;
            let at = |a: f64, side: f64| ((k * a).fract() * side).round() as u32;
            [at(a1, w), at(a2, h)]
        })
        .collect();
    m["name"] = json!("landmarks");
    m["landmarks"] = json!(landmarks);
    Ok(m)
}

/// 200 m with `squares` 0.5 m squares on a lattice and `spawns` spawns between them (half
/// for robots, half for opponents), each about 2 m from the nearest square.
pub(crate) fn crowded(spawns: usize, squares: usize) -> Value {
    let k = (squares as f64).sqrt().ceil() as usize;
    let s = 200.0 / k as f64;
    let obstacles: Vec<Value> = (0..squares)
        .map(|i| {
            let (cx, cy) = ((i % k) as f64 * s + s / 2.0, (i / k) as f64 * s + s / 2.0);
            let (x0, x1, y0, y1) = (r3(cx - 0.25), r3(cx + 0.25), r3(cy - 0.25), r3(cy + 0.25));
            json!([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
        })
        .collect();
    // Between two rows of squares, above a column's centre; then between two columns.
    let between_rows =
        (0..k - 1).flat_map(|j| (0..k).map(move |i| ((i as f64 + 0.5) * s, (j + 1) as f64 * s)));
    let between_columns =
        (0..k).flat_map(|j| (0..k - 1).map(move |i| ((i + 1) as f64 * s, (j as f64 + 0.5) * s)));
    let points: Vec<(f64, f64)> = between_rows.chain(between_columns).take(spawns).collect();
    let (robots, opponents) = points.split_at(points.len() / 2);
    json!({"name": "crowded", "width": 200.0, "height": 200.0, "obstacles": obstacles,
           "robot_spawns": robots.iter().map(|&(x, y)| [r3(x), r3(y), 0.0]).collect::<Vec<_>>(),
           "opponent_spawns": opponents.iter().map(|&(x, y)| [r3(x), r3(y)]).collect::<Vec<_>>()})
}

pub(crate) fn body_size(body: &Value) -> String {
    let n = serde_json::to_vec(body).map_or(0, |b| b.len());
    if n >= 10_000 {
        format!("{} KB body", n / 1000)
    } else {
        format!("{n} B body")
    }
}

/// One request: its status, time and what it said.
pub(crate) async fn one_post(ctx: &Ctx, path: &str, body: &Value) -> Result<Outcome, String> {
    let a = ctx.post(path, body, None).await?;
    Ok(Outcome {
        status: a.status.to_string(),
        request_ms: Some(a.ms),
        note: joined(&[&body_size(body), &a.gist()]),
    })
}

/// Ticks per second over `d` of the bystander and of another match (read from the listing,
/// which is live for every match).
pub(crate) async fn tick_rates(ctx: &Ctx, other: &str, d: Duration) -> Result<(f64, f64), String> {
    let t0 = Instant::now();
    let (b0, o0) = (
        ctx.public_tick(&ctx.bystander).await?,
        ctx.listed_tick(other).await?,
    );
    tokio::time::sleep(d).await;
    let (b1, o1) = (
        ctx.public_tick(&ctx.bystander).await?,
        ctx.listed_tick(other).await?,
    );
    let s = t0.elapsed().as_secs_f64();
    Ok((
        b1.saturating_sub(b0) as f64 / s,
        o1.saturating_sub(o0) as f64 / s,
    ))
}

pub(crate) async fn landmarks(ctx: &Ctx) -> Result<Outcome, String> {
    let body = json!({"map": office_with_landmarks(100_000)?});
    let a = ctx.post("/api/matches", &body, None).await?;
    let mut note = joined(&[&body_size(&body), &a.gist()]);
    if a.status == 201
        && let Some(id) = a.body["id"].as_str()
    {
        // What admitting it did to everyone else: the bystander's rate over the next 5 s,
        // and what the match's own ticks cost (its task's stats).
        let (bystander, own) = tick_rates(ctx, id, Duration::from_secs(5)).await?;
        note += &format!(
            "; over the 5 s after admission the bystander ran {bystander:.1} ticks/s, this match {own:.1}"
        );
        if let Ok(s) = ctx.get(&format!("/api/matches/{id}/stats")).await {
            let f = |k: &str| {
                s.body[k]
                    .as_f64()
                    .map_or("?".into(), |us| format!("{:.0}", us / 1e3))
            };
            note += &format!(
                "; its ticks: mean {} ms, p99 {} ms, max {} ms, {} late",
                f("tick_us_mean"),
                f("tick_us_p99"),
                f("tick_us_max"),
                s.body["late_ticks"]
            );
        }
    }
    Ok(Outcome {
        status: a.status.to_string(),
        request_ms: Some(a.ms),
        note,
    })
}

/// Connections that send half a header, how long the server keeps them, and whether it
/// still answers others meanwhile.
pub(crate) async fn slowloris(ctx: &Ctx) -> Result<Outcome, String> {
    const CONNECTIONS: usize = 300;
    const WAIT: Duration = Duration::from_secs(15);
    let opened = Instant::now();
    let mut held = Vec::new();
    let mut failed = 0;
    for _ in 0..CONNECTIONS {
        let Ok(mut stream) = TcpStream::connect(ctx.addr).await else {
            failed += 1;
            continue;
        };
        if stream
            .write_all(b"GET /api/health HTTP/1.1\r\nHost: probe\r\n")
            .await
            .is_err()
        {
            failed += 1;
            continue;
        }
        // Reads until the server closes (a 408 or the like may come first): when it did.
        held.push(tokio::spawn(async move {
            let mut buf = [0u8; 512];
            loop {
                match stream.read(&mut buf).await {
                    Ok(0) | Err(_) => return opened.elapsed(),
                    Ok(_) => {}
                }
            }
        }));
    }
    tokio::time::sleep_until((opened + WAIT).into()).await;
    // A newcomer on a connection of its own.
    let fresh = reqwest::Client::builder()
        .pool_max_idle_per_host(0)
        .timeout(Duration::from_secs(5))
        .build()
        .map_err(|e| error_text(&e))?;
    let answer = send(fresh.get(ctx.url("/api/health"))).await;
    let opened_count = held.len();
    let mut closed_after = Vec::new();
    for h in held {
        if h.is_finished() {
            closed_after.extend(h.await.ok().map(|d| d.as_secs_f64()));
        } else {
            h.abort(); // drops the stream: our side closes
        }
    }
    let still_open = opened_count - closed_after.len();
    closed_after.sort_by(f64::total_cmp);
    let median = closed_after
        .get(closed_after.len() / 2)
        .map_or(String::new(), |s| format!(", the median at {s:.1} s"));
    let (status, ms) = match &answer {
        Ok(a) => (format!("health {}", a.status), Some(a.ms)),
        Err(e) => (format!("health: {}", shorten(e, 60)), None),
    };
    Ok(Outcome {
        status,
        request_ms: ms,
        note: format!(
            "{} of {} half-sent connections closed by the server within {} s{median}; {still_open} still open; {failed} failed to open",
            closed_after.len(),
            opened_count,
            WAIT.as_secs()
        ),
    })
}

pub(crate) async fn match_table(ctx: &Ctx) -> Result<Outcome, String> {
    const TRIES: usize = 100;
    let body = json!({"map": "office", "clock": "manual", "planner": "idle"});
    let t = Instant::now();
    let mut statuses: BTreeMap<u16, usize> = BTreeMap::new();
    let mut first_refusal = None;
    for _ in 0..TRIES {
        let a = ctx.post("/api/matches", &body, None).await?;
        *statuses.entry(a.status).or_default() += 1;
        if a.status != 201 && first_refusal.is_none() {
            first_refusal = Some(a.gist());
        }
    }
    let status: Vec<String> = statuses.iter().map(|(s, n)| format!("{n}×{s}")).collect();
    let admitted = statuses.get(&201).copied().unwrap_or(0);
    Ok(Outcome {
        status: status.join(", "),
        request_ms: Some(ms_since(t)),
        note: format!(
            "{admitted} of {TRIES} admitted (the bystander is one more from the same address); first refusal: {}",
            first_refusal.unwrap_or_else(|| "none".into())
        ),
    })
}

pub(crate) async fn stranger_delete(ctx: &Ctx) -> Result<Outcome, String> {
    let (_, id, token) = ctx
        .create(&json!({"map": "office", "clock": "manual", "planner": "idle"}))
        .await?;
    let path = format!("/api/matches/{id}");
    let d = send(ctx.http.delete(ctx.url(&path))).await?;
    let after = ctx.get(&path).await?;
    let fate = match after.status {
        404 => "gone: deleted by a stranger",
        200 => "still there",
        _ => "?",
    };
    Ok(Outcome {
        status: d.status.to_string(),
        request_ms: Some(d.ms),
        note: joined(&[
            &format!(
                "owner_token handed out: {}; GET afterwards {} ({fate})",
                if token.is_some() { "yes" } else { "no" },
                after.status,
            ),
            &d.gist(),
        ]),
    })
}

pub(crate) async fn wallhack(ctx: &Ctx) -> Result<Outcome, String> {
    let (created, id, _) = ctx
        .create(&json!({"map": "office", "opponent_control": "human"}))
        .await?;
    let join = ctx
        .post(
            &format!("/api/matches/{id}/players"),
            &json!({"name": "x"}),
            None,
        )
        .await?;
    // Far enough into the match that a live state cannot pass for the first frame.
    tokio::time::sleep(Duration::from_secs(1)).await;
    let t = Instant::now();
    let public1 = ctx.public_tick(&id).await?;
    let read_ms = ms_since(t);
    let live1 = ctx.listed_tick(&id).await?;
    tokio::time::sleep(Duration::from_secs(2)).await;
    let public2 = ctx.public_tick(&id).await?;
    let live2 = ctx.listed_tick(&id).await?;
    let verdict = if public2 + 20 >= live2 {
        "the public state is live"
    } else {
        "the public state is held back"
    };
    Ok(Outcome {
        status: format!("join {}, state 200", join.status),
        request_ms: Some(read_ms),
        note: format!(
            "public tick {public1} → {public2}, live tick {live1} → {live2} (2 s apart): {verdict}; spectator_delay_s {}",
            created
                .body
                .get("spectator_delay_s")
                .unwrap_or(&json!("absent"))
        ),
    })
}

pub(crate) async fn lobby_stall(ctx: &Ctx) -> Result<Outcome, String> {
    // The manual match of `tests/hostile.rs` (8 robots, 8 bots, warehouse, a time limit past
    // 20,000 ticks) with idle robots: hunting, they win within a few hundred ticks and the
    // step ends early; idle, every one of the 20,000 ticks is stepped.
    let (_, id, token) = ctx
        .create(
            &json!({"map": "warehouse", "clock": "manual", "robots": 8, "opponents": 8,
                        "planner": "idle", "time_limit_s": 3600}),
        )
        .await?;
    let step = tokio::spawn(send(
        Ctx::with_token(
            ctx.http.post(ctx.url(&format!("/api/matches/{id}/step"))),
            token.as_deref(),
        )
        .json(&json!({"ticks": 20000})),
    ));
    let mut latencies = Vec::new();
    let mut failed = 0;
    while !step.is_finished() && Instant::now() < ctx.give_up {
        match ctx.get("/api/matches").await {
            Ok(a) if a.status == 200 => latencies.push(a.ms),
            _ => failed += 1,
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    latencies.sort_by(f64::total_cmp);
    let listing = format!(
        "listing read {} times during the step: max {:.0} ms, median {:.1} ms{}",
        latencies.len(),
        latencies.last().copied().unwrap_or(f64::NAN),
        latencies
            .get(latencies.len() / 2)
            .copied()
            .unwrap_or(f64::NAN),
        if failed > 0 {
            format!(", {failed} failed")
        } else {
            String::new()
        }
    );
    if !step.is_finished() {
        step.abort();
        return Ok(Outcome {
            status: "step unanswered".into(),
            request_ms: None,
            note: format!("the step was still running when the probe gave up; {listing}"),
        });
    }
    let a = step.await.map_err(|e| e.to_string())??;
    Ok(Outcome {
        status: format!("step {}", a.status),
        request_ms: Some(a.ms),
        note: format!(
            "{listing}; the step reached tick {} ({}){}",
            a.body["tick"],
            a.body["status"].as_str().unwrap_or("?"),
            if a.status == 200 {
                String::new()
            } else {
                format!("; {}", a.gist())
            }
        ),
    })
}
