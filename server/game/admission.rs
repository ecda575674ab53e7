//! What a request that creates state will cost, priced from its inputs before anything is
//! built: the memory a map or a match keeps, the CPU it takes to build, and the CPU each
//! tick of a match takes. Handlers compare a [`Price`] with the per-request limits and
//! with what the server has already admitted (see `Config`).
//!
//! The coefficients come from `examples/admission_probe.rs` (a counting allocator and a
//! clock around each phase, one input varied at a time; the figures are in
//! docs/operations.md). Each is rounded up from the measurement, and where a cost depends
//! on how a match plays out (how many roles the tracker splits into) the worst case is
//! priced: a price is a bound, not a forecast.

use lasertag_core::sim::arena::{ClearanceGrid, MapDef, bounding_box};
use lasertag_core::world::MatchConfig;
use nalgebra::Point2;

/// Bytes, build seconds, tick milliseconds and stored bytes of one admitted thing.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Price {
    /// Bytes kept while it lives.
    pub memory: u64,
    /// Bytes of the store its record may take while it runs: orders from outside
    /// (`game::record`, bounded by this, not by memory) and its checkpoints
    /// ([`checkpoint_bytes`]).
    pub disk: u64,
    /// Seconds of one core to validate and build it.
    pub build_s: f64,
    /// Milliseconds of one core per tick (matches only).
    pub tick_ms: f64,
}

impl std::ops::Add for Price {
    type Output = Price;

    fn add(self, o: Price) -> Price {
        Price {
            memory: self.memory + o.memory,
            disk: self.disk + o.disk,
            build_s: self.build_s + o.build_s,
            tick_ms: self.tick_ms + o.tick_ms,
        }
    }
}

impl std::iter::Sum for Price {
    fn sum<I: Iterator<Item = Price>>(iter: I) -> Price {
        iter.fold(Price::default(), |a, b| a + b)
    }
}

/// Bytes per clearance-grid cell kept by the arena (its clearance) and by the likelihood
/// field a localising match derives from it.
const GRID_BYTES_PER_CELL: f64 = 4.0 + 16.0;
/// Bytes per vertex: the polyline, its bounding-volume tree and the definition's copy.
const BYTES_PER_VERTEX: f64 = 200.0;
/// Bytes per segment-index entry, with the slack of a growing vector.
const BYTES_PER_INDEX_ENTRY: f64 = 32.0;
/// The planner's table of candidate views: at most 1,500 positions, so it peaks on maps
/// of about 60 m (67 MB measured) and shrinks on bigger ones; per square metre it never
/// came above 21 KB.
const VIEW_TABLE_BYTES_PER_M2: f64 = 22_000.0;
const VIEW_TABLE_MAX_BYTES: f64 = 72e6;
/// Seconds to build the grids of a map, whatever its size (400k cells at most).
const MAP_BASE_S: f64 = 0.08;
/// Seconds per (grid cell × edge whose bounding box covers it): the nearest-wall queries
/// of the clearance grid and of the likelihood field visit every edge whose box contains
/// the query point, so long diagonal walls cost by the area of their boxes.
const S_PER_BOX_CELL: f64 = 40e-9;
/// Seconds per (cell of an obstacle's box × its vertices): the inside test.
const S_PER_INSIDE_TEST: f64 = 3e-9;
/// Seconds per pair of edges of one polygon: the self-intersection check.
const S_PER_EDGE_PAIR: f64 = 8e-9;

/// Memory a match keeps whatever its settings (the world, its queues, its frames).
const MATCH_BASE_BYTES: f64 = 4e6;
/// Per robot: its localiser's particles, scan and plan.
const BYTES_PER_ROBOT: f64 = 64e3;
/// Per tracker particle (position, weight, step and the resampling buffers).
const BYTES_PER_PARTICLE: f64 = 24.0;
/// Per cell of the merge histogram, twice (the tracker's grid and the histograms it
/// fills when it checks roles for a merge).
const BYTES_PER_MERGE_CELL: f64 = 16.0;
// A match's tick is priced at its p99: the heavy ticks are the planner's turns, each a
// distance field over the whole grid for one robot (one turn a tick at most), on top of every
// robot's sensing and localising and the tracker's particles. Fitted to the p99 of seeded
// matches on every shipped map and a spread of settings (`examples/admission_calibration.rs`,
// docs/results/admission_calibration.csv); `tests/admission_calibration.rs` holds every
// price there within 1.5× of its measured p99.
/// Milliseconds per tick whatever the settings.
const TICK_BASE_MS: f64 = 0.15;
/// Per clearance cell: the distance fields of the planner's turn and the bots' choices.
const TICK_MS_PER_CELL: f64 = 0.8e-5;
/// Per robot: its scan and its share of the tracker.
const TICK_MS_PER_ROBOT: f64 = 0.01;
/// Per robot the `coordinated` planner drives: its turns (a distance field, every candidate
/// pose scored).
const TICK_MS_PER_COORDINATED_ROBOT: f64 = 0.07;
/// Per tracker particle and tracker copy, plus as much again per robot whose sightings it
/// weighs (negative information tests each particle against each robot's scan; a
/// teammate's late scan, behind an imperfect radio, takes the slower one-particle test).
const TICK_MS_PER_PARTICLE: f64 = 1e-5;
const TICK_MS_PER_PARTICLE_ROBOT: f64 = 0.5e-5;
/// Per landmark and localising robot.
const TICK_MS_PER_LANDMARK: f64 = 2.2e-4;
/// Per laser beam the localiser weighs and localising robot (each beam against every
/// particle, at most `localise::Settings::max_particles`).
const TICK_MS_PER_LOCALISER_BEAM: f64 = 0.6e-3;
/// Per `search` planner's choice besides its look-ahead: the first level ranks every
/// candidate pose with the travel table.
const TICK_MS_PER_SEARCH_CHOICE: f64 = 0.2;
/// Per view the `search` planner's look-ahead weighs (one pose's fresh share of the
/// belief): a choice weighs `SHORTLIST` views at each node of its beam, and one robot
/// chooses a tick.
const TICK_MS_PER_SEARCH_VIEW: f64 = 0.3e-3;
/// Per merge-grid cell and pair of roles the tracker compares at a merge (every
/// `merge_interval` ticks; the p99 tick is a merging one when merges come often).
const TICK_MS_PER_MERGE_CELL_PAIR: f64 = 0.1e-6;

/// The price of keeping and building an arena for `def` (the planner's view table and the
/// likelihood field it will derive included: a stored map keeps them once a match has been
/// played on it).
pub fn map(def: &MapDef) -> Price {
    let (cell, cols, rows) = ClearanceGrid::shape(def.width, def.height);
    let cells = (cols * rows) as f64;
    let border = [
        Point2::new(0.0, 0.0),
        Point2::new(def.width, 0.0),
        Point2::new(def.width, def.height),
        Point2::new(0.0, def.height),
    ];
    let polygons = std::iter::once(&border[..]).chain(def.obstacles.iter().map(Vec::as_slice));
    let (mut vertices, mut box_cells, mut inside_tests, mut edge_pairs, mut entries) =
        (0.0, 0.0, 0.0, 0.0, 0.0);
    // The segment index's cells: 0.5 m, coarser on huge maps (250k at most).
    let index_cell = 0.5f32.max((def.width * def.height / 250_000.0).sqrt());
    for poly in polygons {
        let n = poly.len() as f64;
        vertices += n;
        edge_pairs += n * n / 2.0;
        let (lo, hi) = bounding_box(poly);
        inside_tests += cells_in(lo, hi, cell) * n;
        for i in 0..poly.len() {
            let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
            box_cells += cells_in(a.inf(&b), a.sup(&b), cell).min(cells);
            entries += ((a.x - b.x).abs() + (a.y - b.y).abs()) as f64 / index_cell as f64 + 2.0;
        }
    }
    let area = (def.width * def.height) as f64;
    let views = (area * VIEW_TABLE_BYTES_PER_M2).min(VIEW_TABLE_MAX_BYTES);
    let memory = cells * GRID_BYTES_PER_CELL
        + vertices * BYTES_PER_VERTEX
        + entries * BYTES_PER_INDEX_ENTRY
        + def.landmarks.len() as f64 * 8.0
        + views;
    Price {
        memory: memory as u64,
        disk: 0,
        // Both the clearance grid and the likelihood field query every cell.
        build_s: MAP_BASE_S
            + 2.0 * box_cells * S_PER_BOX_CELL
            + inside_tests * S_PER_INSIDE_TEST
            + edge_pairs * S_PER_EDGE_PAIR,
        tick_ms: 0.0,
    }
}

/// Bytes of a match's state that changes as it plays, whatever its settings: its event log,
/// radio traffic, scans, plans and the planner's scratch (the share of `MATCH_BASE_BYTES`
/// a checkpoint writes).
const CHECKPOINT_BASE_BYTES: f64 = 1e6;
/// Per event the log may hold (an agent id or two, a tick, a name of at most 32 bytes).
const BYTES_PER_EVENT: f64 = 64.0;
/// Checkpoints the store keeps of a running match (`task::history`).
const CHECKPOINTS_KEPT: f64 = 2.0;

/// The most bytes one checkpoint of a match with `config` on `def` takes (what
/// `World::checkpoint` writes, before it is deflated): the parts of the match's memory
/// that change as it plays — its tracker particles, its robots' localisers and plans, the
/// planner's per-cell scratch — and its event log, at most a shot per agent per cooldown
/// and a few events a second besides. The map's derived tables are not in it: a resume
/// builds them again. The store refuses a checkpoint past this bound (the match then
/// resumes from an older one, or from its start).
pub fn checkpoint_bytes(def: &MapDef, config: &MatchConfig) -> u64 {
    let (_, cols, rows) = ClearanceGrid::shape(def.width, def.height);
    let cells = (cols * rows) as f64;
    let robots = config.robots as f64;
    let copies = if config.radio.perfect() { 1.0 } else { robots };
    let particles = config.tracker.particles_per_role as f64 * config.opponents as f64;
    let localiser = if config.localisation {
        config.localiser.max_particles as f64 * BYTES_PER_PARTICLE
    } else {
        0.0
    };
    let agents = (config.robots + config.opponents) as f64;
    let ticks = config.time_limit_ticks as f64;
    let shots = agents * ticks / config.physics.tag_cooldown_ticks.max(1) as f64;
    let others = 4.0 * ticks / lasertag_core::sim::TICK_HZ as f64;
    let bytes = CHECKPOINT_BASE_BYTES
        + robots * (BYTES_PER_ROBOT + localiser)
        + copies * particles * BYTES_PER_PARTICLE
        + cells * 8.0
        + (shots + others) * BYTES_PER_EVENT;
    bytes as u64
}

/// Whether a match with `config` takes orders from outside (robots or opponents driven over
/// the API), whose record is bounded by [`record::MAX_RECORD_BYTES`](crate::game::record).
fn takes_orders(config: &MatchConfig) -> bool {
    config.planner == lasertag_core::planner::PlannerKind::Api
        || config.outside_robots.contains(&true)
        || config.opponent_control == lasertag_core::world::ControlKind::Api
}

/// Bytes of the orders from outside a match with `config` keeps in memory (the newest, for
/// its replay; the store has the rest): none when it takes none.
fn recorded_orders(config: &MatchConfig) -> f64 {
    if takes_orders(config) {
        crate::game::record::MEMORY_ORDER_BYTES as f64
    } else {
        0.0
    }
}

/// Seconds a distance field takes per grid cell it visits (`office`: 38,400 cells in about
/// 0.49 ms, rounded up).
const S_PER_FIELD_CELL: f64 = 15e-9;

/// The `search` planner's travel table on `def` (bytes, grid cells its distance fields
/// visit): built once per map and shared, but priced with every match that may be the
/// first to need it. Its positions are at most one per candidate cell of the map, and
/// the table is built only within its bounds, so this is its most.
fn search_table(def: &MapDef, config: &MatchConfig, cells: f64) -> (f64, f64) {
    use lasertag_core::planner::coordinated::travel::{MAX_TABLE_POSITIONS, MAX_TABLE_WORK};
    if config.planner != lasertag_core::planner::PlannerKind::Search {
        return (0.0, 0.0);
    }
    let spacing = config.coordination.candidate_spacing as f64;
    let positions = ((def.width as f64 / spacing).ceil() * (def.height as f64 / spacing).ceil())
        .min(MAX_TABLE_POSITIONS as f64);
    let visits = (positions * cells).min(MAX_TABLE_WORK as f64);
    (positions * positions * 4.0, visits)
}

/// The price of a match with `config` on a map of `def`'s size (the map's own price is
/// separate: charged once for a stored map, with the match for an inline one).
pub fn match_on(def: &MapDef, config: &MatchConfig) -> Price {
    let (_, cols, rows) = ClearanceGrid::shape(def.width, def.height);
    let cells = (cols * rows) as f64;
    let robots = config.robots as f64;
    let tracker = &config.tracker;
    // One tracker for the team, or one per robot behind an imperfect radio.
    let copies = if config.radio.perfect() { 1.0 } else { robots };
    // The worst case: one role per opponent, each with its own particles.
    let particles = tracker.particles_per_role as f64 * config.opponents as f64;
    let merge_cells = ((def.width / tracker.grid_cell).ceil() as f64)
        * ((def.height / tracker.grid_cell).ceil() as f64);
    let landmarks = def.landmarks.len() as f64;
    let per_copy =
        cells * 4.0 + merge_cells * BYTES_PER_MERGE_CELL + particles * BYTES_PER_PARTICLE;
    let memory = MATCH_BASE_BYTES
        + robots * (BYTES_PER_ROBOT + landmarks * 8.0)
        + copies * per_copy
        + recorded_orders(config);
    let localising = if config.localisation { robots } else { 0.0 };
    // The search planner negotiates as the coordinated one does, and looks ahead on top.
    let coordinated = if matches!(
        config.planner,
        lasertag_core::planner::PlannerKind::Coordinated
            | lasertag_core::planner::PlannerKind::Search
    ) {
        robots
    } else {
        0.0
    };
    let (table_bytes, table_visits) = search_table(def, config, cells);
    let beams = localising * config.localiser.beams as f64;
    let merges = if tracker.merge {
        // Pairs of roles, one role per opponent at most, in each tracker copy.
        let roles = config.opponents as f64;
        copies * roles * (roles - 1.0) / 2.0 * merge_cells
    } else {
        0.0
    };
    Price {
        memory: (memory + table_bytes) as u64,
        disk: if takes_orders(config) {
            crate::game::record::MAX_RECORD_BYTES as u64
        } else {
            0
        } + (CHECKPOINTS_KEPT * checkpoint_bytes(def, config) as f64) as u64,
        // The world's own setup (particles drawn, trackers copied); the map's grids are in
        // the map's price.
        build_s: 0.01
            + copies * (merge_cells + particles) * 20e-9
            + table_visits * S_PER_FIELD_CELL,
        tick_ms: TICK_BASE_MS
            + cells * TICK_MS_PER_CELL
            + robots * TICK_MS_PER_ROBOT
            + coordinated * TICK_MS_PER_COORDINATED_ROBOT
            + copies * particles * (TICK_MS_PER_PARTICLE + robots * TICK_MS_PER_PARTICLE_ROBOT)
            + localising * landmarks * TICK_MS_PER_LANDMARK
            + beams * TICK_MS_PER_LOCALISER_BEAM
            + search_views(config) * TICK_MS_PER_SEARCH_VIEW
            + merges * TICK_MS_PER_MERGE_CELL_PAIR,
    }
}

/// Milliseconds of a match's tick, at its price, past which the tick runs off the runtime's
/// workers (`tokio::task::block_in_place`): a tick holds its worker until it ends, and
/// every task queued on that worker (other matches' ticks, reads of them) waits as long.
/// Ordinary matches are priced at 0.5–1.3 ms and stay on the workers (the hand-off wakes a
/// thread, tens of microseconds, too dear for hundreds of matches at 20 Hz each); a
/// `search` planner looking several levels deep every tick is priced at 10–16 ms, a fifth
/// to a third of the period, and hands its worker's queue on.
pub const HEAVY_TICK_MS: f64 = 2.0;

/// Whether a match priced at `price` runs its ticks off the workers (see [`HEAVY_TICK_MS`]).
pub fn holds_a_worker(price: &Price) -> bool {
    price.tick_ms > HEAVY_TICK_MS
}

/// Microseconds of one robot's observation for a policy besides its belief features: the
/// layout's encoding, the teammates, the detections (measured by `benches/policy.rs`).
const POLICY_OBSERVATION_US: f64 = 4.0;
/// Microseconds per particle of the robot's tracker that its belief features read.
const POLICY_OBSERVATION_US_PER_PARTICLE: f64 = 0.012;
/// Microseconds per cell of the window the belief's sorting by the way to it searches in
/// (the grid's cells within its reach in rows and columns: the search's tables and the
/// waypoints' memo), besides the cells it settles within the reach (`S_PER_FIELD_CELL`
/// each). A conservative fit of `examples/policy_tick.rs` (docs/performance.md, "Trained
/// policies"): the whole observation took 124 µs on `office` and 140 µs on `warehouse`,
/// where this prices 201 µs on each.
const POLICY_OBSERVATION_US_PER_WINDOW_CELL: f64 = 0.001;

/// What a trained policy adds to a match with `config` on a map of `def`'s size (see
/// `game::policies`): every robot's observation and one inference (`inference_us`, timed
/// on this machine when the policy was loaded) every `every` ticks.
pub fn policy(def: &MapDef, config: &MatchConfig, inference_us: f64, every: u64) -> Price {
    use lasertag_core::tracker::features::PATH_REACH_M;
    let (cell, cols, rows) = ClearanceGrid::shape(def.width, def.height);
    let cells = (cols * rows) as f64;
    let span = 2 * (PATH_REACH_M / cell).floor() as usize + 1;
    let window = (cols.min(span) * rows.min(span)) as f64;
    let within_reach = (std::f64::consts::PI * (PATH_REACH_M / cell).powi(2) as f64).min(cells);
    let robots = config.robots as f64;
    let copies_particles = config.tracker.particles_per_role as f64 * config.opponents as f64;
    let observation_us = POLICY_OBSERVATION_US
        + copies_particles * POLICY_OBSERVATION_US_PER_PARTICLE
        + window * POLICY_OBSERVATION_US_PER_WINDOW_CELL
        + within_reach * S_PER_FIELD_CELL * 1e6;
    Price {
        tick_ms: robots * (observation_us + inference_us) / every.max(1) as f64 / 1000.0,
        ..Price::default()
    }
}

/// Views the `search` planner's look-ahead weighs in one choice: `SHORTLIST` at each node
/// below the first level, whose `search_branching` best poses each lead `search_depth - 1`
/// levels down, `search_branching` continuations a node (0 for any other planner).
fn search_views(config: &MatchConfig) -> f64 {
    use lasertag_core::planner::coordinated::search::SHORTLIST;
    if config.planner != lasertag_core::planner::PlannerKind::Search {
        return 0.0;
    }
    // The choice's own ranking, in views.
    let ranking = TICK_MS_PER_SEARCH_CHOICE / TICK_MS_PER_SEARCH_VIEW;
    let branching = config.coordination.search_branching as f64;
    let nodes: f64 = (1..config.coordination.search_depth)
        .map(|level| branching.powi(level as i32))
        .sum();
    ranking + nodes * SHORTLIST as f64
}

/// The settings the tick prices are fitted to and checked against on every shipped map: the
/// API's default match, the load test's, a large team, an imperfect radio (a tracker per
/// robot), few particles, the baseline planner, the search planner (as it comes, and deep
/// and wide, choosing every tick), every laser beam weighed by the localiser, and a fine
/// merge grid merged every tick; against `evade` bots, placed at random.
pub fn calibration_settings() -> Vec<(&'static str, MatchConfig)> {
    use lasertag_core::bots::BotKind;
    use lasertag_core::planner::PlannerKind;
    use lasertag_core::world::Placement;
    let base = |robots, opponents| MatchConfig {
        robots,
        opponents,
        opponent_bot: BotKind::Evade,
        planner: PlannerKind::Coordinated,
        placement: Placement::Random,
        ..MatchConfig::default()
    };
    let mut radio = base(2, 3);
    radio.radio.latency_ticks = 4;
    radio.radio.loss = 0.2;
    let mut light = base(2, 3);
    light.tracker.particles_per_role = 250;
    let mut baseline = base(2, 3);
    baseline.planner = PlannerKind::Baseline;
    let mut search = base(2, 3);
    search.planner = PlannerKind::Search;
    let mut deep = search.clone();
    deep.coordination.search_depth = 5;
    deep.coordination.search_branching = 6;
    deep.coordination.round_ticks = 1;
    let mut beams = base(2, 3);
    beams.localiser.beams = 181;
    let mut merging = base(2, 8);
    merging.tracker.grid_cell = 0.25;
    merging.tracker.merge_interval = 1;
    vec![
        ("default_2r_1o", base(2, 1)),
        ("loadtest_2r_3o", base(2, 3)),
        ("large_4r_8o", base(4, 8)),
        ("radio_2r_3o", radio),
        ("light_2r_3o_250p", light),
        ("baseline_2r_3o", baseline),
        ("search_2r_3o", search),
        ("search_deep_2r_3o", deep),
        ("beams_2r_3o", beams),
        ("merging_2r_8o", merging),
    ]
}

/// Bytes of a copy of a world besides what its settings scale (measured: about 300 KB for
/// the default match on `office`, the arena shared and not copied).
const WORLD_COPY_BASE_BYTES: f64 = 400e3;

/// The bytes of one copy of a match's world with `config` on `def` (a replay's keyframe, a
/// replay socket's cursor): the match's price without what a running match keeps besides
/// its world (queues, frames), the arena shared.
pub fn world_copy(def: &MapDef, config: &MatchConfig) -> u64 {
    let kept = match_on(def, config).memory as f64 - MATCH_BASE_BYTES - recorded_orders(config);
    (kept.max(0.0) + WORLD_COPY_BASE_BYTES) as u64
}

/// Bytes of a held frame besides its robots, opponents and belief points (the frame, its
/// belief's roles, a few events).
const HELD_FRAME_BYTES: f64 = 1_500.0;
/// Bytes of a robot in a held frame besides its scan, sightings and cloud.
const HELD_ROBOT_BYTES: f64 = 160.0;
/// Bytes of an opponent in a held frame, and of a role in a held belief.
const HELD_AGENT_BYTES: f64 = 96.0;
/// Bytes per particle of a held belief (position and weight as `f32`s).
const HELD_BYTES_PER_PARTICLE: f64 = 12.0;

/// The price of what a match people play keeps to show its truth `delay_ticks` late
/// (`game::delay`): a frame per tick of the delay and a belief of the team and of each
/// robot with a tracker of its own every `BELIEF_HOLD_EVERY` ticks. Nothing for a live match.
pub fn held_back(config: &MatchConfig, delay_ticks: u64) -> Price {
    use crate::game::view::{
        BELIEF_BUDGET, BELIEF_EVERY, BELIEF_HOLD_EVERY, BELIEF_MIN_PER_ROLE, CLOUD_POINTS,
    };
    if delay_ticks == 0 {
        return Price::default();
    }
    let robots = config.robots as f64;
    let opponents = config.opponents as f64;
    let robot = HELD_ROBOT_BYTES
        + config.physics.laser_beams as f64 * 4.0
        + opponents * 8.0
        + CLOUD_POINTS as f64 * 8.0;
    let points = (BELIEF_BUDGET as f64).max(opponents * BELIEF_MIN_PER_ROLE as f64);
    let belief_view = points * 8.0 + opponents * HELD_AGENT_BYTES;
    let frame = HELD_FRAME_BYTES
        + robots * robot
        + opponents * HELD_AGENT_BYTES
        + belief_view / BELIEF_EVERY as f64;
    // The team's belief, and each robot's own behind an imperfect radio.
    let copies = if config.radio.perfect() {
        1.0
    } else {
        1.0 + robots
    };
    let particles = config.tracker.particles_per_role as f64 * opponents;
    let belief = copies * (particles * HELD_BYTES_PER_PARTICLE + opponents * HELD_AGENT_BYTES);
    let beliefs = (delay_ticks / BELIEF_HOLD_EVERY + 2) as f64;
    Price {
        memory: ((delay_ticks + 1) as f64 * frame + beliefs * belief) as u64,
        ..Price::default()
    }
}

/// Grid cells of size `cell` that a box from `lo` to `hi` touches.
fn cells_in(lo: Point2<f32>, hi: Point2<f32>, cell: f32) -> f64 {
    (((hi.x - lo.x) / cell).floor() as f64 + 1.0) * (((hi.y - lo.y) / cell).floor() as f64 + 1.0)
}

/// Megabytes, for messages.
pub fn mb(bytes: u64) -> String {
    format!("{:.0} MB", bytes as f64 / 1e6)
}

/// Why a new match (or map) was not let in; each says what to do about it.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum NoRoom {
    /// The server holds its most matches (the number).
    #[error(
        "the server holds {0} matches, its most; try again when one has finished (finished matches are removed after a grace period)"
    )]
    Server(usize),
    /// This client holds its most matches.
    #[error(
        "{client} holds {max} matches, the most one client may; delete one (DELETE /api/matches/{{id}} with its owner_token) or wait for one to end"
    )]
    Client {
        client: crate::access::ClientKey,
        max: usize,
    },
    /// What is admitted already and this would take the server past its memory budget.
    #[error(
        "the server's memory budget of {} is taken ({} admitted; this needs {}); try again when matches have ended",
        mb(*.budget),
        mb(*.held),
        mb(*.asked)
    )]
    Memory { held: u64, asked: u64, budget: u64 },
    /// This client's matches and maps and this would be priced past its share of the
    /// server's budgets.
    #[error(
        "{client} holds matches and maps priced at {} and {:.1} ms per tick; this needs {} and {:.1} ms, past the share one client may hold ({} and {tick_ms:.1} ms); delete a match or map (with its owner_token) or wait for one to end",
        mb(.held.memory),
        .held.tick_ms,
        mb(.asked.memory),
        .asked.tick_ms,
        mb(*.memory)
    )]
    ClientBudget {
        client: crate::access::ClientKey,
        held: Price,
        asked: Price,
        /// Its share: bytes, and tick milliseconds.
        memory: u64,
        tick_ms: f64,
    },
    /// The running matches and this one would be priced past the tick budget.
    #[error(
        "the server's tick budget of {budget_ms:.0} ms is taken ({held_ms:.1} ms admitted; this match needs {asked_ms:.1} ms); try again when matches have ended"
    )]
    Cpu {
        held_ms: f64,
        asked_ms: f64,
        budget_ms: f64,
    },
    /// The running matches' records, the uploaded policies kept and this request would be
    /// priced past the store's budget.
    #[error(
        "the server's disk budget of {} is taken ({} held by running matches' records and kept policies; this asks for {}); try again when matches have ended or policies are deleted",
        mb(*.budget),
        mb(*.held),
        mb(*.asked)
    )]
    Disk { held: u64, asked: u64, budget: u64 },
    /// The server is draining before it shuts down.
    #[error(
        "the server is shutting down and takes no new matches; its running matches go on until they end"
    )]
    Draining,
}

#[cfg(test)]
mod tests;
