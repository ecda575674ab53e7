//! Our map format (`docs/map-format.md`): [`MapFile`] is the JSON shape; [`validate`]
//! enforces every rule of the spec and reports the first violation as a [`MapError`] naming
//! field and index, and turns the file into a [`MapDef`]. Every way into the server goes
//! through [`validate`], imported maps included.

use nalgebra::Point2;
use serde::{Deserialize, Serialize};

use lasertag_core::sim::arena::MapDef;
pub use lasertag_core::sim::map_rules::MapError;
use lasertag_core::sim::map_rules::{self, MapSpec, err};

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

/// Enforces every rule of the map format (`lasertag_core::sim::map_rules`).
pub fn validate(m: &MapFile) -> Result<MapDef, MapError> {
    map_rules::validate(&m.spec())
}

impl MapFile {
    /// The file's numbers as the core's rules read them.
    pub fn spec(&self) -> MapSpec {
        MapSpec {
            name: self.name.clone(),
            width: self.width,
            height: self.height,
            obstacles: self.obstacles.clone(),
            robot_spawns: self.robot_spawns.clone(),
            opponent_spawns: self.opponent_spawns.clone(),
            landmarks: self.landmarks.clone(),
        }
    }
}

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
