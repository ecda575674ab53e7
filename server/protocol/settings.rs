//! Settings groups on the wire, all from their one declaration in the core
//! ([`lasertag_core::settings`]): a request's object ([`Overrides`]: only declared fields, each
//! of its declared kind, `null` for the default), the echo a summary shows ([`Echo`]: every
//! field, numbers as they were asked), their OpenAPI schemas (the declared ranges and docs),
//! and the Markdown table of docs/settings.md.

use std::fmt;
use std::marker::PhantomData;

use lasertag_core::settings::{FieldError, Group, Kind, Value};
use serde::de::{self, DeserializeSeed, MapAccess, Unexpected, Visitor};
use serde::ser::SerializeMap;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use utoipa::openapi::RefOr;
use utoipa::openapi::schema::{AdditionalProperties, ObjectBuilder, Schema, SchemaType, Type};

/// A settings group as a request gives it: the fields it names, in order.
#[derive(Debug, Clone, PartialEq)]
pub struct Overrides<G> {
    fields: Vec<(&'static str, Value)>,
    group: PhantomData<G>,
}

impl<G> Default for Overrides<G> {
    fn default() -> Self {
        Overrides {
            fields: Vec::new(),
            group: PhantomData,
        }
    }
}

impl<G: Group> Overrides<G> {
    /// `base` with these fields set; an error names the field as `group.field`.
    pub fn apply(&self, mut base: G) -> Result<G, FieldError> {
        for (name, value) in &self.fields {
            base.set(name, *value).map_err(|e| e.within(G::NAME))?;
        }
        Ok(base)
    }
}

impl<'de, G: Group> Deserialize<'de> for Overrides<G> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_map(OverridesVisitor::<G>(PhantomData))
    }
}

struct OverridesVisitor<G>(PhantomData<G>);

impl<'de, G: Group> Visitor<'de> for OverridesVisitor<G> {
    type Value = Overrides<G>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        write!(f, "a `{}` object", G::NAME)
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Overrides<G>, A::Error> {
        let mut out = Overrides::default();
        while let Some(key) = map.next_key::<String>()? {
            let Some(field) = G::field(&key) else {
                let known: Vec<_> = G::FIELDS.iter().map(|f| format!("`{}`", f.name)).collect();
                return Err(de::Error::custom(format_args!(
                    "unknown field `{key}`, expected one of {}",
                    known.join(", ")
                )));
            };
            if out.fields.iter().any(|(name, _)| *name == field.name) {
                return Err(de::Error::custom(format_args!("duplicate field `{key}`")));
            }
            // Through a seed, so that a wrong type is reported at `group.field`.
            if let Some(value) = map.next_value_seed(KindSeed(field.kind))? {
                out.fields.push((field.name, value));
            }
        }
        Ok(out)
    }
}

/// Reads one field's value of `Kind`; `null` is `None` (the default). An integer may be
/// written `5.0`, as JSON tools often do.
struct KindSeed(Kind);

impl<'de> DeserializeSeed<'de> for KindSeed {
    type Value = Option<Value>;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Option<Value>, D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for KindSeed {
    type Value = Option<Value>;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str(match self.0 {
            Kind::Integer => "an integer",
            Kind::Number => "a number",
            Kind::Bool => "a boolean",
        })
    }

    fn visit_unit<E: de::Error>(self) -> Result<Option<Value>, E> {
        Ok(None)
    }

    fn visit_none<E: de::Error>(self) -> Result<Option<Value>, E> {
        Ok(None)
    }

    fn visit_bool<E: de::Error>(self, b: bool) -> Result<Option<Value>, E> {
        match self.0 {
            Kind::Bool => Ok(Some(Value::Bool(b))),
            _ => Err(E::invalid_type(Unexpected::Bool(b), &self)),
        }
    }

    fn visit_i64<E: de::Error>(self, i: i64) -> Result<Option<Value>, E> {
        match self.0 {
            Kind::Integer => Ok(Some(Value::Integer(i))),
            Kind::Number => Ok(Some(Value::Number(i as f64))),
            Kind::Bool => Err(E::invalid_type(Unexpected::Signed(i), &self)),
        }
    }

    fn visit_u64<E: de::Error>(self, u: u64) -> Result<Option<Value>, E> {
        match (self.0, i64::try_from(u)) {
            (Kind::Integer, Ok(i)) => Ok(Some(Value::Integer(i))),
            (Kind::Integer, Err(_)) => Err(E::invalid_value(Unexpected::Unsigned(u), &self)),
            (Kind::Number, _) => Ok(Some(Value::Number(u as f64))),
            (Kind::Bool, _) => Err(E::invalid_type(Unexpected::Unsigned(u), &self)),
        }
    }

    fn visit_f64<E: de::Error>(self, x: f64) -> Result<Option<Value>, E> {
        match self.0 {
            Kind::Number => Ok(Some(Value::Number(x))),
            Kind::Integer if x.fract() == 0.0 && x.abs() < 9.0e15 => {
                Ok(Some(Value::Integer(x as i64)))
            }
            _ => Err(E::invalid_type(Unexpected::Float(x), &self)),
        }
    }

    fn visit_str<E: de::Error>(self, s: &str) -> Result<Option<Value>, E> {
        Err(E::invalid_type(Unexpected::Str(s), &self))
    }

    fn visit_seq<A: de::SeqAccess<'de>>(self, _: A) -> Result<Option<Value>, A::Error> {
        Err(de::Error::invalid_type(Unexpected::Seq, &self))
    }

    fn visit_map<A: MapAccess<'de>>(self, _: A) -> Result<Option<Value>, A::Error> {
        Err(de::Error::invalid_type(Unexpected::Map, &self))
    }
}

/// The settings a match runs with, every field, as summaries show them.
#[derive(Debug, Clone, PartialEq)]
pub struct Echo<G>(pub G);

impl<G: Group> Serialize for Echo<G> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(G::FIELDS.len()))?;
        for field in G::FIELDS {
            match self.0.get(field.name) {
                Some(Value::Integer(i)) => map.serialize_entry(field.name, &i)?,
                Some(Value::Number(x)) => map.serialize_entry(field.name, &x)?,
                Some(Value::Bool(b)) => map.serialize_entry(field.name, &b)?,
                None => {}
            }
        }
        map.end()
    }
}

fn field_type(kind: Kind) -> Type {
    match kind {
        Kind::Integer => Type::Integer,
        Kind::Number => Type::Number,
        Kind::Bool => Type::Boolean,
    }
}

/// What a request may give for group `G`: each declared field, `null` or in its range.
pub fn request_schema<G: Group>() -> RefOr<Schema> {
    let mut object = ObjectBuilder::new()
        .schema_type(SchemaType::from_iter([Type::Object, Type::Null]))
        .additional_properties(Some(AdditionalProperties::FreeForm(false)));
    for f in G::FIELDS {
        let mut field = ObjectBuilder::new()
            .schema_type(SchemaType::from_iter([field_type(f.kind), Type::Null]))
            .description(Some(format!(
                "{} (default {}).",
                f.description(),
                default_text::<G>(f.name)
            )));
        if let Some(r) = f.range {
            field = field.maximum(Some(r.max));
            field = if r.min_exclusive {
                field.exclusive_minimum(Some(r.min))
            } else {
                field.minimum(Some(r.min))
            };
        }
        object = object.property(f.name, field);
    }
    object.into()
}

/// What a summary echoes for group `G`: every declared field, defaults filled in.
pub fn echo_schema<G: Group>() -> RefOr<Schema> {
    let mut object = ObjectBuilder::new().schema_type(Type::Object);
    for f in G::FIELDS {
        object = object
            .property(
                f.name,
                ObjectBuilder::new()
                    .schema_type(field_type(f.kind))
                    .description(Some(f.description())),
            )
            .required(f.name);
    }
    object.into()
}

fn value_text(v: Value) -> String {
    match v {
        Value::Integer(i) => i.to_string(),
        Value::Number(x) => x.to_string(),
        Value::Bool(b) => b.to_string(),
    }
}

fn default_text<G: Group>(name: &str) -> String {
    G::default().get(name).map(value_text).unwrap_or_default()
}

/// The Markdown table of group `G` (docs/settings.md): field, type, default, range, doc.
pub fn markdown_table<G: Group>() -> String {
    let mut out = format!(
        "### `{}`\n\n| field | type | default | range | what it does |\n|---|---|---|---|---|\n",
        G::NAME
    );
    for f in G::FIELDS {
        let kind = match f.kind {
            Kind::Integer => "integer",
            Kind::Number => "number",
            Kind::Bool => "boolean",
        };
        let range = match f.range {
            None => String::new(),
            Some(r) if f.kind == Kind::Integer => format!("{}..={}", r.min as i64, r.max as i64),
            Some(r) => format!(
                "{}{}, {}]",
                if r.min_exclusive { "(" } else { "[" },
                r.min,
                r.max
            ),
        };
        out.push_str(&format!(
            "| `{}` | {kind} | {} | {range} | {} |\n",
            f.name,
            default_text::<G>(f.name),
            f.description()
        ));
    }
    out
}

/// The line after which docs/settings.md is generated.
pub const GENERATED: &str =
    "<!-- Generated from the declarations by server/protocol/settings.rs: do not edit below. -->";

/// Every group's table, as docs/settings.md holds them (a test keeps the file in step).
pub fn markdown_tables() -> String {
    use lasertag_core::{localise, planner::coordinated, radio, sim, tracker};
    [
        markdown_table::<tracker::Settings>(),
        markdown_table::<coordinated::Settings>(),
        markdown_table::<radio::Settings>(),
        markdown_table::<sim::Odometry>(),
        markdown_table::<localise::Settings>(),
    ]
    .join("\n")
}

/// `schema_with` functions for the request and echo of each group (utoipa's attribute takes
/// a plain function path).
macro_rules! group_schemas {
    ($($request:ident, $echo:ident: $group:ty;)*) => {$(
        pub fn $request() -> RefOr<Schema> {
            request_schema::<$group>()
        }
        pub fn $echo() -> RefOr<Schema> {
            echo_schema::<$group>()
        }
    )*};
}

group_schemas! {
    tracker_request, tracker_echo: lasertag_core::tracker::Settings;
    coordination_request, coordination_echo: lasertag_core::planner::coordinated::Settings;
    radio_request, radio_echo: lasertag_core::radio::Settings;
    odometry_request, odometry_echo: lasertag_core::sim::Odometry;
    localiser_request, localiser_echo: lasertag_core::localise::Settings;
}

#[cfg(test)]
mod tests {
    use super::*;
    use lasertag_core::tracker::Settings as Tracker;

    fn parse(json: &str) -> Result<Overrides<Tracker>, String> {
        let d = &mut serde_json::Deserializer::from_str(json);
        serde_path_to_error::deserialize(d).map_err(|e| format!("{}: {}", e.path(), e.inner()))
    }

    #[test]
    fn a_request_sets_only_what_it_names() {
        let o = parse(r#"{"kl_cutoff": 0.5, "particles_per_role": 200.0, "merge": null}"#).unwrap();
        let t = o.apply(Tracker::default()).unwrap();
        assert_eq!(
            (t.kl_cutoff, t.particles_per_role, t.merge),
            (0.5, 200, true)
        );
    }

    #[test]
    fn wrong_fields_and_types_are_named() {
        let e = parse(r#"{"kl": 1}"#).unwrap_err();
        assert!(
            e.contains("unknown field `kl`") && e.contains("`kl_cutoff`"),
            "{e}"
        );
        let e = parse(r#"{"merge": 1}"#).unwrap_err();
        assert!(e.starts_with("merge: invalid type"), "{e}");
        let e = parse(r#"{"particles_per_role": 2.5}"#).unwrap_err();
        assert!(e.starts_with("particles_per_role: invalid type"), "{e}");
        let o = parse(r#"{"grid_cell": 0.01}"#).unwrap();
        let e = o.apply(Tracker::default()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "tracker.grid_cell: 0.01 must be finite and in [0.1, 10]"
        );
    }

    #[test]
    fn echoes_show_numbers_as_asked() {
        let json = serde_json::to_string(&Echo(Tracker::default())).unwrap();
        assert_eq!(
            json,
            r#"{"particles_per_role":1000,"merge":true,"merge_interval":20,"kl_cutoff":0.7,"grid_cell":1.0}"#
        );
    }

    /// docs/settings.md ends with the generated tables; when they differ from the
    /// declarations, this test writes the new ones in (commit them) and fails.
    #[test]
    fn the_docs_table_is_the_declaration() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/settings.md");
        let docs = std::fs::read_to_string(&path).unwrap_or_default();
        let head = match docs.find(GENERATED) {
            Some(at) => &docs[..at],
            None => &docs[..],
        };
        let want = format!("{head}{GENERATED}\n\n{}", markdown_tables());
        if docs != want {
            std::fs::write(&path, &want).expect("docs/settings.md is writable");
            panic!("docs/settings.md was out of date and has been regenerated: commit it");
        }
    }
}
