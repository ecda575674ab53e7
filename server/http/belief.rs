//! `GET /api/matches/{id}/belief`: the robot team's belief, which a tracker of many
//! particles makes the server's largest answer (a 100,000-particle role is 3.6 MB of JSON).
//!
//! So that readers cannot multiply its cost: each encoding (per robot, sight and thinning,
//! and its gzip'd form) is made at most once a tick, on the blocking pool, and shared by
//! every reader of that tick (`game::encoded`); the response carries its own
//! `Content-Encoding`, which the server's compression layer leaves alone. Every read is
//! charged its bytes against the client's and everyone's belief rate (`--belief-mb-per-s`,
//! `--belief-mb-per-s-all`) before anything is encoded: a big reader gets 429, the server
//! stays as fast for everybody else. `?particles=N` thins each role to at most N particles
//! for readers who do not need every one.

use std::collections::HashMap;
use std::io::Write;
use std::sync::Arc;

use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use flate2::Compression;
use flate2::write::GzEncoder;

use crate::game::delay::HeldBelief;
use crate::game::encoded::Encoded;
use crate::http::auth::Bearer;
use crate::http::error::ApiError;
use crate::http::handlers::readable;
use crate::http::limits::{BeliefBytesSpent, BeliefRefused, ClientIp};
use crate::http::state::AppState;
use crate::metrics::Refusal;
use crate::protocol::{self, Belief, ErrorBody};

/// The most particles a role may be thinned to (more is the whole cloud anyway).
const MAX_THIN: usize = 100_000;
/// Bytes of JSON a particle and its weight take at most (`[-123.456,-78.901]` and
/// `0.000012345678` with their commas), and a role's other fields.
const BYTES_PER_PARTICLE: u64 = 40;
const BYTES_PER_ROLE: u64 = 160;

#[utoipa::path(get, path = "/api/matches/{id}/belief",
    params(("id" = String, Path),
           ("robot" = Option<String>, Query, description = "a robot id (r0, r1, …): that robot's own belief (404 for anything that is not one of the match's robots); without it the team's merged view"),
           ("particles" = Option<u64>, Query, minimum = 1, maximum = 100000, description = "thin each role to at most this many particles (systematic resampling by weight, equal weights after); without it every particle")),
    security((), ("owner_token" = [])),
    responses((status = 200, body = Belief), (status = 400, body = ErrorBody), (status = 401, body = ErrorBody),
              (status = 403, body = ErrorBody), (status = 404, body = ErrorBody),
              (status = 429, body = ErrorBody, description = "this client has read its share of belief bytes for now: retry after `Retry-After`"),
              (status = 503, body = ErrorBody, description = "everyone together has read the server's share of belief bytes for now")))]
pub async fn belief(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
    bearer: Bearer,
    Path(id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let (handle, sight) = readable(&state, &bearer, &id)?;
    let robot = crate::http::replays::robot(&query)?;
    let thin = match query.get("particles") {
        None => None,
        Some(v) => Some(
            v.parse::<usize>()
                .ok()
                .filter(|n| (1..=MAX_THIN).contains(n))
                .ok_or_else(|| {
                    ApiError::bad_request(format!(
                        "particles: {v:?} is not an integer in 1..={MAX_THIN}"
                    ))
                })?,
        ),
    };
    let key = format!("belief/{robot:?}/{sight:?}/{thin:?}");
    let cache = handle.hub.encoded.clone();
    // One trip to the match's task: the tick this reader sees, and a copy of the belief
    // only when nobody has encoded that tick yet.
    let (tick, held) = {
        let (cache, key) = (cache.clone(), key.clone());
        handle
            .read(sight, move |r| {
                let tick = r.belief_tick(robot)?;
                let held = (!cache.has(&key, tick))
                    .then(|| r.belief(robot).map(|b| b.into_owned()))
                    .transpose()?;
                Ok((tick, held))
            })
            .await?
    };
    let cell = cache.cell(&key, tick);
    let bytes = match (cell.get(), &held) {
        (Some(encoded), _) => encoded.bytes.len() as u64,
        (None, Some(held)) => estimate(held, thin),
        // Encoded when asked, gone since (the cache started again): read once more.
        (None, None) => 0,
    };
    charge(&state, ip, bytes)?;
    let pool = state.pool.clone();
    let encoded = match held {
        Some(held) => {
            cell.get_or_try_init(|| async move {
                pool.run("encoding a belief", move || encode(held, robot, thin))
                    .await
                    .map_err(ApiError::from)
            })
            .await?
        }
        None => match cell.get() {
            Some(encoded) => encoded,
            None => {
                return Err(BeliefRefused::MovedOn.into());
            }
        },
    }
    .clone();
    let gzip = headers
        .get(header::ACCEPT_ENCODING)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|v| v.split(',').any(|e| e.trim().starts_with("gzip")));
    let mut response = if gzip {
        let pool = state.pool.clone();
        let source = encoded.clone();
        let body = encoded
            .gzip
            .get_or_try_init(|| async move {
                pool.run("compressing a belief", move || gzipped(&source.bytes))
                    .await
                    .map_err(ApiError::from)
            })
            .await?
            .clone();
        let mut r = body.into_response();
        r.headers_mut()
            .insert(header::CONTENT_ENCODING, HeaderValue::from_static("gzip"));
        r
    } else {
        encoded.bytes.clone().into_response()
    };
    response.headers_mut().insert(
        header::CONTENT_TYPE,
        HeaderValue::from_static("application/json"),
    );
    Ok(response)
}

/// Bytes the JSON of `held` will take at most, thinned to `thin`.
fn estimate(held: &HeldBelief, thin: Option<usize>) -> u64 {
    held.roles
        .iter()
        .map(|r| {
            let n = thin.map_or(r.particles.len(), |t| r.particles.len().min(t));
            BYTES_PER_ROLE + n as u64 * BYTES_PER_PARTICLE
        })
        .sum::<u64>()
        + 64
}

fn charge(state: &AppState, ip: std::net::IpAddr, bytes: u64) -> Result<(), BeliefRefused> {
    let cfg = &state.registry.config;
    let mb = 1024.0 * 1024.0;
    let spent = match state.limits.take_belief_bytes(
        ip,
        bytes,
        cfg.belief_mb_per_s * mb,
        cfg.belief_mb_per_s_all * mb,
    ) {
        Ok(()) => return Ok(()),
        Err(spent) => spent,
    };
    state.registry.metrics.refuse(Refusal::RateLimited);
    let secs = |wait: std::time::Duration| wait.as_secs_f64().ceil().max(1.0) as u32;
    Err(match spent {
        BeliefBytesSpent::Client(wait) => BeliefRefused::Client {
            client: crate::access::ClientKey::of(ip),
            mb_per_s: cfg.belief_mb_per_s,
            retry_s: secs(wait),
        },
        BeliefBytesSpent::Server(wait) => BeliefRefused::Server {
            mb_per_s: cfg.belief_mb_per_s_all,
            retry_s: secs(wait),
        },
    })
}

/// The JSON of `held` (thinned to `thin`), as every reader of its tick gets it.
fn encode(mut held: HeldBelief, robot: Option<usize>, thin: Option<usize>) -> Arc<Encoded> {
    if let Some(n) = thin {
        held.thin(n);
    }
    let belief = protocol::state::belief(&held, robot);
    Arc::new(Encoded {
        bytes: serde_json::to_vec(&belief).unwrap_or_default().into(),
        gzip: Default::default(),
    })
}

/// `bytes` gzip'd at the fast level: a belief is mostly digits, and the slow levels cost
/// several times the CPU for a few percent.
fn gzipped(bytes: &[u8]) -> bytes::Bytes {
    let mut out = GzEncoder::new(Vec::with_capacity(bytes.len() / 4), Compression::fast());
    let _ = out.write_all(bytes);
    out.finish().unwrap_or_default().into()
}
