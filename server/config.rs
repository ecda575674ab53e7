//! The server's settings: every limit, grace period and time-out of the shell in one struct.
//!
//! [`Config`] is both the `serve` command's flags (each with a `LASERTAG_*` environment
//! variable, shown by `--help`) and what the tests build with tiny values. The defaults are
//! written once, here, and used by both [`Default`] and clap. None of this reaches the core:
//! a match's own settings (robots, particles, time limit) are checked against it at the edge.

use std::time::Duration;

// For `.map` on the integer parsers of the flags.
use clap::builder::TypedValueParser as _;

/// Default of each setting (see the field docs of [`Config`]).
pub mod defaults {
    pub const MAX_MATCHES: usize = 100;
    pub const MAX_AGENTS_PER_MATCH: usize = 40;
    pub const MAX_PARTICLES_PER_MATCH: usize = 200_000;
    pub const MAX_PLAYERS_PER_MATCH: usize = 32;
    pub const MAX_SPECTATORS_PER_MATCH: usize = 200;
    pub const MAX_SPECTATORS_PER_ADDRESS: usize = 10;
    pub const MAX_CONNECTIONS_PER_ADDRESS: usize = 64;
    pub const REQUESTS_PER_S: f64 = 100.0;
    pub const REQUEST_BURST: f64 = 200.0;
    pub const MESSAGES_PER_S: f64 = 30.0;
    pub const MESSAGE_BURST: f64 = 40.0;
    pub const MAX_BODY_BYTES: usize = 1 << 20;
    pub const MAX_MESSAGE_BYTES: usize = 4096;
    pub const FINISHED_GRACE: &str = "300";
    pub const ABANDONED_AFTER: &str = "120";
    pub const RECONNECT_GRACE: &str = "30";
    pub const MAX_MATCHES_PER_ADDRESS: usize = 8;
    pub const MAX_MAPS: usize = 200;
    pub const MAX_MAPS_PER_ADDRESS: usize = 10;
    pub const MAX_POLICIES: usize = 32;
    pub const MAX_POLICIES_PER_ADDRESS: usize = 4;
    pub const MAX_POLICY_BYTES: usize = 16 << 20;
    pub const MAX_POLICY_INFERENCE_US: u64 = 1000;
    pub const IDLE_MANUAL_AFTER: &str = "600";
    pub const MAX_CONNECTIONS: usize = 4096;
    pub const MAX_WEBTRANSPORT_SESSIONS: usize = 200;
    pub const MAX_REQUEST_MEMORY_MB: u64 = 512;
    pub const MAX_BUILD_S: f64 = 2.0;
    pub const MAX_TICK_MS: f64 = 20.0;
    pub const MEMORY_BUDGET_MB: u64 = 4096;
    pub const DISK_BUDGET_MB: u64 = 2048;
    pub const TICK_OVERRUN_MS: f64 = 50.0;
    pub const JOIN_HOLD: &str = "10";
    pub const MAX_HOLDS_PER_ADDRESS: usize = 1;
    pub const CLIENT_BUDGET_SHARE: f64 = 0.25;
    pub const MAX_COMMAND_WORK: u64 = 2_000_000;
    pub const COMMAND_WORK_PER_S: f64 = 20e6;

    /// Replays re-simulated at once: half the cores (at least one), so that replays leave
    /// the others to matches and to building them.
    pub fn replay_jobs() -> usize {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        cores.div_ceil(2)
    }
    pub const MAX_EXPORTS: usize = 2;
    pub const MAX_EXPORTS_PER_ADDRESS: usize = 1;
    pub const EXPORT_STALL: &str = "30";
    pub const EXPORT_BUDGET: &str = "300";
    pub const MAX_TCP_PER_ADDRESS: usize = 256;
    pub const MAX_SEATS_PER_ADDRESS: usize = 2;
    pub const MAX_NAMES_PER_ADDRESS: u64 = 5;
    pub const MAX_NAMES: u64 = 100_000;
    pub const NAME_CLAIMS_PER_MINUTE: f64 = 60.0;
    pub const BELIEF_MB_PER_S: f64 = 4.0;
    pub const BELIEF_MB_PER_S_ALL: f64 = 32.0;
    pub const MAX_PARTIES: usize = 1_000;
    pub const MAX_PARTIES_PER_ADDRESS: usize = 3;
    pub const PARTY_MISSES_PER_MINUTE: f64 = 10.0;
    pub const MAX_QUEUED: usize = 2_000;
    pub const MAX_QUEUED_PER_ADDRESS: usize = 2;

    /// Tick milliseconds all matches together may be priced at: twice every core's 50 ms at
    /// 20 Hz. A match is priced at its p99 tick, and the heavy ticks of different matches
    /// seldom fall in the same 50 ms: 2 cores ran 240 load-test matches (priced at 0.91 ms
    /// each, 219 ms in all) and 2,000 spectators at 20 Hz, 300 at 19.4 Hz
    /// (docs/performance.md), so the budget admits about 219 of them.
    pub fn tick_budget_ms() -> f64 {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        TICKS_OVERLAP * 50.0 * cores as f64
    }
    /// See [`tick_budget_ms`].
    const TICKS_OVERLAP: f64 = 2.0;
    pub const HEADER_READ_TIMEOUT: &str = "10";
    pub const DRAIN: &str = "0";
}

/// A secret setting: shown as `"<redacted>"` by `Debug`, so logs of the config never carry it.
#[derive(Clone, PartialEq, Eq)]
pub struct Secret(pub String);

impl std::fmt::Debug for Secret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("\"<redacted>\"")
    }
}

impl std::str::FromStr for Secret {
    type Err = String;

    fn from_str(s: &str) -> Result<Secret, String> {
        // Short tokens can be guessed; the owner tokens the server makes are 32 hex digits.
        if s.len() < 16 {
            return Err("must be at least 16 characters".into());
        }
        if !s.bytes().all(|b| b.is_ascii_graphic()) {
            return Err("must be printable ASCII without spaces".into());
        }
        Ok(Secret(s.to_owned()))
    }
}

/// Every setting of the server (flags of `lasertag serve`).
#[derive(Debug, Clone, clap::Args)]
pub struct Config {
    /// Matches the server holds at once, finished ones included until they are cleaned up
    /// (the showcase is always let in); more are refused with 503.
    #[arg(long, env = "LASERTAG_MAX_MATCHES", default_value_t = defaults::MAX_MATCHES,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_matches: usize,
    /// Robots plus opponents in one match; a larger match is refused with 400.
    #[arg(long, env = "LASERTAG_MAX_AGENTS_PER_MATCH", default_value_t = defaults::MAX_AGENTS_PER_MATCH,
          value_parser = clap::value_parser!(u64).range(2..).map(|v| v as usize))]
    pub max_agents_per_match: usize,
    /// Tracker particles of one match (particles per role × opponents: the tracker holds at
    /// most one role per opponent); more are refused with 400.
    #[arg(long, env = "LASERTAG_MAX_PARTICLES_PER_MATCH", default_value_t = defaults::MAX_PARTICLES_PER_MATCH,
          value_parser = clap::value_parser!(u64).range(10..).map(|v| v as usize))]
    pub max_particles_per_match: usize,
    /// People holding an opponent slot in one match; joining past it is refused with 409.
    #[arg(long, env = "LASERTAG_MAX_PLAYERS_PER_MATCH", default_value_t = defaults::MAX_PLAYERS_PER_MATCH,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_players_per_match: usize,
    /// WebSocket spectators of one match; more are refused with 503 before the upgrade.
    #[arg(long, env = "LASERTAG_MAX_SPECTATORS_PER_MATCH", default_value_t = defaults::MAX_SPECTATORS_PER_MATCH,
          value_parser = clap::value_parser!(u64).map(|v| v as usize))]
    pub max_spectators_per_match: usize,
    /// WebSocket spectators of one match from one client (an IPv4 address, or an IPv6
    /// /64); more are refused with 429. A visitor finds a place to watch while fewer than
    /// `--max-spectators-per-match` / this many addresses crowd a match.
    #[arg(long, env = "LASERTAG_MAX_SPECTATORS_PER_ADDRESS", default_value_t = defaults::MAX_SPECTATORS_PER_ADDRESS,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_spectators_per_address: usize,
    /// Open WebSocket connections from one IP address; more are refused with 429.
    #[arg(long, env = "LASERTAG_MAX_CONNECTIONS_PER_ADDRESS", default_value_t = defaults::MAX_CONNECTIONS_PER_ADDRESS,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_connections_per_address: usize,
    /// Sustained HTTP requests per second from one IP address (WebSocket upgrades included);
    /// more get 429 with `Retry-After`.
    #[arg(long, env = "LASERTAG_REQUESTS_PER_S", default_value_t = defaults::REQUESTS_PER_S,
          value_parser = positive)]
    pub requests_per_s: f64,
    /// HTTP requests one IP address may send at once before the rate applies.
    #[arg(long, env = "LASERTAG_REQUEST_BURST", default_value_t = defaults::REQUEST_BURST,
          value_parser = at_least_one)]
    pub request_burst: f64,
    /// Sustained WebSocket messages per second from one connection; more get an `error`,
    /// and a connection that keeps it up is closed (1008).
    #[arg(long, env = "LASERTAG_MESSAGES_PER_S", default_value_t = defaults::MESSAGES_PER_S,
          value_parser = positive)]
    pub messages_per_s: f64,
    /// WebSocket messages one connection may send at once before the rate applies.
    #[arg(long, env = "LASERTAG_MESSAGE_BURST", default_value_t = defaults::MESSAGE_BURST,
          value_parser = at_least_one)]
    pub message_burst: f64,
    /// Largest HTTP request body in bytes (413 past it).
    #[arg(long, env = "LASERTAG_MAX_BODY_BYTES", default_value_t = defaults::MAX_BODY_BYTES,
          value_parser = clap::value_parser!(u64).range(64..).map(|v| v as usize))]
    pub max_body_bytes: usize,
    /// Largest WebSocket message a client may send, in bytes: bigger ones get an `error`
    /// (and count towards a 1008 close); over 16 times this (at least 64 KiB) the connection
    /// is closed at once (1009).
    #[arg(long, env = "LASERTAG_MAX_MESSAGE_BYTES", default_value_t = defaults::MAX_MESSAGE_BYTES,
          value_parser = clap::value_parser!(u64).range(64..).map(|v| v as usize))]
    pub max_message_bytes: usize,
    /// Seconds a finished match stays readable (state, events, end screen) before it is
    /// removed.
    #[arg(long = "finished-grace-s", value_name = "SECONDS", env = "LASERTAG_FINISHED_GRACE_S",
          default_value = defaults::FINISHED_GRACE, value_parser = seconds)]
    pub finished_grace: Duration,
    /// Seconds a match with human-controlled opponents may go without any client (no
    /// WebSocket connected, no API request for it) before it is ended and removed. Matches
    /// without human slots (bots, API) are never abandoned: they end at their time limit.
    #[arg(long = "abandoned-after-s", value_name = "SECONDS", env = "LASERTAG_ABANDONED_AFTER_S",
          default_value = defaults::ABANDONED_AFTER, value_parser = seconds)]
    pub abandoned_after: Duration,
    /// Seconds a player whose connection dropped may take to come back with the same token
    /// before the slot is freed.
    #[arg(long = "reconnect-grace-s", value_name = "SECONDS", env = "LASERTAG_RECONNECT_GRACE_S",
          default_value = defaults::RECONNECT_GRACE, value_parser = seconds)]
    pub reconnect_grace: Duration,
    /// The operator's token: `Authorization: Bearer <it>` may change or delete any match or
    /// uploaded map (at least 16 printable characters). Without it only owners can.
    #[arg(long, env = "LASERTAG_ADMIN_TOKEN", value_parser = clap::value_parser!(Secret))]
    pub admin_token: Option<Secret>,
    /// Matches one client (an IPv4 address, or an IPv6 /64) may hold at once, finished ones
    /// included until they are removed; more are refused with 429.
    #[arg(long, env = "LASERTAG_MAX_MATCHES_PER_ADDRESS", default_value_t = defaults::MAX_MATCHES_PER_ADDRESS,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_matches_per_address: usize,
    /// Maps the server holds, shipped ones included; uploads past it are refused with 503.
    #[arg(long, env = "LASERTAG_MAX_MAPS", default_value_t = defaults::MAX_MAPS,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_maps: usize,
    /// Uploaded maps one client (an IPv4 address, or an IPv6 /64) may keep; more are refused
    /// with 429 until it deletes one.
    #[arg(long, env = "LASERTAG_MAX_MAPS_PER_ADDRESS", default_value_t = defaults::MAX_MAPS_PER_ADDRESS,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_maps_per_address: usize,
    /// Trained policies the server holds (`POST /api/policies`), shipped ones included.
    #[arg(long, env = "LASERTAG_MAX_POLICIES", default_value_t = defaults::MAX_POLICIES,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_policies: usize,
    /// Uploaded policies one client may keep; more are refused with 429 until it deletes one.
    #[arg(long, env = "LASERTAG_MAX_POLICIES_PER_ADDRESS", default_value_t = defaults::MAX_POLICIES_PER_ADDRESS,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_policies_per_address: usize,
    /// Bytes of one uploaded policy (an ONNX file); a larger upload is refused with 413.
    #[arg(long, env = "LASERTAG_MAX_POLICY_BYTES", default_value_t = defaults::MAX_POLICY_BYTES,
          value_parser = clap::value_parser!(u64).range(1..=(1 << 30)).map(|v| v as usize))]
    pub max_policy_bytes: usize,
    /// Microseconds one inference of an uploaded policy may take on this machine (timed
    /// when it is loaded); a slower one is refused with 400. Its cost per tick is also
    /// priced into every match it drives.
    #[arg(long, env = "LASERTAG_MAX_POLICY_INFERENCE_US", default_value_t = defaults::MAX_POLICY_INFERENCE_US,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_policy_inference_us: u64,
    /// Seconds a manual-clock match may go without a request that changes it (step, command)
    /// before it is ended and removed: manual matches never end on their own.
    #[arg(long = "idle-manual-after-s", value_name = "SECONDS", env = "LASERTAG_IDLE_MANUAL_AFTER_S",
          default_value = defaults::IDLE_MANUAL_AFTER, value_parser = seconds)]
    pub idle_manual_after: Duration,
    /// TCP connections open at once, WebSockets included; past it the server stops
    /// accepting until one closes (new clients wait in the kernel's backlog). Default 4096;
    /// given or not, never more than the open files leave (`http::derive_caps`), and a given
    /// value lowered to that is logged with what was asked and what was granted.
    #[arg(long, env = "LASERTAG_MAX_CONNECTIONS",
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_connections: Option<usize>,
    /// WebTransport sessions open at once. Each costs the server far more CPU than a
    /// WebSocket (QUIC encrypts and paces every datagram itself: about 24 µs a snapshot,
    /// docs/network.md); past it a new session is refused at once and the page plays over
    /// its WebSocket instead. The default is what 2 cores carry beside 100 matches and
    /// 1,800 WebSocket spectators; raise it with cores.
    #[arg(long, env = "LASERTAG_MAX_WEBTRANSPORT_SESSIONS", default_value_t = defaults::MAX_WEBTRANSPORT_SESSIONS,
          value_parser = clap::value_parser!(u64).range(0..).map(|v| v as usize))]
    pub max_webtransport_sessions: usize,
    /// Seconds a client has to send a request's header, and the most a connection may sit
    /// idle between requests; then it is closed.
    #[arg(long = "header-read-timeout-s", value_name = "SECONDS", env = "LASERTAG_HEADER_READ_TIMEOUT_S",
          default_value = defaults::HEADER_READ_TIMEOUT, value_parser = seconds)]
    pub header_read_timeout: Duration,
    /// Megabytes one request may make the server keep: a map upload, or a match with its
    /// inline map (priced from the request before anything is built); more is refused
    /// with 400 naming what is too big.
    #[arg(long, env = "LASERTAG_MAX_REQUEST_MEMORY_MB", default_value_t = defaults::MAX_REQUEST_MEMORY_MB,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_request_memory_mb: u64,
    /// Seconds of one core that validating and building what one request asks for may be
    /// priced at; more is refused with 400.
    #[arg(long, env = "LASERTAG_MAX_BUILD_S", default_value_t = defaults::MAX_BUILD_S,
          value_parser = positive)]
    pub max_build_s: f64,
    /// Milliseconds of one core that one tick of one match may be priced at (the tick
    /// period is 50 ms); more is refused with 400.
    #[arg(long, env = "LASERTAG_MAX_TICK_MS", default_value_t = defaults::MAX_TICK_MS,
          value_parser = positive)]
    pub max_tick_ms: f64,
    /// Megabytes all admitted matches and uploaded maps together may be priced at; past it
    /// new ones are refused with 503 until some go.
    #[arg(long, env = "LASERTAG_MEMORY_BUDGET_MB", default_value_t = defaults::MEMORY_BUDGET_MB,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub memory_budget_mb: u64,
    /// Megabytes of the store the running matches' records may be priced at together (a
    /// match driven over the API may record 64 MB of orders); past it new ones are refused
    /// with 503 until some go. Ended matches are bounded by the history's retention.
    #[arg(long, env = "LASERTAG_DISK_BUDGET_MB", default_value_t = defaults::DISK_BUDGET_MB,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub disk_budget_mb: u64,
    /// Tick milliseconds all running matches together may be priced at (default: 2 × 50 ms
    /// on every core: a match is priced at its p99 tick, and those seldom coincide); past it
    /// new matches are refused with 503.
    #[arg(long, env = "LASERTAG_TICK_BUDGET_MS", default_value_t = defaults::tick_budget_ms(),
          value_parser = positive)]
    pub tick_budget_ms: f64,
    /// Share (0..=1) of the memory and tick budgets one client (address or IPv6 /64) may hold
    /// with its matches and uploaded maps together; past it, 429. So that one visitor's
    /// admitted requests can never take the whole server.
    #[arg(long, env = "LASERTAG_CLIENT_BUDGET_SHARE", default_value_t = defaults::CLIENT_BUDGET_SHARE,
          value_parser = share)]
    pub client_budget_share: f64,
    /// Units of path search (a grid cell searched, a point of a path tested; about 25 ns
    /// each) the robots' waypoints of one command or `act` may take; an order that needs
    /// more is refused with 400. Each waypoint searches up to the whole navigation grid
    /// (10 cm cells, 400,000 at most), so on the largest maps only a few fit.
    #[arg(long, env = "LASERTAG_MAX_COMMAND_WORK", default_value_t = defaults::MAX_COMMAND_WORK,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_command_work: u64,
    /// Units of path search per second that robots' waypoints may take server-wide (one
    /// client: its `client-budget-share` of it). A command is charged its waypoints × twice
    /// its map's grid cells (at most `max-command-work`) before it runs; past the server's
    /// rate 503, past a client's 429, until the budget refills.
    #[arg(long, env = "LASERTAG_COMMAND_WORK_PER_S", default_value_t = defaults::COMMAND_WORK_PER_S,
          value_parser = positive)]
    pub command_work_per_s: f64,
    /// Replays re-simulated at once (their own pool, apart from the one that builds
    /// matches; default: half the cores). A replay read that finds them busy for 2 s is
    /// refused with 503; a client may have twice its `client-budget-share` of them in
    /// flight (at least 2), then 429.
    #[arg(long, env = "LASERTAG_REPLAY_JOBS", default_value_t = defaults::replay_jobs(),
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub replay_jobs: usize,
    /// Milliseconds past which one tick of a match counts as an overrun (reported in
    /// `lasertag_tick_overruns_total` and the log); a match whose ticks overran in half of
    /// its last 200 ends with reason `overloaded`, so that it cannot starve the others.
    #[arg(long, env = "LASERTAG_TICK_OVERRUN_MS", default_value_t = defaults::TICK_OVERRUN_MS,
          value_parser = positive)]
    pub tick_overrun_ms: f64,
    /// Seconds a slot joined with `POST …/players` is held for a WebSocket to play it (to
    /// send its first input); a slot not played by then is freed, its connection closed.
    #[arg(long = "join-hold-s", value_name = "SECONDS", env = "LASERTAG_JOIN_HOLD_S",
          default_value = defaults::JOIN_HOLD, value_parser = seconds)]
    pub join_hold: Duration,
    /// Slots of one match that one client (an IPv4 address, or an IPv6 /64) may hold
    /// without playing them (connected or not, no input sent yet); more joins are refused
    /// with 429 until one is played or lapses.
    #[arg(long, env = "LASERTAG_MAX_HOLDS_PER_ADDRESS", default_value_t = defaults::MAX_HOLDS_PER_ADDRESS,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_holds_per_address: usize,
    /// Seconds a server told to stop (SIGTERM, Ctrl-C) drains before it shuts down: it
    /// takes no new matches, and its running matches go on until they end or the drain
    /// does; then the rest end with reason `server_shutdown`. A second signal ends the
    /// drain at once. 0: shut down at once.
    #[arg(long = "drain-s", value_name = "SECONDS", env = "LASERTAG_DRAIN_S",
          default_value = defaults::DRAIN, value_parser = seconds)]
    pub drain: Duration,
    /// Replay exports (`GET /api/replays/{id}/export`) streaming at once; more are refused
    /// with 503.
    #[arg(long, env = "LASERTAG_MAX_EXPORTS", default_value_t = defaults::MAX_EXPORTS,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_exports: usize,
    /// Of those, the exports one client (an IPv4 address, or an IPv6 /64) may stream at
    /// once; more are refused with 429.
    #[arg(long, env = "LASERTAG_MAX_EXPORTS_PER_ADDRESS", default_value_t = defaults::MAX_EXPORTS_PER_ADDRESS,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_exports_per_address: usize,
    /// Seconds an export waits for a client that stops reading; then it ends with a last
    /// line saying it is incomplete and the `from_tick` to resume from.
    #[arg(long = "export-stall-s", value_name = "SECONDS", env = "LASERTAG_EXPORT_STALL_S",
          default_value = defaults::EXPORT_STALL, value_parser = seconds)]
    pub export_stall: Duration,
    /// Seconds one export may stream in all (a slow reader holds an export slot no longer);
    /// then it ends as an incomplete export does, to be resumed with `from_tick`.
    #[arg(long = "export-budget-s", value_name = "SECONDS", env = "LASERTAG_EXPORT_BUDGET_S",
          default_value = defaults::EXPORT_BUDGET, value_parser = seconds)]
    pub export_budget: Duration,
    /// TCP connections (HTTP and WebSocket alike) open at once from one client (an IPv4
    /// address, or an IPv6 /64); past it a new connection is closed as soon as it is
    /// accepted. Default 256, and at most a sixteenth of what the open files leave, so other
    /// clients always find room; a given value is the operator's and is used as given, only
    /// never more than the open files leave (logged with what was asked and granted).
    #[arg(long, env = "LASERTAG_MAX_TCP_PER_ADDRESS",
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_tcp_per_address: Option<usize>,
    /// Opponent slots one client (an IPv4 address, or an IPv6 /64) may hold over all
    /// matches at once, played or not; more joins are refused with 429. With the showcases
    /// that start when every one is full, it keeps a few addresses from taking every seat
    /// people are invited to.
    #[arg(long, env = "LASERTAG_MAX_SEATS_PER_ADDRESS", default_value_t = defaults::MAX_SEATS_PER_ADDRESS,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_seats_per_address: usize,
    /// Let one client (an IPv4 address, or an IPv6 /64) hold seats on both sides of one
    /// match (an opponent slot and a pursuer slot). Off: a second join on the other side is
    /// refused with 409, since one person on both would see the hunters' belief live while
    /// being hunted (people behind one address then play on one side of a match).
    #[arg(long, env = "LASERTAG_BOTH_SIDES_PER_ADDRESS")]
    pub both_sides_per_address: bool,
    /// Names one client (an IPv4 address, or an IPv6 /64) may keep (`POST /api/names`);
    /// more claims are refused with 429 until it gives one up.
    #[arg(long, env = "LASERTAG_MAX_NAMES_PER_ADDRESS", default_value_t = defaults::MAX_NAMES_PER_ADDRESS,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_names_per_address: u64,
    /// Names everyone together may keep (about 200 bytes each in the history); past it
    /// claims are refused with 503.
    #[arg(long, env = "LASERTAG_MAX_NAMES", default_value_t = defaults::MAX_NAMES,
          value_parser = clap::value_parser!(u64).range(1..))]
    pub max_names: u64,
    /// Claims of names the server takes a minute, all clients together (bursts of as
    /// many): each is a write to the history, which live matches share.
    #[arg(long, env = "LASERTAG_NAME_CLAIMS_PER_MINUTE", default_value_t = defaults::NAME_CLAIMS_PER_MINUTE,
          value_parser = positive)]
    pub name_claims_per_minute: f64,
    /// Megabytes of beliefs (`GET …/belief`, as JSON before compression) one client (an
    /// IPv4 address, or an IPv6 /64) may read a second, in bursts of two seconds' worth;
    /// past it 429 with `Retry-After`. A belief bigger than the burst is let through when
    /// the client has its whole burst, and the client then waits for what it overdrew.
    #[arg(long, env = "LASERTAG_BELIEF_MB_PER_S", default_value_t = defaults::BELIEF_MB_PER_S,
          value_parser = positive)]
    pub belief_mb_per_s: f64,
    /// Megabytes of beliefs all clients together may read a second (bursts of two seconds'
    /// worth); past it 503 with `Retry-After`. Encoding and compressing them runs on the
    /// blocking pool, once a tick per belief however many read it.
    #[arg(long, env = "LASERTAG_BELIEF_MB_PER_S_ALL", default_value_t = defaults::BELIEF_MB_PER_S_ALL,
          value_parser = positive)]
    pub belief_mb_per_s_all: f64,
    /// Parties (waiting rooms, `POST /api/parties`) everyone together may hold (each at
    /// most 8 people, a few kilobytes with its row in the store); past it 503.
    #[arg(long, env = "LASERTAG_MAX_PARTIES", default_value_t = defaults::MAX_PARTIES,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_parties: usize,
    /// Parties one client (an IPv4 address, or an IPv6 /64) may host at once; past it 429.
    #[arg(long, env = "LASERTAG_MAX_PARTIES_PER_ADDRESS", default_value_t = defaults::MAX_PARTIES_PER_ADDRESS,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_parties_per_address: usize,
    /// Party codes one client may name a minute that name no party (bursts of as many):
    /// past it 429, so that guessing a code takes months, not minutes.
    #[arg(long, env = "LASERTAG_PARTY_MISSES_PER_MINUTE", default_value_t = defaults::PARTY_MISSES_PER_MINUTE,
          value_parser = positive)]
    pub party_misses_per_minute: f64,
    /// People the queue (`POST /api/queue`) holds at once, all clients together; past it 503.
    #[arg(long, env = "LASERTAG_MAX_QUEUED", default_value_t = defaults::MAX_QUEUED,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_queued: usize,
    /// Tickets one client may hold in the queue at once; past it 429.
    #[arg(long, env = "LASERTAG_MAX_QUEUED_PER_ADDRESS", default_value_t = defaults::MAX_QUEUED_PER_ADDRESS,
          value_parser = clap::value_parser!(u64).range(1..).map(|v| v as usize))]
    pub max_queued_per_address: usize,
}

impl Default for Config {
    fn default() -> Config {
        let secs = |s: &str| seconds(s).unwrap_or(Duration::ZERO);
        Config {
            max_matches: defaults::MAX_MATCHES,
            max_agents_per_match: defaults::MAX_AGENTS_PER_MATCH,
            max_particles_per_match: defaults::MAX_PARTICLES_PER_MATCH,
            max_players_per_match: defaults::MAX_PLAYERS_PER_MATCH,
            max_spectators_per_match: defaults::MAX_SPECTATORS_PER_MATCH,
            max_spectators_per_address: defaults::MAX_SPECTATORS_PER_ADDRESS,
            max_connections_per_address: defaults::MAX_CONNECTIONS_PER_ADDRESS,
            requests_per_s: defaults::REQUESTS_PER_S,
            request_burst: defaults::REQUEST_BURST,
            messages_per_s: defaults::MESSAGES_PER_S,
            message_burst: defaults::MESSAGE_BURST,
            max_body_bytes: defaults::MAX_BODY_BYTES,
            max_message_bytes: defaults::MAX_MESSAGE_BYTES,
            finished_grace: secs(defaults::FINISHED_GRACE),
            abandoned_after: secs(defaults::ABANDONED_AFTER),
            reconnect_grace: secs(defaults::RECONNECT_GRACE),
            admin_token: None,
            max_matches_per_address: defaults::MAX_MATCHES_PER_ADDRESS,
            max_maps: defaults::MAX_MAPS,
            max_maps_per_address: defaults::MAX_MAPS_PER_ADDRESS,
            max_policies: defaults::MAX_POLICIES,
            max_policies_per_address: defaults::MAX_POLICIES_PER_ADDRESS,
            max_policy_bytes: defaults::MAX_POLICY_BYTES,
            max_policy_inference_us: defaults::MAX_POLICY_INFERENCE_US,
            idle_manual_after: secs(defaults::IDLE_MANUAL_AFTER),
            max_connections: None,
            max_webtransport_sessions: defaults::MAX_WEBTRANSPORT_SESSIONS,
            header_read_timeout: secs(defaults::HEADER_READ_TIMEOUT),
            max_request_memory_mb: defaults::MAX_REQUEST_MEMORY_MB,
            max_build_s: defaults::MAX_BUILD_S,
            max_tick_ms: defaults::MAX_TICK_MS,
            memory_budget_mb: defaults::MEMORY_BUDGET_MB,
            disk_budget_mb: defaults::DISK_BUDGET_MB,
            tick_budget_ms: defaults::tick_budget_ms(),
            client_budget_share: defaults::CLIENT_BUDGET_SHARE,
            max_command_work: defaults::MAX_COMMAND_WORK,
            command_work_per_s: defaults::COMMAND_WORK_PER_S,
            replay_jobs: defaults::replay_jobs(),
            tick_overrun_ms: defaults::TICK_OVERRUN_MS,
            join_hold: secs(defaults::JOIN_HOLD),
            max_holds_per_address: defaults::MAX_HOLDS_PER_ADDRESS,
            drain: secs(defaults::DRAIN),
            max_exports: defaults::MAX_EXPORTS,
            max_exports_per_address: defaults::MAX_EXPORTS_PER_ADDRESS,
            export_stall: secs(defaults::EXPORT_STALL),
            export_budget: secs(defaults::EXPORT_BUDGET),
            max_tcp_per_address: None,
            max_seats_per_address: defaults::MAX_SEATS_PER_ADDRESS,
            both_sides_per_address: false,
            max_names_per_address: defaults::MAX_NAMES_PER_ADDRESS,
            max_names: defaults::MAX_NAMES,
            name_claims_per_minute: defaults::NAME_CLAIMS_PER_MINUTE,
            belief_mb_per_s: defaults::BELIEF_MB_PER_S,
            belief_mb_per_s_all: defaults::BELIEF_MB_PER_S_ALL,
            max_parties: defaults::MAX_PARTIES,
            max_parties_per_address: defaults::MAX_PARTIES_PER_ADDRESS,
            party_misses_per_minute: defaults::PARTY_MISSES_PER_MINUTE,
            max_queued: defaults::MAX_QUEUED,
            max_queued_per_address: defaults::MAX_QUEUED_PER_ADDRESS,
        }
    }
}

impl Config {
    /// Messages over this many bytes are not even read: the connection is closed (1009).
    pub fn hard_message_bytes(&self) -> usize {
        (self.max_message_bytes * 16).max(64 * 1024)
    }
}

/// A number of seconds (`30`, `0.5`) as a duration.
fn seconds(s: &str) -> Result<Duration, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if !(v.is_finite() && (0.0..=1e7).contains(&v)) {
        return Err(format!("{s}: must be between 0 and 10000000 seconds"));
    }
    Ok(Duration::from_secs_f64(v))
}

fn positive(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a number"))?;
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(format!("{s}: must be a positive number"))
    }
}

fn share(s: &str) -> Result<f64, String> {
    let v = positive(s)?;
    if v <= 1.0 {
        Ok(v)
    } else {
        Err(format!("{s}: must be a share in (0, 1]"))
    }
}

fn at_least_one(s: &str) -> Result<f64, String> {
    let v = positive(s)?;
    if v >= 1.0 {
        Ok(v)
    } else {
        Err(format!("{s}: must be at least 1"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        config: Config,
    }

    #[test]
    fn clap_defaults_are_the_default_config() {
        // No LASERTAG_* variables are set in the test environment for these names... but a
        // developer's shell might: only compare when none is.
        if std::env::vars().any(|(k, _)| k.starts_with("LASERTAG_")) {
            return;
        }
        let parsed = Cli::try_parse_from(["lasertag"]).map(|c| c.config);
        let parsed = parsed.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(format!("{parsed:?}"), format!("{:?}", Config::default()));
    }

    #[test]
    fn bad_values_are_refused_with_their_name() {
        let e = Cli::try_parse_from(["lasertag", "--finished-grace-s", "soon"])
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("finished-grace-s") && e.contains("soon"), "{e}");
        let e = Cli::try_parse_from(["lasertag", "--requests-per-s", "0"])
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains("positive"), "{e}");
        let ok = Cli::try_parse_from(["lasertag", "--reconnect-grace-s", "0.5"]);
        assert!(ok.is_ok_and(|c| c.config.reconnect_grace == Duration::from_millis(500)));
    }
}
