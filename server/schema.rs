//! Hand-written OpenAPI schemas for the fields whose Rust type says less than the API checks
//! (fixed-length coordinate arrays, bounded lists, a map given by name or inline), and
//! deserialisers for integers written as `5.0`.
//!
//! The schema is a contract that conformance tests (schemathesis) hold the server to: a body
//! the schema allows must not be refused for its shape, and one it forbids must be refused.
//! So every bound here is the same one the validators enforce (`protocol.rs`, `maps/`).

use serde::{Deserialize, Deserializer, de::Error as _};
use utoipa::openapi::schema::{
    ArrayBuilder, ObjectBuilder, OneOfBuilder, Schema, SchemaType, Type,
};
use utoipa::openapi::{RefOr, schema::Ref};

// The map format's limits: the core's rules enforce them and the OpenAPI schema states them.
pub use lasertag_core::sim::map_rules::{
    MAX_LANDMARKS, MAX_POLYGON_VERTICES, MAX_SPAWNS, MAX_VERTICES,
};

/// The largest coordinate a request may give (start positions, waypoints).
pub const MAX_COORDINATE: f64 = 1e6;

fn number(lo: f64, hi: f64) -> ObjectBuilder {
    ObjectBuilder::new()
        .schema_type(Type::Number)
        .minimum(Some(lo))
        .maximum(Some(hi))
}

/// `[x, y]` or `[x, y, heading]`: `n` numbers, each in `lo..=hi`.
fn tuple(n: usize, lo: f64, hi: f64) -> ArrayBuilder {
    ArrayBuilder::new()
        .items(number(lo, hi))
        .min_items(Some(n))
        .max_items(Some(n))
}

fn nullable_array() -> SchemaType {
    SchemaType::from_iter([Type::Array, Type::Null])
}

/// Explicit starts, `[x, y, heading]` (`n` 3) or `[x, y]` (`n` 2), at most `at_most` (the
/// most agents of that side a match may have: `protocol::bounds`).
pub fn starts(n: usize, at_most: usize, description: &str) -> RefOr<Schema> {
    ArrayBuilder::new()
        .schema_type(nullable_array())
        .items(tuple(n, -MAX_COORDINATE, MAX_COORDINATE))
        .max_items(Some(at_most))
        .description(Some(description))
        .into()
}

/// An opponent's new route: at most 1,000 points `[x, y]`.
pub fn waypoints() -> RefOr<Schema> {
    ArrayBuilder::new()
        .schema_type(nullable_array())
        .items(tuple(2, -MAX_COORDINATE, MAX_COORDINATE))
        .max_items(Some(1000))
        .description(Some(
            "Replaces the route: straight legs at top speed, stopping at the last point.",
        ))
        .into()
}

/// `seed`: any u64. No `format`: `int64` is signed, and tools bound it to `i64::MAX`.
pub fn seed() -> RefOr<Schema> {
    ObjectBuilder::new()
        .schema_type(SchemaType::from_iter([Type::Integer, Type::Null]))
        .minimum(Some(0u64))
        .maximum(Some(u64::MAX))
        .description(Some(
            "0..=18446744073709551615 (default 0): the same seed and inputs give the same match.",
        ))
        .into()
}

/// `seed` of a match summary: a u64, or null while it is secret.
pub fn seed_shown() -> RefOr<Schema> {
    ObjectBuilder::new()
        .schema_type(SchemaType::from_iter([Type::Integer, Type::Null]))
        .minimum(Some(0u64))
        .maximum(Some(u64::MAX))
        .description(Some(
            "The match's seed; null while a match people may join runs (only its owner and the operator see it then), shown to everyone once it has ended.",
        ))
        .into()
}

/// A map's name: what `maps::validate` allows.
pub const MAP_NAME_PATTERN: &str = "^[a-z0-9_-]{1,64}$";

/// `map` of `POST /api/matches`: a map's name, or a map object.
pub fn map_or_name() -> RefOr<Schema> {
    OneOfBuilder::new()
        .item(
            ObjectBuilder::new()
                .schema_type(Type::String)
                .pattern(Some(MAP_NAME_PATTERN))
                .description(Some("The name of a map the server has (404 otherwise).")),
        )
        .item(Ref::from_schema_name("MapFile"))
        .description(Some("A map name, or an inline map object."))
        .into()
}

/// Polygons of a map: at least 3 vertices each, inside the 500 m bound of any arena.
pub fn obstacles() -> RefOr<Schema> {
    ArrayBuilder::new()
        .items(
            ArrayBuilder::new()
                .items(tuple(2, 0.0, 500.0))
                .min_items(Some(3))
                .max_items(Some(MAX_POLYGON_VERTICES)),
        )
        .description(Some(
            "Polygons, each of 3 to 1000 vertices `[x, y]` inside the arena, not intersecting itself; 10000 vertices in all at most.",
        ))
        .into()
}

/// Spawns and landmarks `[x, y]` (`[x, y, heading]` for robots with `n` 3); `at_least` 1 for
/// spawns, 0 for landmarks.
fn map_points(n: usize, at_least: usize, at_most: usize, description: &str) -> RefOr<Schema> {
    let item = if n == 3 {
        // The heading may be any number, so the three share the loosest bound (`prefixItems`
        // could bound x and y apart, but tools that convert 3.1 schemas to older drafts
        // choke on it); the arena check covers x and y.
        ArrayBuilder::new()
            .items(ObjectBuilder::new().schema_type(Type::Number))
            .min_items(Some(3))
            .max_items(Some(3))
    } else {
        tuple(2, 0.0, 500.0)
    };
    ArrayBuilder::new()
        .items(item)
        .min_items(Some(at_least))
        .max_items(Some(at_most))
        .description(Some(description))
        .into()
}

pub fn robot_spawns() -> RefOr<Schema> {
    map_points(
        3,
        1,
        MAX_SPAWNS,
        "Robot spawns `[x, y, heading]`, 1 to 64, each inside the arena and at least 0.25 m from walls.",
    )
}

pub fn opponent_spawns() -> RefOr<Schema> {
    map_points(
        2,
        1,
        MAX_SPAWNS,
        "Opponent spawns `[x, y]`, 1 to 64, each inside the arena and at least 0.25 m from walls.",
    )
}

pub fn landmarks() -> RefOr<Schema> {
    map_points(
        2,
        0,
        MAX_LANDMARKS,
        "Landmarks `[x, y]` inside the arena, at most 256 (optional).",
    )
}

/// An integer JSON number, also when written with a fraction of zero (`5.0`): JSON Schema's
/// `integer` allows those, and the API says `integer`.
fn integer<E: serde::de::Error>(n: serde_json::Number) -> Result<i64, E> {
    if let Some(v) = n.as_i64() {
        return Ok(v);
    }
    match n.as_f64() {
        // In range: `i64::MAX as f64` is 2^63, itself not an i64.
        Some(f) if f.fract() == 0.0 && f.abs() < i64::MAX as f64 => Ok(f as i64),
        _ => Err(E::custom(format!(
            "invalid value: {n}, expected an integer"
        ))),
    }
}

pub fn opt_int<'de, D: Deserializer<'de>>(d: D) -> Result<Option<i64>, D::Error> {
    Option::<serde_json::Number>::deserialize(d)?
        .map(integer)
        .transpose()
}

pub fn int<'de, D: Deserializer<'de>>(d: D) -> Result<i64, D::Error> {
    integer(serde_json::Number::deserialize(d)?)
}

/// A seed: an integer in `0..=u64::MAX` (also written as `5.0`).
pub fn opt_seed<'de, D: Deserializer<'de>>(d: D) -> Result<Option<u64>, D::Error> {
    let Some(n) = Option::<serde_json::Number>::deserialize(d)? else {
        return Ok(None);
    };
    if let Some(v) = n.as_u64() {
        return Ok(Some(v));
    }
    match n.as_f64() {
        // `u64::MAX as f64` is 2^64, itself not a u64.
        Some(f) if f.fract() == 0.0 && (0.0..u64::MAX as f64).contains(&f) => Ok(Some(f as u64)),
        _ => Err(D::Error::custom(format!(
            "invalid value: {n}, expected an integer in 0..=18446744073709551615"
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Deserialize)]
    struct T {
        #[serde(default, deserialize_with = "opt_int")]
        a: Option<i64>,
        #[serde(default, deserialize_with = "opt_seed")]
        s: Option<u64>,
    }

    fn parse(text: &str) -> Result<T, String> {
        serde_json::from_str(text).map_err(|e| e.to_string())
    }

    #[test]
    fn integers_may_be_written_with_a_zero_fraction_only() {
        assert_eq!(parse(r#"{"a": 5.0}"#).unwrap().a, Some(5));
        assert_eq!(parse(r#"{"a": -3}"#).unwrap().a, Some(-3));
        assert_eq!(parse(r#"{"a": null}"#).unwrap().a, None);
        assert_eq!(parse(r#"{}"#).unwrap().a, None);
        assert!(
            parse(r#"{"a": 5.5}"#)
                .unwrap_err()
                .contains("expected an integer")
        );
        assert!(parse(r#"{"a": 1e300}"#).is_err());
        assert!(parse(r#"{"a": "5"}"#).is_err());
        assert_eq!(
            parse(r#"{"s": 18446744073709551615}"#).unwrap().s,
            Some(u64::MAX)
        );
        assert_eq!(parse(r#"{"s": 7.0}"#).unwrap().s, Some(7));
        assert!(parse(r#"{"s": -1}"#).is_err());
        assert!(parse(r#"{"s": 18446744073709551616}"#).is_err());
    }
}
