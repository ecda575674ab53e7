//! The rules of the map format (`docs/map-format.md`), on plain data: [`MapSpec`] is a map
//! as a file or a request gives it (numbers as parsed, `f64`), [`validate`] enforces every
//! rule, reports the first violation as a [`MapError`] naming field and index, and turns
//! the spec into a [`MapDef`]. Every way into a match goes through [`validate`]: the
//! server's files, uploads and imports, and the in-process research engine.

use nalgebra::Point2;

use super::AGENT_RADIUS;
use super::arena::{MapDef, point_in_polygon};

/// Most obstacle vertices a map may have, over all polygons.
pub const MAX_VERTICES: usize = 10_000;
/// Most vertices of one polygon: checking that it does not cross itself compares every
/// pair of its edges.
pub const MAX_POLYGON_VERTICES: usize = 1_000;
/// Most robot spawns, and most opponent spawns (at least as many as a match may have agents
/// of a side; spawns wrap): each is checked against every wall.
pub const MAX_SPAWNS: usize = 64;
/// Most landmarks: a localising robot looks for every one of them each tick.
pub const MAX_LANDMARKS: usize = 256;

/// A map as given, before its rules are checked.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MapSpec {
    pub name: String,
    pub width: f64,
    pub height: f64,
    pub obstacles: Vec<Vec<[f64; 2]>>,
    /// `[x, y, heading]`.
    pub robot_spawns: Vec<[f64; 3]>,
    pub opponent_spawns: Vec<[f64; 2]>,
    pub landmarks: Vec<[f64; 2]>,
}

/// A map that breaks a rule: `path` names the field and index, `message` what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {message}")]
pub struct MapError {
    pub path: String,
    pub message: String,
}

/// The error at `path`.
pub fn err(path: impl Into<String>, message: impl Into<String>) -> MapError {
    MapError {
        path: path.into(),
        message: message.into(),
    }
}

/// Enforces every rule of the map format.
pub fn validate(m: &MapSpec) -> Result<MapDef, MapError> {
    let name_ok = !m.name.is_empty()
        && m.name.len() <= 64
        && m.name
            .bytes()
            .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-' || b == b'_');
    if !name_ok {
        return Err(err(
            "name",
            format!(
                "{:?} must be 1 to 64 characters of a-z 0-9 - _",
                m.name.chars().take(80).collect::<String>()
            ),
        ));
    }
    for (field, v) in [("width", m.width), ("height", m.height)] {
        if !v.is_finite() || v <= 0.0 || v > 500.0 {
            return Err(err(field, format!("{v} must be finite and in (0, 500]")));
        }
    }
    let (w, h) = (m.width, m.height);
    let inside = |p: [f64; 2]| p[0] >= 0.0 && p[0] <= w && p[1] >= 0.0 && p[1] <= h;
    let total: usize = m.obstacles.iter().map(Vec::len).sum();
    if total > MAX_VERTICES {
        return Err(err(
            "obstacles",
            format!("{total} vertices in all, the limit is {MAX_VERTICES}"),
        ));
    }
    for (field, n, max) in [
        ("robot_spawns", m.robot_spawns.len(), MAX_SPAWNS),
        ("opponent_spawns", m.opponent_spawns.len(), MAX_SPAWNS),
        ("landmarks", m.landmarks.len(), MAX_LANDMARKS),
    ] {
        if n > max {
            return Err(err(field, format!("{n} points, the limit is {max}")));
        }
    }
    for (i, poly) in m.obstacles.iter().enumerate() {
        if poly.len() > MAX_POLYGON_VERTICES {
            return Err(err(
                format!("obstacles[{i}]"),
                format!(
                    "polygon has {} vertices, the limit is {MAX_POLYGON_VERTICES}",
                    poly.len()
                ),
            ));
        }
        if poly.len() < 3 {
            return Err(err(
                format!("obstacles[{i}]"),
                format!("polygon has {} vertices, needs at least 3", poly.len()),
            ));
        }
        for (j, v) in poly.iter().enumerate() {
            if !v.iter().all(|c| c.is_finite()) || !inside(*v) {
                return Err(err(
                    format!("obstacles[{i}][{j}]"),
                    format!(
                        "vertex [{}, {}] lies outside the {w} x {h} arena",
                        v[0], v[1]
                    ),
                ));
            }
        }
        if let Some((a, b)) = self_intersection(poly) {
            return Err(err(
                format!("obstacles[{i}]"),
                format!("polygon intersects itself (edges {a} and {b})"),
            ));
        }
    }
    if m.robot_spawns.is_empty() {
        return Err(err("robot_spawns", "needs at least 1 spawn"));
    }
    if m.opponent_spawns.is_empty() {
        return Err(err("opponent_spawns", "needs at least 1 spawn"));
    }
    let obstacles: Vec<Vec<Point2<f32>>> = m
        .obstacles
        .iter()
        .map(|poly| {
            poly.iter()
                .map(|v| Point2::new(v[0] as f32, v[1] as f32))
                .collect()
        })
        .collect();
    let check_spawn = |field: String, p: [f64; 2]| -> Result<(), MapError> {
        if !p.iter().all(|c| c.is_finite()) || !inside(p) {
            return Err(err(
                field,
                format!("[{}, {}] lies outside the {w} x {h} arena", p[0], p[1]),
            ));
        }
        let r = AGENT_RADIUS as f64;
        if p[0] < r || p[1] < r || p[0] > w - r || p[1] > h - r {
            return Err(err(
                field,
                format!("[{}, {}] is closer than {r} m to the border", p[0], p[1]),
            ));
        }
        let pt = Point2::new(p[0] as f32, p[1] as f32);
        for (k, poly) in obstacles.iter().enumerate() {
            if point_in_polygon(pt, poly) {
                return Err(err(field, format!("lies inside obstacles[{k}]")));
            }
            if distance_to_polygon_edges(pt, poly) < AGENT_RADIUS - 1e-4 {
                return Err(err(
                    field,
                    format!("is closer than {r} m to obstacles[{k}]"),
                ));
            }
        }
        Ok(())
    };
    for (i, s) in m.robot_spawns.iter().enumerate() {
        if !s[2].is_finite() {
            return Err(err(
                format!("robot_spawns[{i}]"),
                "heading must be a finite number",
            ));
        }
        check_spawn(format!("robot_spawns[{i}]"), [s[0], s[1]])?;
    }
    for (i, s) in m.opponent_spawns.iter().enumerate() {
        check_spawn(format!("opponent_spawns[{i}]"), *s)?;
    }
    for (i, l) in m.landmarks.iter().enumerate() {
        if !l.iter().all(|c| c.is_finite()) || !inside(*l) {
            return Err(err(
                format!("landmarks[{i}]"),
                format!("[{}, {}] lies outside the {w} x {h} arena", l[0], l[1]),
            ));
        }
    }
    let p2 = |v: &[f64; 2]| Point2::new(v[0] as f32, v[1] as f32);
    Ok(MapDef {
        name: m.name.clone(),
        width: w as f32,
        height: h as f32,
        obstacles,
        robot_spawns: m
            .robot_spawns
            .iter()
            .map(|s| [s[0] as f32, s[1] as f32, s[2] as f32])
            .collect(),
        opponent_spawns: m.opponent_spawns.iter().map(p2).collect(),
        landmarks: m.landmarks.iter().map(p2).collect(),
    })
}

/// The JSON shape of a validated map (for `GET /api/maps/{name}`).
/// The first pair of edges that cross or touch (other than neighbours sharing a vertex).
fn self_intersection(poly: &[[f64; 2]]) -> Option<(usize, usize)> {
    let n = poly.len();
    let edge = |i: usize| (poly[i], poly[(i + 1) % n]);
    for i in 0..n {
        for j in i + 1..n {
            let adjacent = j == i + 1 || (i == 0 && j == n - 1);
            let (a, b) = edge(i);
            let (c, d) = edge(j);
            if adjacent {
                // Neighbours share one vertex; they intersect improperly only when they fold back
                // onto each other (collinear and overlapping).
                let shared_is_ab = j == i + 1;
                let (p, q, r) = if shared_is_ab { (a, b, d) } else { (b, a, c) };
                if cross(p, q, r).abs() < 1e-12 && dot(sub(p, q), sub(r, q)) > 0.0 {
                    return Some((i, j));
                }
                continue;
            }
            if segments_intersect(a, b, c, d) {
                return Some((i, j));
            }
        }
    }
    None
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// Cross product of (b - a) and (c - a).
fn cross(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

fn on_segment(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> bool {
    p[0] >= a[0].min(b[0])
        && p[0] <= a[0].max(b[0])
        && p[1] >= a[1].min(b[1])
        && p[1] <= a[1].max(b[1])
}

fn segments_intersect(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (d1, d2) = (cross(c, d, a), cross(c, d, b));
    let (d3, d4) = (cross(a, b, c), cross(a, b, d));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on_segment(c, d, a))
        || (d2 == 0.0 && on_segment(c, d, b))
        || (d3 == 0.0 && on_segment(a, b, c))
        || (d4 == 0.0 && on_segment(a, b, d))
}

fn distance_to_polygon_edges(p: Point2<f32>, poly: &[Point2<f32>]) -> f32 {
    let n = poly.len();
    (0..n)
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            let ab = b - a;
            let t = ((p - a).dot(&ab) / ab.norm_squared().max(1e-12)).clamp(0.0, 1.0);
            (a + ab * t - p).norm()
        })
        .fold(f32::INFINITY, f32::min)
}
