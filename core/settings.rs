//! Settings defined once. A settings group (the tracker's, the planner's weights, the radio,
//! the odometry noise, the localiser) is declared with [`settings!`](crate::settings!): each
//! field's name, type, default, range and doc, in one place. Everything else comes from that
//! declaration: the struct and its `Default`, checked setting by name ([`Group::set`], which
//! the API's request bodies and the experiments' `--set` both go through), the value a match
//! runs with by name ([`Group::get`], the API's echoes), and the table of fields
//! ([`Group::FIELDS`], from which the server writes the OpenAPI bounds and the docs table).
//!
//! Errors are typed ([`FieldError`]: the field's path and what is wrong); the API and the
//! command line each put their own prefix in front.

use thiserror::Error;

/// What a field holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Integer,
    Number,
    Bool,
}

/// A field's value, as requests give it and echoes show it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    Integer(i64),
    Number(f64),
    Bool(bool),
}

/// The values a number or integer field accepts: `[min, max]`, or `(min, max]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    pub min: f64,
    pub min_exclusive: bool,
    pub max: f64,
}

impl Range {
    fn contains(&self, x: f64) -> bool {
        x.is_finite()
            && (if self.min_exclusive {
                x > self.min
            } else {
                x >= self.min
            })
            && x <= self.max
    }
}

/// One declared field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Field {
    pub name: &'static str,
    /// The declaration's doc comment, one line per `///` line (leading spaces kept).
    pub doc: &'static str,
    pub kind: Kind,
    /// `None` for booleans.
    pub range: Option<Range>,
}

impl Field {
    /// The doc comment as one line of prose.
    pub fn description(&self) -> String {
        self.doc.split_whitespace().collect::<Vec<_>>().join(" ")
    }
}

/// A setting that was refused: which field (a path such as `tracker.kl_cutoff`) and why.
#[derive(Debug, Clone, PartialEq, Error)]
#[error("{field}: {message}")]
pub struct FieldError {
    pub field: String,
    pub message: String,
}

impl FieldError {
    /// The same error with `prefix.` in front of the field's path.
    pub fn within(self, prefix: &str) -> FieldError {
        FieldError {
            field: format!("{prefix}.{}", self.field),
            message: self.message,
        }
    }
}

/// A settings group: what [`settings!`](crate::settings!) implements for each declaration.
pub trait Group: Default + Clone {
    /// The group's name in requests and echoes (`tracker`, `coordination`, …).
    const NAME: &'static str;
    /// Its declared fields, in order.
    const FIELDS: &'static [Field];

    /// The value of field `name`, or `None` when there is no such field.
    fn get(&self, name: &str) -> Option<Value>;

    /// Sets field `name` to `value` after checking its kind and range.
    fn set(&mut self, name: &str, value: Value) -> Result<(), FieldError>;

    /// The declared field `name`.
    fn field(name: &str) -> Option<&'static Field> {
        Self::FIELDS.iter().find(|f| f.name == name)
    }

    /// Sets field `name` from text, as a command line gives it (`travel_weight=0.02`).
    fn set_text(&mut self, name: &str, text: &str) -> Result<(), FieldError> {
        let field = Self::field(name).ok_or_else(|| unknown::<Self>(name))?;
        let refuse = |what: &str| FieldError {
            field: name.to_string(),
            message: format!("{text:?} is not {what}"),
        };
        let value = match field.kind {
            Kind::Integer => Value::Integer(text.trim().parse().map_err(|_| refuse("an integer"))?),
            Kind::Number => Value::Number(text.trim().parse().map_err(|_| refuse("a number"))?),
            Kind::Bool => Value::Bool(text.trim().parse().map_err(|_| refuse("true or false"))?),
        };
        self.set(name, value)
    }
}

/// The error for a field the group does not declare.
pub fn unknown<G: Group>(name: &str) -> FieldError {
    let known: Vec<_> = G::FIELDS.iter().map(|f| f.name).collect();
    FieldError {
        field: name.to_string(),
        message: format!("unknown setting (known: {})", known.join(", ")),
    }
}

/// A Rust type a field may have, and how its values are checked and shown.
pub trait FieldType: Copy {
    const KIND: Kind;
    fn to_value(self) -> Value;
    /// `value` as this type, if it is of the right kind and within `range`; otherwise what
    /// is wrong with it.
    fn from_value(value: Value, range: Option<Range>) -> Result<Self, String>;
}

fn number_in(value: Value, range: Option<Range>) -> Result<f64, String> {
    let x = match value {
        Value::Number(x) => x,
        Value::Integer(i) => i as f64,
        Value::Bool(_) => return Err("must be a number".into()),
    };
    match range {
        Some(r) if !r.contains(x) => {
            let open = if r.min_exclusive { "(" } else { "[" };
            Err(format!(
                "{x} must be finite and in {open}{}, {}]",
                r.min, r.max
            ))
        }
        _ => Ok(x),
    }
}

fn integer_in(value: Value, range: Option<Range>) -> Result<i64, String> {
    let i = match value {
        Value::Integer(i) => i,
        Value::Number(x) if x.fract() == 0.0 && x.abs() < 9.0e15 => x as i64,
        _ => return Err("must be an integer".into()),
    };
    match range {
        Some(r) if !r.contains(i as f64) => Err(format!(
            "{i} must be in {}..={}",
            r.min as i64, r.max as i64
        )),
        _ => Ok(i),
    }
}

impl FieldType for f32 {
    const KIND: Kind = Kind::Number;
    /// The shortest decimal that reads back as this `f32`, as an `f64`: a setting asked as
    /// 0.7 is echoed as 0.7, not as 0.699999988079071.
    fn to_value(self) -> Value {
        Value::Number(self.to_string().parse().unwrap_or(self as f64))
    }
    fn from_value(value: Value, range: Option<Range>) -> Result<f32, String> {
        number_in(value, range).map(|x| x as f32)
    }
}

macro_rules! integer_field_type {
    ($($t:ty),*) => {$(
        impl FieldType for $t {
            const KIND: Kind = Kind::Integer;
            fn to_value(self) -> Value {
                Value::Integer(self as i64)
            }
            fn from_value(value: Value, range: Option<Range>) -> Result<$t, String> {
                let i = integer_in(value, range)?;
                <$t>::try_from(i).map_err(|_| format!("{i} is out of range"))
            }
        }
    )*};
}
integer_field_type!(u32, u64, usize);

impl FieldType for bool {
    const KIND: Kind = Kind::Bool;
    fn to_value(self) -> Value {
        Value::Bool(self)
    }
    fn from_value(value: Value, _: Option<Range>) -> Result<bool, String> {
        match value {
            Value::Bool(b) => Ok(b),
            _ => Err("must be true or false".into()),
        }
    }
}

/// Declares a settings group: the struct, its `Default` and its [`Group`] implementation.
///
/// ```ignore
/// settings! {
///     /// Settings of the team's opponent tracker.
///     #[derive(Debug, Clone, PartialEq)]
///     pub struct Settings as "tracker" {
///         /// Particles in each role's filter.
///         pub particles_per_role: usize = 1000, range(10, 100_000);
///         /// Merge roles whose clouds become indistinguishable.
///         pub merge: bool = true;
///         /// Symmetric KL divergence under which two roles merge.
///         pub kl_cutoff: f32 = 0.7, above(0.0, 1e6);
///     }
///     internal {
///         /// Probability that an opponent in plain view goes undetected.
///         pub p_miss: f32 = 0.05;
///     }
/// }
/// ```
///
/// `range(lo, hi)` accepts `[lo, hi]`, `above(lo, hi)` accepts `(lo, hi]`. Fields under
/// `internal` are part of the struct and its default but not of the group: no request or
/// command line sets them.
#[macro_export]
macro_rules! settings {
    (
        $(#[doc = $sdoc:literal])*
        #[derive($($derive:ident),*)]
        pub struct $name:ident as $group:literal {
            $(
                $(#[doc = $doc:literal])*
                pub $field:ident : $ty:ty = $default:expr $(, $bound:ident ($lo:expr, $hi:expr))? ;
            )*
        }
        $(internal {
            $(
                $(#[doc = $idoc:literal])*
                pub $ifield:ident : $ity:ty = $idefault:expr ;
            )*
        })?
    ) => {
        $(#[doc = $sdoc])*
        #[derive($($derive),*)]
        pub struct $name {
            $( $(#[doc = $doc])* pub $field: $ty, )*
            $($( $(#[doc = $idoc])* pub $ifield: $ity, )*)?
        }

        impl Default for $name {
            fn default() -> Self {
                $name {
                    $( $field: $default, )*
                    $($( $ifield: $idefault, )*)?
                }
            }
        }

        impl $crate::settings::Group for $name {
            const NAME: &'static str = $group;
            const FIELDS: &'static [$crate::settings::Field] = &[
                $( $crate::settings::Field {
                    name: stringify!($field),
                    doc: concat!($($doc, "\n",)*),
                    kind: <$ty as $crate::settings::FieldType>::KIND,
                    range: $crate::settings!(@range $($bound($lo, $hi))?),
                }, )*
            ];

            fn get(&self, name: &str) -> Option<$crate::settings::Value> {
                match name {
                    $( stringify!($field) => {
                        Some($crate::settings::FieldType::to_value(self.$field))
                    } )*
                    _ => None,
                }
            }

            fn set(
                &mut self,
                name: &str,
                value: $crate::settings::Value,
            ) -> Result<(), $crate::settings::FieldError> {
                let range = <Self as $crate::settings::Group>::field(name).and_then(|f| f.range);
                let refuse = |message: String| $crate::settings::FieldError {
                    field: name.to_string(),
                    message,
                };
                match name {
                    $( stringify!($field) => {
                        self.$field = <$ty as $crate::settings::FieldType>::from_value(value, range)
                            .map_err(refuse)?;
                    } )*
                    _ => return Err($crate::settings::unknown::<Self>(name)),
                }
                Ok(())
            }
        }
    };
    (@range) => { None };
    (@range range($lo:expr, $hi:expr)) => {
        Some($crate::settings::Range { min: $lo as f64, min_exclusive: false, max: $hi as f64 })
    };
    (@range above($lo:expr, $hi:expr)) => {
        Some($crate::settings::Range { min: $lo as f64, min_exclusive: true, max: $hi as f64 })
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    crate::settings! {
        /// A group for the tests.
        #[derive(Debug, Clone, PartialEq)]
        pub struct Example as "example" {
            /// A count.
            pub count: usize = 10, range(1, 100);
            /// A weight,
            /// over two lines.
            pub weight: f32 = 0.7, above(0.0, 1.0);
            pub flag: bool = true;
        }
        internal {
            /// Not settable.
            pub hidden: f32 = 2.0;
        }
    }

    #[test]
    fn the_declaration_gives_defaults_fields_and_docs() {
        let e = Example::default();
        assert_eq!((e.count, e.weight, e.flag, e.hidden), (10, 0.7, true, 2.0));
        let names: Vec<_> = Example::FIELDS.iter().map(|f| f.name).collect();
        assert_eq!(names, ["count", "weight", "flag"]);
        assert_eq!(
            Example::FIELDS[1].description(),
            "A weight, over two lines."
        );
        assert_eq!(Example::FIELDS[2].range, None);
        assert_eq!(Example::FIELDS[0].kind, Kind::Integer);
    }

    #[test]
    fn set_checks_kind_and_range_and_names_the_field() {
        let mut e = Example::default();
        e.set("count", Value::Integer(5)).unwrap();
        e.set("count", Value::Number(6.0)).unwrap();
        assert_eq!(e.count, 6);
        let err = e.set("count", Value::Integer(0)).unwrap_err();
        assert_eq!(err.to_string(), "count: 0 must be in 1..=100");
        let err = e.set("weight", Value::Number(0.0)).unwrap_err();
        assert_eq!(
            err.within("example").to_string(),
            "example.weight: 0 must be finite and in (0, 1]"
        );
        assert!(e.set("weight", Value::Number(f64::NAN)).is_err());
        assert!(e.set("flag", Value::Integer(1)).is_err());
        let err = e.set("hidden", Value::Number(1.0)).unwrap_err();
        assert!(err.message.contains("known: count, weight, flag"), "{err}");
        assert_eq!(
            e,
            Example {
                count: 6,
                ..Example::default()
            },
            "refusals change nothing"
        );
    }

    #[test]
    fn text_settings_parse_by_kind() {
        let mut e = Example::default();
        e.set_text("weight", "0.25").unwrap();
        e.set_text("flag", "false").unwrap();
        assert_eq!((e.weight, e.flag), (0.25, false));
        assert!(e.set_text("count", "2.5").is_err());
        assert!(
            e.set_text("weight", "2").is_err(),
            "out of range on the command line too"
        );
    }

    #[test]
    fn numbers_are_echoed_as_asked() {
        let mut e = Example::default();
        e.set("weight", Value::Number(0.01)).unwrap();
        assert_eq!(e.get("weight"), Some(Value::Number(0.01)));
        assert_eq!(Example::default().get("weight"), Some(Value::Number(0.7)));
        assert_eq!(e.get("nothing"), None);
    }
}
