//! Our map format (`docs/map-format.md`): [`MapFile`] is the JSON shape; [`validate`]
//! enforces every rule of the spec and reports the first violation as a [`MapError`] naming
//! field and index, and turns the file into a [`MapDef`]. Every way into the server goes
//! through [`validate`], imported maps included.

use nalgebra::Point2;
use serde::{Deserialize, Serialize};

use lasertag_core::sim::AGENT_RADIUS;
use lasertag_core::sim::arena::{MapDef, point_in_polygon};

use crate::schema::{MAX_LANDMARKS, MAX_POLYGON_VERTICES, MAX_SPAWNS, MAX_VERTICES};

/// Largest map file or inline map accepted.
pub const MAX_MAP_BYTES: usize = 1 << 20;

/// The JSON object of a map, as in files and API bodies.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MapFile {
    /// 1 to 64 characters of a-z 0-9 - _ (a map file is `<name>.json`).
    #[schema(pattern = "^[a-z0-9_-]{1,64}$")]
    pub name: String,
    /// Metres, in (0, 500].
    #[schema(exclusive_minimum = 0.0, maximum = 500.0)]
    pub width: f64,
    /// Metres, in (0, 500].
    #[schema(exclusive_minimum = 0.0, maximum = 500.0)]
    pub height: f64,
    #[schema(schema_with = crate::schema::obstacles)]
    pub obstacles: Vec<Vec<[f64; 2]>>,
    #[schema(schema_with = crate::schema::robot_spawns)]
    pub robot_spawns: Vec<[f64; 3]>,
    #[schema(schema_with = crate::schema::opponent_spawns)]
    pub opponent_spawns: Vec<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    #[schema(schema_with = crate::schema::landmarks)]
    pub landmarks: Vec<[f64; 2]>,
}

/// A map that breaks a rule: `path` names the field and index, `message` what is wrong.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{path}: {message}")]
pub struct MapError {
    pub path: String,
    pub message: String,
}

fn err(path: impl Into<String>, message: impl Into<String>) -> MapError {
    MapError {
        path: path.into(),
        message: message.into(),
    }
}

/// Parses map JSON text (size-checked) into a validated definition.
pub fn parse(text: &str) -> Result<MapDef, MapError> {
    if text.len() > MAX_MAP_BYTES {
        return Err(err(
            "map",
            format!("{} bytes, the limit is {MAX_MAP_BYTES}", text.len()),
        ));
    }
    let de = &mut serde_json::Deserializer::from_str(text);
    let file: MapFile = serde_path_to_error::deserialize(de).map_err(json_error)?;
    validate(&file)
}

/// Converts an already-parsed JSON value (an inline map in a request) into a validated definition.
pub fn from_value(value: serde_json::Value) -> Result<MapDef, MapError> {
    let file: MapFile = serde_path_to_error::deserialize(value).map_err(json_error)?;
    validate(&file)
}

fn json_error(e: serde_path_to_error::Error<serde_json::Error>) -> MapError {
    let path = e.path().to_string();
    let path = if path == "." { "map".to_string() } else { path };
    err(path, e.into_inner().to_string())
}

/// Enforces every rule of the map format.
pub fn validate(m: &MapFile) -> Result<MapDef, MapError> {
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
pub fn to_file(def: &MapDef) -> MapFile {
    let p = |v: &Point2<f32>| [v.x as f64, v.y as f64];
    MapFile {
        name: def.name.clone(),
        width: def.width as f64,
        height: def.height as f64,
        obstacles: def
            .obstacles
            .iter()
            .map(|poly| poly.iter().map(p).collect())
            .collect(),
        robot_spawns: def
            .robot_spawns
            .iter()
            .map(|s| [s[0] as f64, s[1] as f64, s[2] as f64])
            .collect(),
        opponent_spawns: def.opponent_spawns.iter().map(p).collect(),
        landmarks: def.landmarks.iter().map(p).collect(),
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn good() -> serde_json::Value {
        json!({
            "name": "t", "width": 10.0, "height": 6.0,
            "obstacles": [[[4.0, 2.0], [6.0, 2.0], [6.0, 4.0], [4.0, 4.0]]],
            "robot_spawns": [[1.0, 1.0, 0.0]],
            "opponent_spawns": [[9.0, 5.0]],
            "landmarks": [[5.0, 5.0]]
        })
    }

    fn message(v: serde_json::Value) -> String {
        from_value(v).unwrap_err().to_string()
    }

    #[test]
    fn a_good_map_passes_and_round_trips() {
        let def = from_value(good()).unwrap();
        assert_eq!(def.obstacles.len(), 1);
        let back = serde_json::to_value(to_file(&def)).unwrap();
        assert_eq!(back, good());
    }

    #[test]
    fn every_rule_names_field_and_index() {
        type Mutation = Box<dyn Fn(&mut serde_json::Value)>;
        let cases: Vec<(Mutation, &str)> = vec![
            (Box::new(|m| m["name"] = json!("Bad Name")), "name:"),
            (Box::new(|m| m["name"] = json!("")), "name:"),
            (Box::new(|m| m["width"] = json!(0.0)), "width:"),
            (Box::new(|m| m["height"] = json!(501.0)), "height:"),
            (
                Box::new(|m| m["width"] = json!("wide")),
                "width: invalid type",
            ),
            (
                Box::new(|m| m["obstacles"][0] = json!([[1.0, 1.0], [2.0, 2.0]])),
                "obstacles[0]: polygon has 2 vertices, needs at least 3",
            ),
            (
                Box::new(|m| m["obstacles"][0][2] = json!([60.0, 4.0])),
                "obstacles[0][2]: vertex",
            ),
            (
                Box::new(|m| {
                    m["obstacles"][0] = json!([[4.0, 2.0], [6.0, 4.0], [6.0, 2.0], [4.0, 4.0]])
                }),
                "obstacles[0]: polygon intersects itself",
            ),
            (
                Box::new(|m| m["obstacles"][0] = json!([[4.0, 2.0], [5.0, 2.0], [6.0, 2.0]])),
                "obstacles[0]: polygon intersects itself", // collinear: its edges overlap
            ),
            (Box::new(|m| m["robot_spawns"] = json!([])), "robot_spawns:"),
            (
                Box::new(|m| m["opponent_spawns"] = json!([])),
                "opponent_spawns:",
            ),
            (
                Box::new(|m| m["robot_spawns"][0] = json!([5.0, 3.0, 0.0])),
                "robot_spawns[0]: lies inside obstacles[0]",
            ),
            (
                Box::new(|m| m["opponent_spawns"][0] = json!([3.9, 3.0])),
                "opponent_spawns[0]: is closer than 0.25 m to obstacles[0]",
            ),
            (
                Box::new(|m| m["opponent_spawns"][0] = json!([9.9, 3.0])),
                "opponent_spawns[0]: [9.9, 3] is closer than 0.25 m to the border",
            ),
            (
                Box::new(|m| m["opponent_spawns"][0] = json!([11.0, 3.0])),
                "opponent_spawns[0]: [11, 3] lies outside",
            ),
            (
                Box::new(|m| m["landmarks"][0] = json!([-1.0, 3.0])),
                "landmarks[0]:",
            ),
            (
                Box::new(|m| m["robot_spawns"][0] = json!([1.0, 1.0])),
                "robot_spawns[0]: invalid length 2",
            ),
            (
                Box::new(|m| m["colour"] = json!("red")),
                "unknown field `colour`",
            ),
            (
                Box::new(|m| {
                    m.as_object_mut()
                        .unwrap()
                        .remove("obstacles")
                        .map(|_| ())
                        .unwrap()
                }),
                "missing field `obstacles`",
            ),
        ];
        for (i, (mutate, expected)) in cases.iter().enumerate() {
            let mut m = good();
            mutate(&mut m);
            let msg = message(m);
            assert!(
                msg.contains(expected),
                "case {i}: {msg:?} lacks {expected:?}"
            );
        }
    }

    #[test]
    fn too_many_vertices_and_too_many_bytes_are_refused() {
        let mut m = good();
        let ring: Vec<_> = (0..10_001)
            .map(|k| {
                let a = k as f64 / 10_001.0 * std::f64::consts::TAU;
                [5.0 + 0.5 * a.cos(), 3.0 + 0.5 * a.sin()]
            })
            .collect();
        m["obstacles"] = json!([ring]);
        assert!(message(m).starts_with("obstacles: 10001 vertices"));
        let big = " ".repeat(MAX_MAP_BYTES + 1);
        assert!(parse(&big).unwrap_err().to_string().starts_with("map:"));
    }

    #[test]
    fn malformed_json_is_an_error_not_a_panic() {
        assert!(parse("{\"name\": ").is_err());
        assert!(parse("{\"name\": \"x\", \"width\": NaN}").is_err());
        assert!(parse("{\"name\": \"x\", \"width\": 1e999}").is_err());
    }
}
