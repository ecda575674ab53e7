//! [`Invalid`]: a refused part of a request, and [`invalid`], which makes one.

/// A request part that was refused: the JSON path of what is wrong, and why.
pub use lasertag_core::settings::FieldError as Invalid;

/// `Invalid` at `field`.
pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Invalid {
    Invalid {
        field: field.into(),
        message: message.into(),
    }
}
