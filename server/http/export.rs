//! `GET /api/replays/{id}/export`: a replay as JSON lines for research, one line a tick:
//! `{"tick", "state"}` and, when asked, `"belief"`, the same objects as the replay's
//! `/state` and `/belief` at that tick.
//!
//! A 10-minute match is 12,000 lines of several kilobytes, so the lines are made on a
//! blocking thread that plays the replay forward and streamed as they come, through a
//! small channel: the server holds a few lines per export, never the file. Exports run at
//! most [`EXPORTS`] at a time, and one whose client stops reading is dropped after
//! [`STALL`].

use std::collections::HashMap;
use std::convert::Infallible;
use std::time::{Duration, Instant};

use axum::body::{Body, Bytes};
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use tokio::sync::{Semaphore, mpsc};

use crate::game::view::Frame;
use crate::http::error::ApiError;
use crate::http::replays::{find, number};
use crate::http::state::AppState;
use crate::protocol::replays::ExportLine;
use crate::protocol::{self, ErrorBody};

/// Exports running at once (each keeps a thread busy re-simulating).
const EXPORTS: usize = 2;
/// Most lines one export gives (a 15-minute match, tick by tick).
pub const MAX_LINES: u64 = 18_000;
/// Lines made ahead of the client.
const AHEAD: usize = 16;
/// How long an export waits for a client that does not read.
const STALL: Duration = Duration::from_secs(30);

static RUNNING: Semaphore = Semaphore::const_new(EXPORTS);

#[utoipa::path(get, path = "/api/replays/{id}/export",
    params(("id" = String, Path),
           ("from" = Option<u64>, Query, description = "first tick (0)"),
           ("to" = Option<u64>, Query, description = "last tick (the match's last)"),
           ("every" = Option<u64>, Query, minimum = 1, description = "one line every this many ticks (1)"),
           ("belief" = Option<bool>, Query, description = "add the team's belief to each line (false)")),
    responses((status = 200, content_type = "application/x-ndjson", description = "one JSON object a line: {\"tick\", \"state\", \"belief\"?}"),
              (status = 400, body = ErrorBody), (status = 404, body = ErrorBody),
              (status = 503, body = ErrorBody, description = "too many exports running")))]
pub async fn export(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    let r = find(&state, &id).await?;
    let last = r.last_tick;
    let from = number(&query, "from", last, Some(0))?;
    let to = number(&query, "to", last, Some(last))?;
    let every = number(&query, "every", last.max(1), Some(1))?;
    if every == 0 {
        // As the document says (minimum 1): a line every 0 ticks is no export.
        return Err(ApiError::bad_request(format!(
            "every: 0 is not an integer in 1..={}",
            last.max(1)
        )));
    }
    if from > to {
        return Err(ApiError::bad_request(format!(
            "from: {from} is after to: {to}"
        )));
    }
    let belief = match query.get("belief").map(String::as_str) {
        None | Some("false") | Some("0") => false,
        Some("true") | Some("1") => true,
        Some(other) => {
            return Err(ApiError::bad_request(format!(
                "belief: {other:?} is not true or false"
            )));
        }
    };
    let lines = (to - from) / every + 1;
    if lines > MAX_LINES {
        return Err(ApiError::bad_request(format!(
            "{lines} lines asked (ticks {from} to {to} every {every}); at most {MAX_LINES} an export: \
             narrow from/to or raise every"
        )));
    }
    let permit = RUNNING.try_acquire().map_err(|_| {
        ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            format!("{EXPORTS} exports are running; try again when one has finished"),
        )
    })?;
    let (tx, mut rx) = mpsc::channel::<Bytes>(AHEAD);
    state.registry.history.opened(&r);
    tokio::task::spawn_blocking(move || {
        let _permit = permit;
        let Ok(mut cursor) = r.cursor(from) else {
            return;
        };
        loop {
            let world = cursor.world();
            let tick = world.tick;
            if (tick - from).is_multiple_of(every) {
                let frame = Frame::build(world, &[], 0, 0, true);
                let state = protocol::state(&frame, &r.meta, r.config());
                let belief = if belief {
                    protocol::belief_of(world, None)
                } else {
                    None
                };
                let mut line = serde_json::to_vec(&ExportLine {
                    tick,
                    state: &state,
                    belief: belief.as_ref(),
                })
                .unwrap_or_default();
                line.push(b'\n');
                if !send(&tx, Bytes::from(line)) {
                    return;
                }
            }
            if tick >= to || !r.advance(&mut cursor) {
                return;
            }
        }
    });
    let body = futures_util::stream::poll_fn(move |cx| {
        rx.poll_recv(cx).map(|line| line.map(Ok::<_, Infallible>))
    });
    Ok((
        [(header::CONTENT_TYPE, "application/x-ndjson")],
        Body::from_stream(body),
    )
        .into_response())
}

/// Hands `line` to the response; false when the client went away or stopped reading.
fn send(tx: &mpsc::Sender<Bytes>, mut line: Bytes) -> bool {
    let since = Instant::now();
    loop {
        match tx.try_send(line) {
            Ok(()) => return true,
            Err(mpsc::error::TrySendError::Closed(_)) => return false,
            Err(mpsc::error::TrySendError::Full(back)) => {
                if since.elapsed() > STALL {
                    return false;
                }
                line = back;
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    }
}
