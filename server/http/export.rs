//! `GET /api/replays/{id}/export`: a replay as JSON lines for research, one line a tick:
//! `{"tick", "state"}` and, when asked, `"belief"`, the same objects as the replay's
//! `/state` and `/belief` at that tick; then always a last line, `{"complete", "lines"}`,
//! with `"from_tick"` and `"reason"` when the server cut the export short (a client that
//! stopped reading, the export's time budget, a server that stops), so that a client can
//! never take a cut export for a whole one, and resumes it with `?from_tick=`.
//!
//! A 10-minute match is 12,000 lines of several kilobytes, so the lines are made on a
//! blocking thread that plays the replay forward and streamed as they come, through a
//! small channel: the server holds a few lines per export, never the file. The last line
//! goes through a channel of its own, so a client that stopped reading still finds it
//! after the lines it had not read. Exports run at most `--max-exports` at a time, of
//! them `--max-exports-per-address` for one client.

use std::collections::HashMap;
use std::convert::Infallible;
use std::future::Future;
use std::pin::Pin;
use std::task::Poll;
use std::time::{Duration, Instant};

use axum::body::{Body, Bytes};
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use tokio::sync::{mpsc, oneshot};
use tokio_util::sync::CancellationToken;

use crate::game::view::Frame;
use crate::http::error::ApiError;
use crate::http::limits::{AddressExport, ClientIp, ExportWatch, ExportsFull};
use crate::http::replays::{find, number};
use crate::http::state::AppState;
use crate::metrics::Refusal;
use crate::protocol::replays::{ExportEnd, ExportLine};
use crate::protocol::{self, ErrorBody};

/// Most lines one export gives (a 15-minute match, tick by tick).
pub const MAX_LINES: u64 = 18_000;
/// Lines made ahead of the client.
const AHEAD: usize = 16;

/// Why the server ended an export before its last tick (the last line's `reason`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Cut {
    /// The client took no line for `--export-stall-s`.
    Stalled,
    /// The client had read nothing for a while when a newcomer found every slot taken.
    GaveWay,
    /// The export ran for `--export-budget-s`.
    Budget,
    /// The server is stopping.
    Shutdown,
    /// The replay could not be played to the tick asked for.
    Replay,
    /// The client went away: nobody reads the last line.
    Gone,
}

impl Cut {
    fn reason(self) -> &'static str {
        match self {
            Cut::Stalled => "stalled: the client read nothing for too long",
            Cut::GaveWay => "gave way: the client read nothing while another waited for the slot",
            Cut::Budget => "budget: the export ran for its most time",
            Cut::Shutdown => "shutdown: the server is stopping",
            Cut::Replay => "replay: the replay could not be played further",
            Cut::Gone => "gone",
        }
    }
}

/// What bounds one export's writer.
struct Bounds {
    stall: Duration,
    until: Instant,
    shutdown: CancellationToken,
}

#[utoipa::path(get, path = "/api/replays/{id}/export",
    params(("id" = String, Path),
           ("from" = Option<u64>, Query, description = "first tick (0)"),
           ("to" = Option<u64>, Query, description = "last tick (the match's last)"),
           ("every" = Option<u64>, Query, minimum = 1, description = "one line every this many ticks (1)"),
           ("belief" = Option<bool>, Query, description = "add the team's belief to each line (false)"),
           ("from_tick" = Option<u64>, Query, description = "resume at this tick (from..=to), as an incomplete export's last line says (from)")),
    responses((status = 200, content_type = "application/x-ndjson", description = "one JSON object a line: {\"tick\", \"state\", \"belief\"?}, then always {\"complete\", \"lines\", \"from_tick\"?, \"reason\"?}"),
              (status = 400, body = ErrorBody), (status = 404, body = ErrorBody),
              (status = 429, body = ErrorBody, description = "this client runs its share of exports"),
              (status = 503, body = ErrorBody, description = "too many exports running")))]
pub async fn export(
    State(state): State<AppState>,
    ClientIp(ip): ClientIp,
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
    let start = number(&query, "from_tick", last, Some(from))?;
    if !(from..=to).contains(&start) {
        return Err(ApiError::bad_request(format!(
            "from_tick: {start} is not an integer in {from}..={to}"
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
    let cfg = &state.registry.config;
    let slot = open_slot(&state, ip).await.map_err(|full| match full {
            ExportsFull::Client => {
                state.registry.metrics.refuse(Refusal::ClientQuota);
                ApiError::new(
                    StatusCode::TOO_MANY_REQUESTS,
                    format!(
                        "exports: this client runs {} export(s), its most; try again when one has finished",
                        cfg.max_exports_per_address
                    ),
                )
            }
            ExportsFull::Server | ExportsFull::GivingWay => {
                state.registry.metrics.refuse(Refusal::Budget);
                ApiError::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    format!(
                        "exports: {} are running, this server's most; try again when one has finished",
                        cfg.max_exports
                    ),
                )
            }
        })?;
    let bounds = Bounds {
        stall: cfg.export_stall,
        until: Instant::now() + cfg.export_budget,
        shutdown: state.registry.shutdown.clone(),
    };
    let (tx, mut rx) = mpsc::channel::<Bytes>(AHEAD);
    let (end_tx, end_rx) = oneshot::channel::<Bytes>();
    state.registry.history.opened(&r);
    // A thread of its own at a lower priority (at most `--max-exports` of them): an export
    // takes the CPU that live matches and requests leave, never theirs.
    let spawned = crate::game::background::spawn("export", move || {
        let watch = slot.watch();
        // The first line's tick: `start`, or the next tick on the grid of `from` and `every`.
        let mut next = start + (every - (start - from) % every) % every;
        let mut sent = 0;
        let cut = (|| {
            if next > to {
                return None;
            }
            let Ok(mut cursor) = r.cursor(next) else {
                return Some(Cut::Replay);
            };
            loop {
                let world = cursor.world();
                let tick = world.tick;
                if tick == next {
                    let frame = Frame::build(world, &Default::default(), 0, 0, true);
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
                    if let Err(cut) = send(&tx, Bytes::from(line), &bounds, watch) {
                        return Some(cut);
                    }
                    sent += 1;
                    next = tick + every;
                }
                if next > to {
                    return None;
                }
                // Past the last tick before `to`, or a stored window that could not be read.
                if !matches!(r.advance(&mut cursor), Ok(true)) {
                    return Some(Cut::Replay);
                }
            }
        })();
        drop(tx);
        if cut == Some(Cut::Gone) {
            return;
        }
        let end = ExportEnd {
            complete: cut.is_none(),
            lines: sent,
            from_tick: cut.map(|_| next),
            reason: cut.map(Cut::reason),
        };
        let mut line = serde_json::to_vec(&end).unwrap_or_default();
        line.push(b'\n');
        let _ = end_tx.send(Bytes::from(line));
    });
    if let Err(e) = spawned {
        return Err(ApiError::new(
            StatusCode::SERVICE_UNAVAILABLE,
            format!("exports: no thread for this one ({e}); try again later"),
        ));
    }
    let mut end = Some(end_rx);
    let body = futures_util::stream::poll_fn(move |cx| {
        match rx.poll_recv(cx) {
            Poll::Ready(Some(line)) => return Poll::Ready(Some(Ok::<_, Infallible>(line))),
            Poll::Pending => return Poll::Pending,
            Poll::Ready(None) => {}
        }
        // Every line is out: the last one follows once the writer has made it.
        let Some(rx) = end.as_mut() else {
            return Poll::Ready(None);
        };
        match Pin::new(rx).poll(cx) {
            Poll::Pending => Poll::Pending,
            Poll::Ready(line) => {
                end = None;
                Poll::Ready(line.ok().map(Ok))
            }
        }
    });
    Ok((
        [(header::CONTENT_TYPE, "application/x-ndjson")],
        Body::from_stream(body),
    )
        .into_response())
}

/// Hands `line` to the response; why not when the client went away, stopped reading, or
/// the export is out of time.
fn send(
    tx: &mpsc::Sender<Bytes>,
    mut line: Bytes,
    bounds: &Bounds,
    watch: &ExportWatch,
) -> Result<(), Cut> {
    let since = Instant::now();
    loop {
        if bounds.shutdown.is_cancelled() {
            return Err(Cut::Shutdown);
        }
        if Instant::now() >= bounds.until {
            return Err(Cut::Budget);
        }
        match tx.try_send(line) {
            Ok(()) => {
                watch.reading();
                return Ok(());
            }
            Err(mpsc::error::TrySendError::Closed(_)) => return Err(Cut::Gone),
            Err(mpsc::error::TrySendError::Full(back)) => {
                watch.stalled();
                if since.elapsed() >= bounds.stall {
                    return Err(Cut::Stalled);
                }
                if watch.asked_to_give_way() {
                    return Err(Cut::GaveWay);
                }
                line = back;
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    }
}

/// How long a newcomer waits for a slot an export that stopped reading gives up.
const GIVE_WAY_WAIT: Duration = Duration::from_secs(2);

/// A slot for an export of `ip`: at once, or once an export whose client stopped reading
/// has given its slot up (within [`GIVE_WAY_WAIT`]).
async fn open_slot(state: &AppState, ip: std::net::IpAddr) -> Result<AddressExport, ExportsFull> {
    let cfg = &state.registry.config;
    let until = Instant::now() + GIVE_WAY_WAIT;
    loop {
        match state
            .limits
            .open_export(ip, cfg.max_exports, cfg.max_exports_per_address)
        {
            Err(ExportsFull::GivingWay) if Instant::now() < until => {
                tokio::time::sleep(Duration::from_millis(20)).await;
            }
            other => return other,
        }
    }
}
