//! The bounds of the requests' top-level numbers (`robots`, `opponents`, `time_limit_s`,
//! `spectator_delay_s` of `POST /api/matches`; `ticks` of `step` and `act`), each declared
//! once in [`BOUNDS`]. Everything else comes from the declaration: the checks and their
//! error messages ([`Bound::integer`], [`Bound::number`]), the OpenAPI schema of each field
//! ([`Bound::schema`]), the `bounds` of `GET /api/rules`, and the table in docs/api.md
//! ([`markdown_table`], kept in step by a test).
//!
//! The nested settings groups (`tracker`, `radio`, …) declare their own fields in the core
//! (`lasertag_core::settings`); these are the request's own.

use lasertag_core::settings::{Kind, Range};
use utoipa::openapi::RefOr;
use utoipa::openapi::schema::{KnownFormat, ObjectBuilder, Schema, SchemaFormat, SchemaType, Type};

use super::refusal::{Invalid, invalid};

/// One bounded number of a request.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bound {
    /// The field's name in the request body.
    pub name: &'static str,
    /// `Integer` or `Number`.
    pub kind: Kind,
    pub range: Range,
    /// What a request that leaves the field out (or gives `null`) gets; `None` when the field
    /// is required.
    pub default: Option<f64>,
    /// What the field is, one sentence (the schema's description and the docs' table).
    pub doc: &'static str,
}

const fn closed(min: f64, max: f64) -> Range {
    Range {
        min,
        min_exclusive: false,
        max,
    }
}

/// `robots` of `POST /api/matches`.
pub const ROBOTS: Bound = Bound {
    name: "robots",
    kind: Kind::Integer,
    range: closed(1.0, 8.0),
    default: Some(2.0),
    doc: "Robots on the team.",
};

/// `opponents` of `POST /api/matches`.
pub const OPPONENTS: Bound = Bound {
    name: "opponents",
    kind: Kind::Integer,
    range: closed(1.0, 32.0),
    default: Some(1.0),
    doc: "Opponents the robots hunt.",
};

/// `pursuer_slots` of `POST /api/matches`.
pub const PURSUER_SLOTS: Bound = Bound {
    name: "pursuer_slots",
    kind: Kind::Integer,
    range: closed(0.0, 8.0),
    default: Some(0.0),
    doc: "The last this many robots are seats for people on the robot team (`POST /api/matches/{id}/players` with `team: robots`); at most `robots`.",
};

/// `time_limit_s` of `POST /api/matches`.
pub const TIME_LIMIT_S: Bound = Bound {
    name: "time_limit_s",
    kind: Kind::Number,
    range: Range {
        min: 0.0,
        min_exclusive: true,
        max: 86_400.0,
    },
    default: Some(300.0),
    doc: "Seconds of match time after which the opponents win.",
};

/// `spectator_delay_s` of `POST /api/matches`. Its maximum prices what a match holds back.
pub const SPECTATOR_DELAY_S: Bound = Bound {
    name: "spectator_delay_s",
    kind: Kind::Number,
    range: closed(0.0, 600.0),
    default: Some(30.0),
    doc: "Seconds the match's state, belief, events and spectator WebSocket run behind for \
          everyone but its owner when people may play it (human opponents, `bots_joinable`, \
          or `pursuer_slots`); ignored, and echoed as 0, when they may not.",
};

/// `ticks` of `POST /api/matches/{id}/step` (required there).
pub const STEP_TICKS: Bound = Bound {
    name: "ticks",
    kind: Kind::Integer,
    range: closed(1.0, 100_000.0),
    default: None,
    doc: "Ticks `step` advances the match by.",
};

/// `ticks` of `POST /api/matches/{id}/act`: the range of `step`'s, and a default.
pub const ACT_TICKS: Bound = Bound {
    default: Some(1.0),
    doc: "Ticks `act` advances the match by after applying the commands.",
    ..STEP_TICKS
};

/// Every bound, in the order of the docs' table.
pub const BOUNDS: [(&str, Bound); 7] = [
    ("POST /api/matches", ROBOTS),
    ("POST /api/matches", OPPONENTS),
    ("POST /api/matches", PURSUER_SLOTS),
    ("POST /api/matches", TIME_LIMIT_S),
    ("POST /api/matches", SPECTATOR_DELAY_S),
    ("POST /api/matches/{id}/step", STEP_TICKS),
    ("POST /api/matches/{id}/act", ACT_TICKS),
];

impl Bound {
    /// The default, for a bound that has one (0 for a required field, which never uses it).
    pub const fn default_value(&self) -> f64 {
        match self.default {
            Some(d) => d,
            None => 0.0,
        }
    }

    /// The largest integer allowed (for an integer bound).
    pub const fn max_integer(&self) -> i64 {
        self.range.max as i64
    }

    /// `value` (the default when `None`) if it is in range; otherwise an error naming the
    /// field (`robots: 9 must be in 1..=8`).
    pub fn integer(&self, value: Option<i64>) -> Result<i64, Invalid> {
        let v = value.unwrap_or(self.default_value() as i64);
        let (lo, hi) = (self.range.min as i64, self.range.max as i64);
        if self.contains(v as f64) {
            Ok(v)
        } else {
            Err(invalid(self.name, format!("{v} must be in {lo}..={hi}")))
        }
    }

    /// `value` (the default when `None`) if it is finite and in range; otherwise an error
    /// naming the field (`time_limit_s: 0 must be finite and in (0, 86400]`).
    pub fn number(&self, value: Option<f64>) -> Result<f64, Invalid> {
        let v = value.unwrap_or(self.default_value());
        if self.contains(v) {
            Ok(v)
        } else {
            Err(invalid(
                self.name,
                format!("{v} must be finite and in {}", self.range_text()),
            ))
        }
    }

    fn contains(&self, v: f64) -> bool {
        let r = self.range;
        v.is_finite()
            && (if r.min_exclusive {
                v > r.min
            } else {
                v >= r.min
            })
            && v <= r.max
    }

    /// The range as the error messages and docs write it: `1..=8`, `(0, 86400]`, `[0, 600]`.
    pub fn range_text(&self) -> String {
        let r = self.range;
        match self.kind {
            Kind::Integer => format!("{}..={}", r.min as i64, r.max as i64),
            _ => format!(
                "{}{}, {}]",
                if r.min_exclusive { "(" } else { "[" },
                r.min,
                r.max
            ),
        }
    }

    /// The default as the docs write it (`2`, `300`), or `required`.
    pub fn default_text(&self) -> String {
        match self.default {
            Some(d) => d.to_string(),
            None => "required".to_owned(),
        }
    }

    /// The field's OpenAPI schema: its type (and `null`, standing for the default, when
    /// `nullable`), range and description.
    pub fn schema(&self, nullable: bool) -> RefOr<Schema> {
        let (kind, format) = match self.kind {
            Kind::Integer => (Type::Integer, KnownFormat::Int64),
            _ => (Type::Number, KnownFormat::Double),
        };
        let schema_type = if nullable {
            SchemaType::from_iter([kind, Type::Null])
        } else {
            SchemaType::new(kind)
        };
        let description = match self.default {
            Some(_) => format!(
                "{} Range {}, default {}.",
                self.doc,
                self.range_text(),
                self.default_text()
            ),
            None => format!("{} Range {}.", self.doc, self.range_text()),
        };
        let object = ObjectBuilder::new()
            .schema_type(schema_type)
            .format(Some(SchemaFormat::KnownFormat(format)))
            .maximum(Some(self.range.max))
            .description(Some(description));
        let object = if self.range.min_exclusive {
            object.exclusive_minimum(Some(self.range.min))
        } else {
            object.minimum(Some(self.range.min))
        };
        object.into()
    }
}

/// `schema_with` functions (utoipa's attribute takes a plain function path). The fields of
/// `POST /api/matches` take `null` for the default; `ticks` takes only numbers.
pub fn robots_schema() -> RefOr<Schema> {
    ROBOTS.schema(true)
}

pub fn opponents_schema() -> RefOr<Schema> {
    OPPONENTS.schema(true)
}

pub fn pursuer_slots_schema() -> RefOr<Schema> {
    PURSUER_SLOTS.schema(true)
}

pub fn time_limit_s_schema() -> RefOr<Schema> {
    TIME_LIMIT_S.schema(true)
}

pub fn spectator_delay_s_schema() -> RefOr<Schema> {
    SPECTATOR_DELAY_S.schema(true)
}

pub fn step_ticks_schema() -> RefOr<Schema> {
    STEP_TICKS.schema(false)
}

pub fn act_ticks_schema() -> RefOr<Schema> {
    ACT_TICKS.schema(false)
}

/// `robot_starts`: one per robot, so at most [`ROBOTS`]' maximum.
pub fn robot_starts_schema() -> RefOr<Schema> {
    crate::schema::starts(
        3,
        ROBOTS.max_integer() as usize,
        "Explicit robot starts `[x, y, heading]`, one per robot (the count must equal `robots`, each inside the arena and clear of walls).",
    )
}

/// `opponent_starts`: one per opponent, so at most [`OPPONENTS`]' maximum.
pub fn opponent_starts_schema() -> RefOr<Schema> {
    crate::schema::starts(
        2,
        OPPONENTS.max_integer() as usize,
        "Explicit opponent starts `[x, y]`, one per opponent (the count must equal `opponents`, each inside the arena and clear of walls).",
    )
}

/// The marker lines between which docs/api.md holds [`markdown_table`].
pub const GENERATED_BEGIN: &str = "<!-- Generated from server/protocol/bounds.rs by its tests: do not edit until the end marker. -->";
pub const GENERATED_END: &str = "<!-- End of the generated bounds. -->";

/// The table of every bound, as docs/api.md shows it.
pub fn markdown_table() -> String {
    let mut out = String::from(
        "| request | field | type | range | default | what it is |\n|---|---|---|---|---|---|\n",
    );
    for (request, b) in BOUNDS {
        let kind = match b.kind {
            Kind::Integer => "integer",
            _ => "number",
        };
        out.push_str(&format!(
            "| `{request}` | `{}` | {kind} | {} | {} | {} |\n",
            b.name,
            b.range_text(),
            b.default_text(),
            b.doc
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checks_name_the_field_and_say_the_range() {
        assert_eq!(ROBOTS.integer(None), Ok(2));
        assert_eq!(
            ROBOTS.integer(Some(9)).unwrap_err().to_string(),
            "robots: 9 must be in 1..=8"
        );
        assert_eq!(
            TIME_LIMIT_S.number(Some(0.0)).unwrap_err().to_string(),
            "time_limit_s: 0 must be finite and in (0, 86400]"
        );
        assert_eq!(SPECTATOR_DELAY_S.number(Some(0.0)), Ok(0.0));
        assert!(SPECTATOR_DELAY_S.number(Some(f64::NAN)).is_err());
        assert_eq!(ACT_TICKS.integer(None), Ok(1));
        assert_eq!(
            STEP_TICKS.integer(Some(0)).unwrap_err().to_string(),
            "ticks: 0 must be in 1..=100000"
        );
    }

    #[test]
    fn schemas_state_the_declared_range() {
        let s = serde_json::to_value(TIME_LIMIT_S.schema(true)).unwrap();
        assert_eq!(s["exclusiveMinimum"], 0.0);
        assert_eq!(s["maximum"], 86_400.0);
        assert_eq!(s["type"], serde_json::json!(["number", "null"]));
        let s = serde_json::to_value(STEP_TICKS.schema(false)).unwrap();
        assert_eq!(
            (s["minimum"].as_f64(), s["maximum"].as_f64()),
            (Some(1.0), Some(1e5))
        );
        assert_eq!(s["type"], "integer");
    }

    /// docs/api.md holds the table between its markers; when it differs from the
    /// declarations, this test writes the new one in (commit it) and fails.
    #[test]
    fn the_docs_table_is_the_declaration() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/api.md");
        let docs = std::fs::read_to_string(&path).expect("docs/api.md is readable");
        let (Some(begin), Some(end)) = (docs.find(GENERATED_BEGIN), docs.find(GENERATED_END))
        else {
            panic!("docs/api.md has the bounds markers");
        };
        let want = format!(
            "{}{GENERATED_BEGIN}\n\n{}\n{}",
            &docs[..begin],
            markdown_table(),
            &docs[end..]
        );
        if docs != want {
            std::fs::write(&path, &want).expect("docs/api.md is writable");
            panic!("docs/api.md's bounds were out of date and have been regenerated: commit it");
        }
    }
}
