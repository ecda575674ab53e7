//! The server's Prometheus metrics, served at `GET /metrics` in the text format.
//!
//! Each server has its own [`prometheus::Registry`] (not the crate's global one), so that
//! several servers in one process (the integration tests) count separately. Labels take
//! values from small fixed sets only (planner kinds, roles, refusal reasons), so the number
//! of series stays bounded however long the server runs.

use prometheus::{
    Encoder, Histogram, HistogramOpts, HistogramVec, IntCounter, IntCounterVec, IntGauge,
    IntGaugeVec, Opts, Registry, TextEncoder,
};

/// Why a request, connection or message was refused (`lasertag_refused_total{reason}`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// HTTP requests over the per-address rate (429).
    RateLimited,
    /// WebSocket connections over the per-address cap (429).
    ConnectionsPerAddress,
    /// A new match while the server holds its most (503).
    MatchesFull,
    /// A spectator past the per-match cap (503).
    SpectatorsFull,
    /// A spectator past its address's share of one match's places (429).
    SpectatorsPerAddress,
    /// A player past the per-match cap (409).
    PlayersFull,
    /// A match with more robots and opponents than allowed (400).
    TooManyAgents,
    /// A match with more tracker particles than allowed (400).
    TooManyParticles,
    /// An HTTP body over the size limit (413).
    BodyTooLarge,
    /// A WebSocket message over the per-connection rate.
    MessageRate,
    /// A WebSocket message over the size limit.
    MessageTooLarge,
    /// A WebSocket message that is not valid (not JSON, unknown type, out of range...).
    MessageInvalid,
    /// A new match or map from a client that holds its most (429).
    ClientQuota,
    /// A map upload while the server holds its most maps (503).
    MapsFull,
    /// A policy upload while the server holds its most policies (503).
    PoliciesFull,
    /// A change without an owner or admin token (401).
    Unauthorized,
    /// A change with a token that is not the owner's (403).
    Forbidden,
    /// A request priced past a per-request limit (400) or the server's budgets (503).
    Budget,
    /// A TCP connection past the per-address cap, closed as soon as it was accepted.
    TcpPerAddress,
    /// A WebTransport session past the server's cap, refused at its first packet.
    WebTransportFull,
}

impl Refusal {
    pub const ALL: [Refusal; 20] = [
        Refusal::RateLimited,
        Refusal::ConnectionsPerAddress,
        Refusal::MatchesFull,
        Refusal::SpectatorsFull,
        Refusal::SpectatorsPerAddress,
        Refusal::PlayersFull,
        Refusal::TooManyAgents,
        Refusal::TooManyParticles,
        Refusal::BodyTooLarge,
        Refusal::MessageRate,
        Refusal::MessageTooLarge,
        Refusal::MessageInvalid,
        Refusal::ClientQuota,
        Refusal::MapsFull,
        Refusal::PoliciesFull,
        Refusal::Unauthorized,
        Refusal::Forbidden,
        Refusal::Budget,
        Refusal::TcpPerAddress,
        Refusal::WebTransportFull,
    ];

    pub fn label(self) -> &'static str {
        match self {
            Refusal::RateLimited => "rate_limited",
            Refusal::ConnectionsPerAddress => "connections_per_address",
            Refusal::MatchesFull => "matches_full",
            Refusal::SpectatorsFull => "spectators_full",
            Refusal::SpectatorsPerAddress => "spectators_per_address",
            Refusal::PlayersFull => "players_full",
            Refusal::TooManyAgents => "too_many_agents",
            Refusal::TooManyParticles => "too_many_particles",
            Refusal::BodyTooLarge => "body_too_large",
            Refusal::MessageRate => "message_rate",
            Refusal::MessageTooLarge => "message_too_large",
            Refusal::MessageInvalid => "message_invalid",
            Refusal::ClientQuota => "client_quota",
            Refusal::MapsFull => "maps_full",
            Refusal::PoliciesFull => "policies_full",
            Refusal::Unauthorized => "unauthorized",
            Refusal::Forbidden => "forbidden",
            Refusal::Budget => "budget",
            Refusal::TcpPerAddress => "tcp_per_address",
            Refusal::WebTransportFull => "webtransport_full",
        }
    }
}

/// Every metric family of the server.
#[derive(Debug, Clone)]
pub struct Metrics {
    registry: Registry,
    /// Matches held, by `state` (`running`, `finished`); set at each scrape.
    pub matches: IntGaugeVec,
    /// Matches removed, by `reason` (`deleted`, `finished`, `abandoned`, `idle`, `moved`:
    /// another server took it).
    pub matches_removed: IntCounterVec,
    /// Matches a starting server found left running in its store, by `outcome`
    /// (`resumed`, `lost`: its record could not be rebuilt).
    pub matches_resumed: IntCounterVec,
    /// WebSocket clients connected now, by `role` (`player`, `spectator`).
    pub clients: IntGaugeVec,
    /// Compute time of one tick (world step and frame), by planner `kind` and `clock`.
    pub tick_seconds: HistogramVec,
    /// Time of the team's tracker update within a tick, by planner `kind`.
    pub tracker_seconds: HistogramVec,
    /// Time of the team's planner within a tick, by planner `kind`.
    pub planner_seconds: HistogramVec,
    /// Bytes of snapshots sent to WebSocket clients, by `role`.
    pub snapshot_bytes: IntCounterVec,
    /// Requests, connections and messages refused, by `reason`.
    pub refused: IntCounterVec,
    /// Ticks that started more than half a period late (real-time matches).
    pub late_ticks: IntCounter,
    /// Ticks whose computation took longer than `--tick-overrun-ms`.
    pub tick_overruns: IntCounter,
    /// Round trips to the fleet's Redis (`--fleet`), answered or not.
    pub fleet_round_trips: IntCounter,
    /// Round trips to the fleet's Redis that failed (refused, timed out, cut).
    pub fleet_errors: IntCounter,
    /// Nodes in this node's view of the fleet, itself included (0 outside a fleet).
    pub fleet_nodes: IntGauge,
}

/// Tick-scale buckets: 50 µs to 100 ms (a tick has 50 ms).
const TICK_BUCKETS: [f64; 13] = [
    0.000_05, 0.000_1, 0.000_25, 0.000_5, 0.001, 0.002, 0.005, 0.01, 0.02, 0.035, 0.05, 0.075, 0.1,
];

impl Metrics {
    /// Registers every family; the names are fixed, so registering cannot collide.
    pub fn new() -> Metrics {
        let registry = Registry::new();
        let matches = IntGaugeVec::new(
            Opts::new("lasertag_matches", "Matches held by the server, by state"),
            &["state"],
        )
        .expect("valid metric");
        let matches_removed = IntCounterVec::new(
            Opts::new(
                "lasertag_matches_removed_total",
                "Matches removed: deleted through the API, cleaned up after finishing, or abandoned",
            ),
            &["reason"],
        )
        .expect("valid metric");
        let matches_resumed = IntCounterVec::new(
            Opts::new(
                "lasertag_matches_resumed_total",
                "Matches a starting server found left running in its store: resumed, or lost when their record could not be rebuilt",
            ),
            &["outcome"],
        )
        .expect("valid metric");
        let clients = IntGaugeVec::new(
            Opts::new(
                "lasertag_clients",
                "WebSocket clients connected, by role (player or spectator)",
            ),
            &["role"],
        )
        .expect("valid metric");
        let histogram = |name: &str, help: &str, labels: &[&str]| {
            HistogramVec::new(
                HistogramOpts::new(name, help).buckets(TICK_BUCKETS.to_vec()),
                labels,
            )
            .expect("valid metric")
        };
        let tick_seconds = histogram(
            "lasertag_tick_seconds",
            "Compute time of one tick (world step and frame), by planner kind and clock",
            &["kind", "clock"],
        );
        let tracker_seconds = histogram(
            "lasertag_tracker_seconds",
            "Time of the robots' tracker update in one tick, by planner kind",
            &["kind"],
        );
        let planner_seconds = histogram(
            "lasertag_planner_seconds",
            "Time of the robots' planner in one tick, by planner kind",
            &["kind"],
        );
        let snapshot_bytes = IntCounterVec::new(
            Opts::new(
                "lasertag_snapshot_bytes_total",
                "Bytes of snapshots sent over WebSockets, by client role",
            ),
            &["role"],
        )
        .expect("valid metric");
        let refused = IntCounterVec::new(
            Opts::new(
                "lasertag_refused_total",
                "Requests, connections and WebSocket messages refused, by reason",
            ),
            &["reason"],
        )
        .expect("valid metric");
        let tick_overruns = IntCounter::new(
            "lasertag_tick_overruns_total",
            "Ticks whose computation took longer than the overrun limit",
        )
        .expect("valid metric");
        let late_ticks = IntCounter::new(
            "lasertag_late_ticks_total",
            "Real-time ticks that started over half a period late",
        )
        .expect("valid metric");
        let fleet_round_trips = IntCounter::new(
            "lasertag_fleet_redis_round_trips_total",
            "Round trips to the fleet's Redis directory",
        )
        .expect("valid metric");
        let fleet_errors = IntCounter::new(
            "lasertag_fleet_redis_errors_total",
            "Round trips to the fleet's Redis directory that failed",
        )
        .expect("valid metric");
        let fleet_nodes = IntGauge::new(
            "lasertag_fleet_nodes",
            "Nodes in this node's view of the fleet, itself included",
        )
        .expect("valid metric");
        for c in [
            Box::new(matches.clone()) as Box<dyn prometheus::core::Collector>,
            Box::new(matches_removed.clone()),
            Box::new(matches_resumed.clone()),
            Box::new(clients.clone()),
            Box::new(tick_seconds.clone()),
            Box::new(tracker_seconds.clone()),
            Box::new(planner_seconds.clone()),
            Box::new(snapshot_bytes.clone()),
            Box::new(refused.clone()),
            Box::new(late_ticks.clone()),
            Box::new(tick_overruns.clone()),
            Box::new(fleet_round_trips.clone()),
            Box::new(fleet_errors.clone()),
            Box::new(fleet_nodes.clone()),
        ] {
            registry.register(c).expect("metric names are distinct");
        }
        // Series that exist from the start, so a scrape shows every family at zero.
        for state in ["running", "finished"] {
            matches.with_label_values(&[state]).set(0);
        }
        for role in ["player", "spectator"] {
            clients.with_label_values(&[role]).set(0);
            snapshot_bytes.with_label_values(&[role]).inc_by(0);
        }
        for kind in ["coordinated", "search", "baseline", "idle"] {
            for clock in ["realtime", "manual"] {
                tick_seconds.with_label_values(&[kind, clock]);
            }
            tracker_seconds.with_label_values(&[kind]);
            planner_seconds.with_label_values(&[kind]);
        }
        for r in Refusal::ALL {
            refused.with_label_values(&[r.label()]).inc_by(0);
        }
        for reason in ["deleted", "finished", "abandoned", "idle", "moved"] {
            matches_removed.with_label_values(&[reason]).inc_by(0);
        }
        for outcome in ["resumed", "lost"] {
            matches_resumed.with_label_values(&[outcome]).inc_by(0);
        }
        Metrics {
            registry,
            matches,
            matches_removed,
            matches_resumed,
            clients,
            tick_seconds,
            tracker_seconds,
            planner_seconds,
            snapshot_bytes,
            refused,
            late_ticks,
            tick_overruns,
            fleet_round_trips,
            fleet_errors,
            fleet_nodes,
        }
    }

    pub fn refuse(&self, why: Refusal) {
        self.refused.with_label_values(&[why.label()]).inc();
    }

    /// A client counted in `lasertag_clients{role}` until the guard is dropped.
    pub fn client(&self, role: &'static str) -> ClientGuard {
        let g = self.clients.with_label_values(&[role]);
        g.inc();
        ClientGuard(g)
    }

    pub fn tick_histograms(&self, kind: &str, clock: &str) -> TickHistograms {
        TickHistograms {
            tick: self.tick_seconds.with_label_values(&[kind, clock]),
            tracker: self.tracker_seconds.with_label_values(&[kind]),
            planner: self.planner_seconds.with_label_values(&[kind]),
        }
    }

    /// The text exposition of every family.
    pub fn render(&self) -> String {
        let mut out = Vec::new();
        // Encoding into a Vec fails only on a malformed family, which `new` rules out.
        if let Err(e) = TextEncoder::new().encode(&self.registry.gather(), &mut out) {
            tracing::error!("encoding metrics: {e}");
        }
        String::from_utf8(out).unwrap_or_default()
    }
}

impl Default for Metrics {
    fn default() -> Metrics {
        Metrics::new()
    }
}

/// The histograms a match task observes, resolved once per match.
#[derive(Debug, Clone)]
pub struct TickHistograms {
    pub tick: Histogram,
    pub tracker: Histogram,
    pub planner: Histogram,
}

/// Decrements a client gauge when dropped.
#[derive(Debug)]
pub struct ClientGuard(IntGauge);

impl Drop for ClientGuard {
    fn drop(&mut self) {
        self.0.dec();
    }
}
