//! What creating state costs, measured from the inputs of a request: the data behind pricing
//! map uploads, inline maps and matches before anything is allocated.
//!
//! For each scenario of a table (one input varied at a time from a baseline: the `office`
//! map, 2 robots, 1 opponent, the API's defaults) it measures, with a counting global
//! allocator and a wall clock, each phase on its own (the allocator's peak is reset between
//! phases):
//!
//! 1. map: `maps::from_value` (parse and validate the JSON) then `Arena::new` — time, peak
//!    bytes above the start (the input JSON included), bytes the `Arena` keeps;
//! 2. match: `World::new` on a fresh arena (so it builds the arena's derived tables: the
//!    planner's view table, the localiser's likelihood field), then a second `World::new` on
//!    the same arena (the derived tables cached: what one more match on that map costs;
//!    skipped when it would take the live bytes over the cap);
//! 3. stepping: 40 ticks of `World::step` — mean and max tick time, peak above the start of
//!    stepping, bytes kept afterwards, allocations per tick;
//! 4. breakdown: the view table, the likelihood field and one tracker built again on their
//!    own (uncached), to attribute the derived cost of phase 2.
//!
//! The match configuration goes through `CreateMatch::validate`, as an API request would.
//! Each scenario runs in a child process (this same program, `--child <name>`), so that
//! arenas and allocator state never leak between scenarios, with a time limit (default 60 s)
//! and an allocation cap (default 3 GiB): a scenario over either is stopped and reported
//! with the phase it was in, and its earlier phases are kept.
//!
//! ```sh
//! cargo run --release --example admission_probe                  # every scenario
//! cargo run --release --example admission_probe -- --only diag   # names containing "diag"
//! cargo run --release --example admission_probe -- --list
//! cargo run --release --example admission_probe -- --timeout-s 120 --cap-gib 4
//! ```
//!
//! Output: one CSV row per scenario (bytes and milliseconds), then a readable table (MB =
//! 10^6 bytes).
//!
//! Some scenarios are over the map format's limits (`MAX_LANDMARKS`, `MAX_POLYGON_VERTICES`,
//! `MAX_VERTICES`, `MAX_SPAWNS`): the validator refuses them before anything is built. They
//! stay in the table, to show what the limits cut off, as `refused by the map format (…)`
//! when the validator refused them with a limit in phase 1.
//!
//! Long file: the scenario table, the child-process harness, the counting allocator and the
//! report belong together in one program that can be read top to bottom.

use std::alloc::{GlobalAlloc, Layout, System};
use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::time::{Duration, Instant};

use lasertag::protocol::CreateMatch;
use lasertag_core::localise::LikelihoodField;
use lasertag_core::sim::arena::Arena;
use lasertag_core::sim::views::ViewTable;
use lasertag_core::tracker::Tracker;
use lasertag_core::world::{MatchConfig, World};
use rand::SeedableRng;
use serde_json::{Value, json};

// ---------------------------------------------------------------------------------------
// The counting allocator.
//
// A measurement tool only: this example is the one place in the project that replaces the
// global allocator, and only to count. It forwards every call to `System` unchanged and
// keeps three atomics: bytes live now, the highest that has been since the last reset, and
// the number of allocations. It can also refuse an allocation that would take the live
// total over a cap, so that a runaway scenario stops (the standard "memory allocation
// failed" abort) instead of exhausting the machine. Counts are of requested sizes, not of
// what the system allocator rounds them up to.
// ---------------------------------------------------------------------------------------

struct Counting;

static CURRENT: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);
static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);
static CAP: AtomicUsize = AtomicUsize::new(usize::MAX);

/// Counts `n` more bytes live, unless that would pass the cap.
fn reserve(n: usize) -> bool {
    let now = CURRENT.fetch_add(n, Relaxed) + n;
    if now > CAP.load(Relaxed) {
        CURRENT.fetch_sub(n, Relaxed);
        return false;
    }
    PEAK.fetch_max(now, Relaxed);
    ALLOCATIONS.fetch_add(1, Relaxed);
    true
}

fn release(n: usize) {
    CURRENT.fetch_sub(n, Relaxed);
}

// SAFETY: every method forwards to `System` with the caller's arguments and only adds
// bookkeeping; a refused request returns null, which `GlobalAlloc` allows.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if !reserve(layout.size()) {
            return std::ptr::null_mut();
        }
        let p = unsafe { System.alloc(layout) };
        if p.is_null() {
            release(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if !reserve(layout.size()) {
            return std::ptr::null_mut();
        }
        let p = unsafe { System.alloc_zeroed(layout) };
        if p.is_null() {
            release(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        release(layout.size());
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let old = layout.size();
        if new_size > old && !reserve(new_size - old) {
            return std::ptr::null_mut();
        }
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if p.is_null() {
            if new_size > old {
                release(new_size - old);
            }
        } else if new_size < old {
            release(old - new_size);
        }
        p
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn current() -> usize {
    CURRENT.load(Relaxed)
}

/// Starts a phase: the peak is forgotten and becomes the bytes live now.
fn reset_peak() -> usize {
    let now = current();
    PEAK.store(now, Relaxed);
    now
}

fn peak() -> usize {
    PEAK.load(Relaxed)
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

// ---------------------------------------------------------------------------------------
// Scenarios.
// ---------------------------------------------------------------------------------------

const TICKS: u64 = 40;

/// The shipped map every "office" scenario starts from.
const OFFICE: &str = include_str!("../maps/office.json");

#[derive(Debug, Clone, Copy)]
enum MapSpec {
    /// The shipped office; `Some(n)` replaces its landmarks by `n` spread over the arena.
    Office(Option<usize>),
    /// An empty square of this side (m).
    Empty(f64),
    /// 500 m × 500 m with this many thin slivers, each a long diagonal quadrilateral.
    Diagonals(usize),
    /// 100 m × 100 m with small squares totalling this many vertices.
    Squares(usize),
    /// 100 m × 100 m with one polygon of this many vertices (a circle of radius 30 m).
    Ring(usize),
}

struct Scenario {
    name: &'static str,
    /// What the rows of one group vary.
    group: &'static str,
    map: MapSpec,
    /// The `CreateMatch` fields besides `map`.
    request: Value,
}

fn scenarios() -> Vec<Scenario> {
    let s = |name, group, map, request| Scenario {
        name,
        group,
        map,
        request,
    };
    let none = || json!({});
    let mut v = vec![s("baseline", "baseline", MapSpec::Office(None), none())];
    for side in [20.0, 60.0, 100.0, 250.0, 500.0] {
        let name = match side as u32 {
            20 => "empty-20m",
            60 => "empty-60m",
            100 => "empty-100m",
            250 => "empty-250m",
            _ => "empty-500m",
        };
        v.push(s(name, "map area", MapSpec::Empty(side), none()));
    }
    for (name, n) in [
        ("diagonals-1", 1),
        ("diagonals-4", 4),
        ("diagonals-16", 16),
        ("diagonals-64", 64),
        ("diagonals-256", 256),
    ] {
        v.push(s(name, "diagonal edges", MapSpec::Diagonals(n), none()));
    }
    for (name, n) in [
        ("vertices-100", 100),
        ("vertices-1000", 1000),
        ("vertices-5000", 5000),
        ("vertices-10000", 10_000),
    ] {
        v.push(s(name, "vertex count", MapSpec::Squares(n), none()));
    }
    for (name, n) in [("ring-1000", 1000), ("ring-10000", 10_000)] {
        v.push(s(name, "vertex count", MapSpec::Ring(n), none()));
    }
    for (name, n) in [
        ("landmarks-0", 0),
        ("landmarks-1000", 1000),
        ("landmarks-10000", 10_000),
        ("landmarks-100000", 100_000),
    ] {
        let request = json!({"localisation": true});
        v.push(s(name, "landmarks", MapSpec::Office(Some(n)), request));
    }
    v.push(s(
        "landmarks-100000-loc-off",
        "landmarks",
        MapSpec::Office(Some(100_000)),
        json!({"localisation": false}),
    ));
    v.push(s(
        "localisation-off",
        "landmarks",
        MapSpec::Office(None),
        json!({"localisation": false}),
    ));
    for (name, robots, opponents) in [
        ("robots-8", 8, 1),
        ("opponents-32", 2, 32),
        ("agents-8-32", 8, 32),
    ] {
        let request = json!({"robots": robots, "opponents": opponents});
        v.push(s(name, "agents", MapSpec::Office(None), request));
    }
    for (name, n) in [
        ("particles-1000", 1000),
        ("particles-5000", 5000),
        ("particles-20000", 20_000),
    ] {
        let request = json!({"opponents": 8, "tracker": {"particles_per_role": n}});
        v.push(s(name, "particles", MapSpec::Office(None), request));
    }
    let grid = |cell: Option<f64>, loss: f64| {
        let mut r = json!({"robots": 8, "opponents": 8, "radio": {"loss": loss}});
        if let Some(c) = cell {
            r["tracker"] = json!({"grid_cell": c});
        }
        r
    };
    v.push(s(
        "grid-default",
        "tracker grid",
        MapSpec::Empty(100.0),
        grid(None, 0.0),
    ));
    v.push(s(
        "grid-0.1",
        "tracker grid",
        MapSpec::Empty(100.0),
        grid(Some(0.1), 0.0),
    ));
    v.push(s(
        "grid-0.1-lossy",
        "tracker grid",
        MapSpec::Empty(100.0),
        grid(Some(0.1), 0.5),
    ));
    v.push(s(
        "grid-0.1-500m",
        "tracker grid",
        MapSpec::Empty(500.0),
        grid(Some(0.1), 0.0),
    ));
    v.push(s(
        "grid-0.1-500m-lossy",
        "tracker grid",
        MapSpec::Empty(500.0),
        grid(Some(0.1), 0.5),
    ));
    let radio = |loss: f64, particles: usize| {
        json!({"robots": 8, "opponents": 8, "radio": {"loss": loss},
               "tracker": {"particles_per_role": particles}})
    };
    v.push(s(
        "radio-perfect-8x8",
        "radio",
        MapSpec::Office(None),
        radio(0.0, 1000),
    ));
    v.push(s(
        "radio-lossy-8x8",
        "radio",
        MapSpec::Office(None),
        radio(0.5, 1000),
    ));
    v.push(s(
        "radio-lossy-8x8-p20000",
        "radio",
        MapSpec::Office(None),
        radio(0.5, 20_000),
    ));
    v
}

/// Rounds to a millimetre, as a map author would write coordinates.
fn r3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

fn map_json(spec: MapSpec) -> Value {
    match spec {
        MapSpec::Office(None) => serde_json::from_str(OFFICE).expect("maps/office.json parses"),
        MapSpec::Office(Some(n)) => {
            let mut m: Value = serde_json::from_str(OFFICE).expect("maps/office.json parses");
            let (w, h) = (m["width"].as_f64().unwrap(), m["height"].as_f64().unwrap());
            // The R2 low-discrepancy sequence: evenly spread, deterministic.
            let (a1, a2) = (0.754_877_666_246_692_8, 0.569_840_290_998_053_3);
            let landmarks: Vec<[f64; 2]> = (1..=n)
                .map(|k| {
                    let k = k as f64;
                    [r3((k * a1).fract() * w), r3((k * a2).fract() * h)]
                })
                .collect();
            m["landmarks"] = json!(landmarks);
            m
        }
        MapSpec::Empty(side) => json!({
            "name": "probe", "width": side, "height": side, "obstacles": [],
            "robot_spawns": [[1.0, 1.0, 0.0]],
            "opponent_spawns": [[side - 1.0, side - 1.0]],
        }),
        MapSpec::Diagonals(n) => {
            // Parallel slivers 0.5 m wide along the diagonal from near (10, 10) to near
            // (490, 490), 1.5 m apart, alternately shifted right (from (10 + d, 10) to
            // (490, 490 - d)) and up (from (10, 10 + d) to (490 - d, 490)).
            let half = 0.5 / std::f64::consts::SQRT_2; // the width along (-1, 1) / √2
            let slivers: Vec<Vec<[f64; 2]>> = (0..n)
                .map(|k| {
                    let d = 1.5 * k.div_ceil(2) as f64;
                    let (a, b) = if k % 2 == 0 {
                        ([10.0 + d, 10.0], [490.0, 490.0 - d])
                    } else {
                        ([10.0, 10.0 + d], [490.0 - d, 490.0])
                    };
                    vec![
                        a,
                        b,
                        [r3(b[0] - half), r3(b[1] + half)],
                        [r3(a[0] - half), r3(a[1] + half)],
                    ]
                })
                .collect();
            json!({
                "name": "probe", "width": 500.0, "height": 500.0, "obstacles": slivers,
                "robot_spawns": [[480.0, 20.0, 0.0]],
                "opponent_spawns": [[20.0, 480.0]],
            })
        }
        MapSpec::Ring(n) => {
            let ring: Vec<[f64; 2]> = (0..n)
                .map(|k| {
                    let a = k as f64 / n as f64 * std::f64::consts::TAU;
                    [r3(50.0 + 30.0 * a.cos()), r3(50.0 + 30.0 * a.sin())]
                })
                .collect();
            json!({
                "name": "probe", "width": 100.0, "height": 100.0, "obstacles": [ring],
                "robot_spawns": [[5.0, 5.0, 0.0]],
                "opponent_spawns": [[95.0, 95.0]],
            })
        }
        MapSpec::Squares(vertices) => {
            // 0.5 m squares centred on a k × k lattice over the map; spawns on lattice
            // corners, at least 1 m from every square.
            let squares = vertices / 4;
            let k = (squares as f64).sqrt().ceil() as usize;
            let sp = 100.0 / k as f64;
            let obstacles: Vec<Vec<[f64; 2]>> = (0..squares)
                .map(|i| {
                    let (cx, cy) = (
                        (i % k) as f64 * sp + sp / 2.0,
                        (i / k) as f64 * sp + sp / 2.0,
                    );
                    let (x0, x1, y0, y1) =
                        (r3(cx - 0.25), r3(cx + 0.25), r3(cy - 0.25), r3(cy + 0.25));
                    vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
                })
                .collect();
            let far = (k - 1) as f64 * sp;
            json!({
                "name": "probe", "width": 100.0, "height": 100.0, "obstacles": obstacles,
                "robot_spawns": [[r3(sp), r3(sp), 0.0]],
                "opponent_spawns": [[r3(far), r3(far)]],
            })
        }
    }
}

/// Input measures of a map, read from its JSON (what an admission check could compute):
/// obstacle vertices, total wall length (obstacles and border, m), and the sum over wall
/// segments of the cells of the ray-cast bucket grid their bounding boxes touch (the
/// arena's `SegmentGrid` rule: 0.5 m cells, coarser beyond 250,000 cells).
fn map_measures(m: &Value) -> (usize, f64, u64) {
    let (w, h) = (m["width"].as_f64().unwrap(), m["height"].as_f64().unwrap());
    let border = vec![[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]];
    let polys: Vec<Vec<[f64; 2]>> = serde_json::from_value(m["obstacles"].clone()).unwrap();
    let vertices = polys.iter().map(Vec::len).sum();
    let cell = 0.5f64.max((w * h / 250_000.0).sqrt());
    let (cols, rows) = ((w / cell).ceil().max(1.0), (h / cell).ceil().max(1.0));
    let (mut length, mut cells) = (0.0, 0u64);
    for poly in std::iter::once(&border).chain(&polys) {
        for (i, a) in poly.iter().enumerate() {
            let b = poly[(i + 1) % poly.len()];
            length += ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
            let span = |lo: f64, hi: f64, n: f64| {
                let c0 = ((lo - 1e-3) / cell).floor().max(0.0);
                let c1 = ((hi + 1e-3) / cell).floor().min(n - 1.0);
                (c1 - c0 + 1.0).max(0.0) as u64
            };
            cells += span(a[0].min(b[0]), a[0].max(b[0]), cols)
                * span(a[1].min(b[1]), a[1].max(b[1]), rows);
        }
    }
    (vertices, length, cells)
}

/// The match configuration an API request with these fields would get.
fn match_config(request: &Value) -> MatchConfig {
    let mut body = request.clone();
    body["map"] = json!("probe");
    let bytes = serde_json::to_vec(&body).unwrap();
    let create: CreateMatch = lasertag::protocol::parse(&bytes).expect("request parses");
    create.validate().expect("request is valid").config
}

// ---------------------------------------------------------------------------------------
// One scenario, measured (the child process). Prints `key<TAB>value` lines as it goes;
// `phase<TAB>name` marks where it is, should it be stopped.
// ---------------------------------------------------------------------------------------

fn emit(key: &str, value: impl std::fmt::Display) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{key}\t{value}");
    let _ = out.flush();
}

fn run_child(sc: &Scenario) -> Result<(), String> {
    let config = match_config(&sc.request);
    let text_bytes = serde_json::to_string(&map_json(sc.map)).unwrap().len();
    let (vertices, length, seg_cells) = map_measures(&map_json(sc.map));
    let trackers = if config.radio.uses_channel() {
        config.robots
    } else {
        1
    };
    emit("json_text_bytes", text_bytes);
    emit("vertices", vertices);
    emit("wall_length_m", format!("{length:.0}"));
    emit("seg_bbox_cells", seg_cells);
    emit("robots", config.robots);
    emit("opponents", config.opponents);
    emit("particles_per_role", config.tracker.particles_per_role);
    emit("grid_cell", config.tracker.grid_cell);
    emit("trackers", trackers);
    emit("localisation", config.localisation);

    // Phase 1: the map.
    emit("phase", "map");
    let before_json = current();
    let value = map_json(sc.map);
    emit(
        "landmarks",
        value["landmarks"].as_array().map_or(0, Vec::len),
    );
    let start = reset_peak();
    emit("json_value_bytes", start - before_json);
    let t = Instant::now();
    let def = lasertag::maps::from_value(value).map_err(|e| e.to_string())?;
    emit("validate_ms", format!("{:.3}", ms(t.elapsed())));
    emit("validate_peak_b", peak() - start);
    let t = Instant::now();
    let arena = Arc::new(Arena::new(def));
    emit("arena_ms", format!("{:.3}", ms(t.elapsed())));
    emit("map_peak_b", peak() - start);
    emit("arena_retained_b", current() - before_json);
    emit("clearance_cells", arena.grid.len());

    // Phase 2: the match, cold (derived tables built) then warm (cached).
    emit("phase", "world");
    let start = reset_peak();
    let t = Instant::now();
    let mut world = World::new(arena.clone(), config.clone()).map_err(|e| e.to_string())?;
    emit("world_ms", format!("{:.3}", ms(t.elapsed())));
    emit("world_peak_b", peak() - start);
    let retained = current() - start;
    emit("world_retained_b", retained);
    // A second match would about double what is live: skip it when that passes the cap,
    // so that stepping is still measured.
    if current() + retained < CAP.load(Relaxed) {
        emit("phase", "world-warm");
        let start = reset_peak();
        let t = Instant::now();
        let warm = World::new(arena.clone(), config.clone()).map_err(|e| e.to_string())?;
        emit("warm_ms", format!("{:.3}", ms(t.elapsed())));
        emit("warm_peak_b", peak() - start);
        emit("warm_retained_b", current() - start);
        drop(warm);
    } else {
        emit("skipped", "second World::new (over the cap)");
    }

    // Phase 3: stepping.
    emit("phase", "step");
    let start = reset_peak();
    let allocations = ALLOCATIONS.load(Relaxed);
    let mut times = Vec::with_capacity(TICKS as usize);
    for _ in 0..TICKS {
        let t = Instant::now();
        world.step();
        times.push(ms(t.elapsed()));
    }
    let mean = times.iter().sum::<f64>() / times.len() as f64;
    let max = times.iter().copied().fold(0.0, f64::max);
    emit("ticks", world.tick);
    emit("tick_mean_ms", format!("{mean:.3}"));
    emit("tick_max_ms", format!("{max:.3}"));
    emit("step_peak_b", peak() - start);
    emit("step_retained_b", current() as i64 - start as i64);
    emit(
        "allocs_per_tick",
        (ALLOCATIONS.load(Relaxed) - allocations) / TICKS,
    );
    let roles: usize = world.team.trackers.iter().map(|t| t.roles.len()).sum();
    emit("roles_after", roles);
    drop(world);

    // Phase 4: what the derived tables and a tracker cost on their own.
    emit("phase", "breakdown");
    let spec = config.coordination.view_spec(&arena, &config.physics);
    let start = reset_peak();
    let t = Instant::now();
    let views = ViewTable::build(&arena, spec);
    emit("views_ms", format!("{:.3}", ms(t.elapsed())));
    emit("views_b", current() - start);
    emit("view_poses", views.len());
    drop(views);
    if config.localisation {
        let start = reset_peak();
        let t = Instant::now();
        let field = LikelihoodField::new(&arena, &config.localiser, config.physics.laser_range);
        emit("field_ms", format!("{:.3}", ms(t.elapsed())));
        emit("field_b", current() - start);
        drop(field);
    }
    let mut settings = config.tracker.clone();
    settings.opponent_speed = config.physics.opponent_speed;
    settings.tag_half_angle = config.physics.tag_half_angle;
    settings.tag_range = config.physics.tag_range;
    let start = reset_peak();
    let t = Instant::now();
    let tracker = Tracker::new(
        &arena,
        settings,
        config.opponents as u32,
        rand_chacha::ChaCha8Rng::seed_from_u64(0),
    );
    emit("tracker_ms", format!("{:.3}", ms(t.elapsed())));
    emit("tracker_b", current() - start);
    drop(tracker);
    emit("phase", "done");
    Ok(())
}

// ---------------------------------------------------------------------------------------
// The table (the parent process).
// ---------------------------------------------------------------------------------------

/// The map format's limit a scenario's map is over, if any, from the constants the validator
/// (`maps::validate`) enforces. Such a map is refused at validation before anything is built;
/// the scenario stays to show what the limit cuts off, and its row says so instead of
/// reporting a failed child.
fn over_format_limit(m: &Value) -> Option<String> {
    use lasertag::maps::{MAX_LANDMARKS, MAX_POLYGON_VERTICES, MAX_SPAWNS, MAX_VERTICES};
    let count = |v: &Value| v.as_array().map_or(0, Vec::len);
    let polygons: Vec<usize> = m["obstacles"]
        .as_array()
        .map_or(Vec::new(), |ps| ps.iter().map(count).collect());
    [
        (
            "obstacle vertices in all",
            polygons.iter().sum(),
            MAX_VERTICES,
        ),
        (
            "vertices in one polygon",
            polygons.iter().copied().max().unwrap_or(0),
            MAX_POLYGON_VERTICES,
        ),
        ("robot spawns", count(&m["robot_spawns"]), MAX_SPAWNS),
        ("opponent spawns", count(&m["opponent_spawns"]), MAX_SPAWNS),
        ("landmarks", count(&m["landmarks"]), MAX_LANDMARKS),
    ]
    .into_iter()
    .find(|&(_, n, limit)| n > limit)
    .map(|(what, n, limit)| format!("{n} {what}, the limit is {limit}"))
}

/// CSV columns, in order (the child's keys, plus the parent's `scenario`, `group`, `note`).
const COLUMNS: &[&str] = &[
    "json_text_bytes",
    "json_value_bytes",
    "vertices",
    "wall_length_m",
    "seg_bbox_cells",
    "clearance_cells",
    "landmarks",
    "robots",
    "opponents",
    "particles_per_role",
    "grid_cell",
    "trackers",
    "localisation",
    "validate_ms",
    "validate_peak_b",
    "arena_ms",
    "map_peak_b",
    "arena_retained_b",
    "world_ms",
    "world_peak_b",
    "world_retained_b",
    "warm_ms",
    "warm_peak_b",
    "warm_retained_b",
    "ticks",
    "tick_mean_ms",
    "tick_max_ms",
    "step_peak_b",
    "step_retained_b",
    "allocs_per_tick",
    "roles_after",
    "views_ms",
    "views_b",
    "view_poses",
    "field_ms",
    "field_b",
    "tracker_ms",
    "tracker_b",
];

struct Row {
    name: &'static str,
    group: &'static str,
    values: HashMap<String, String>,
    note: String,
}

fn run_parent(
    exe: &std::path::Path,
    sc: &Scenario,
    timeout: Duration,
    cap: usize,
) -> Result<Row, String> {
    let over_limit = over_format_limit(&map_json(sc.map));
    let mut child = Command::new(exe)
        .args(["--child", sc.name, "--cap-bytes", &cap.to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("starting {}: {e}", exe.display()))?;
    let stdout = child.stdout.take().unwrap();
    let mut stderr = child.stderr.take().unwrap();
    let lines = std::thread::spawn(move || {
        BufReader::new(stdout)
            .lines()
            .map_while(Result::ok)
            .collect::<Vec<_>>()
    });
    let errors = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let t = Instant::now();
    let mut timed_out = false;
    let status = loop {
        if let Some(status) = child.try_wait().map_err(|e| e.to_string())? {
            break status;
        }
        if t.elapsed() > timeout {
            let _ = child.kill();
            timed_out = true;
            break child.wait().map_err(|e| e.to_string())?;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let lines = lines.join().unwrap_or_default();
    let errors = errors.join().unwrap_or_default();
    let mut values = HashMap::new();
    let mut phase = String::from("setup");
    for line in lines {
        if let Some((k, v)) = line.split_once('\t') {
            if k == "phase" {
                phase = v.to_string();
            } else {
                values.insert(k.to_string(), v.to_string());
            }
        }
    }
    let skipped = values
        .get("skipped")
        .map_or(String::new(), |s| format!("skipped: {s}"));
    let note = if timed_out {
        format!(
            "stopped: over {} s, in phase {phase}",
            timeout.as_secs_f64()
        )
    } else if errors.contains("memory allocation of") {
        format!(
            "stopped: over the {:.1} GiB cap, in phase {phase}",
            cap as f64 / (1u64 << 30) as f64
        )
    } else if let Some(limit) = &over_limit
        && !status.success()
        && phase == "map"
        && errors.contains("the limit is")
    {
        // The validator refused it, as the limits say it must: not a failure of the probe.
        format!("refused by the map format ({limit})")
    } else if !status.success() {
        let last = errors.lines().last().unwrap_or("").to_string();
        format!("failed in phase {phase} ({status}): {last}")
    } else if let Some(limit) = &over_limit {
        format!("over the map format's limits ({limit}) but accepted: the validator disagrees")
    } else {
        skipped
    };
    Ok(Row {
        name: sc.name,
        group: sc.group,
        values,
        note,
    })
}

fn mb(row: &Row, key: &str) -> String {
    row.values
        .get(key)
        .and_then(|v| v.parse::<f64>().ok())
        .map_or("-".into(), |b| format!("{:.2}", b / 1e6))
}

fn val(row: &Row, key: &str) -> String {
    row.values.get(key).cloned().unwrap_or_else(|| "-".into())
}

fn print_tables(rows: &[Row]) {
    println!("scenario,group,{},note", COLUMNS.join(","));
    for r in rows {
        let cells: Vec<String> = COLUMNS.iter().map(|c| val(r, c)).collect();
        println!(
            "{},{},{},\"{}\"",
            r.name,
            r.group,
            cells.join(","),
            r.note.replace('"', "'")
        );
    }
    println!();
    let header = [
        "scenario",
        "map ms",
        "map pk MB",
        "arena MB",
        "world ms",
        "world pk MB",
        "world MB",
        "warm ms",
        "warm MB",
        "tick ms",
        "tick max",
        "step pk MB",
        "step +MB",
        "views MB",
        "field MB",
        "note",
    ];
    let mut table: Vec<Vec<String>> = vec![header.iter().map(|s| s.to_string()).collect()];
    for r in rows {
        let map_ms = match (
            r.values
                .get("validate_ms")
                .and_then(|v| v.parse::<f64>().ok()),
            r.values.get("arena_ms").and_then(|v| v.parse::<f64>().ok()),
        ) {
            (Some(a), Some(b)) => format!("{:.1}", a + b),
            _ => "-".into(),
        };
        let num = |k: &str| {
            r.values
                .get(k)
                .and_then(|v| v.parse::<f64>().ok())
                .map_or("-".into(), |x| format!("{x:.1}"))
        };
        table.push(vec![
            r.name.to_string(),
            map_ms,
            mb(r, "map_peak_b"),
            mb(r, "arena_retained_b"),
            num("world_ms"),
            mb(r, "world_peak_b"),
            mb(r, "world_retained_b"),
            num("warm_ms"),
            mb(r, "warm_retained_b"),
            num("tick_mean_ms"),
            num("tick_max_ms"),
            mb(r, "step_peak_b"),
            mb(r, "step_retained_b"),
            mb(r, "views_b"),
            mb(r, "field_b"),
            r.note.clone(),
        ]);
    }
    let widths: Vec<usize> = (0..header.len())
        .map(|c| table.iter().map(|row| row[c].len()).max().unwrap_or(0))
        .collect();
    for (i, row) in table.iter().enumerate() {
        let line: Vec<String> = row
            .iter()
            .zip(&widths)
            .enumerate()
            .map(|(c, (cell, w))| {
                if c == 0 || c == header.len() - 1 {
                    format!("{cell:<w$}")
                } else {
                    format!("{cell:>w$}")
                }
            })
            .collect();
        println!("{}", line.join("  ").trim_end());
        if i == 0 {
            println!(
                "{}",
                "-".repeat(widths.iter().sum::<usize>() + 2 * widths.len())
            );
        }
    }
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let flag = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let all = scenarios();
    if args.iter().any(|a| a == "--list") {
        for sc in &all {
            println!(
                "{:<24} {:<16} {:?} {}",
                sc.name, sc.group, sc.map, sc.request
            );
        }
        return Ok(());
    }
    if let Some(name) = flag("--child") {
        if let Some(cap) = flag("--cap-bytes") {
            CAP.store(cap.parse().map_err(|_| "bad --cap-bytes")?, Relaxed);
        }
        let sc = all
            .iter()
            .find(|s| s.name == name)
            .ok_or_else(|| format!("no scenario {name:?}"))?;
        return run_child(sc);
    }
    let timeout_s: f64 =
        flag("--timeout-s").map_or(Ok(60.0), |s| s.parse().map_err(|_| "bad --timeout-s"))?;
    let cap_gib: f64 =
        flag("--cap-gib").map_or(Ok(3.0), |s| s.parse().map_err(|_| "bad --cap-gib"))?;
    let only = flag("--only");
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let mut rows = Vec::new();
    for sc in all
        .iter()
        .filter(|s| only.as_ref().is_none_or(|o| s.name.contains(o.as_str())))
    {
        let t = Instant::now();
        let row = run_parent(
            &exe,
            sc,
            Duration::from_secs_f64(timeout_s),
            (cap_gib * (1u64 << 30) as f64) as usize,
        )?;
        eprintln!(
            "{:<24} {:>7.1} s  {}",
            sc.name,
            t.elapsed().as_secs_f64(),
            if row.note.is_empty() { "ok" } else { &row.note }
        );
        rows.push(row);
    }
    print_tables(&rows);
    Ok(())
}
