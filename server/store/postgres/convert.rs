//! The client's errors as the store's, with the database's own words, and counts as
//! PostgreSQL's `BIGINT`: what the connection, the schema and the writes share.

use crate::store::backend::StoreError;

/// An error of the client, with the database's own message when there is one ("db error"
/// alone says nothing).
pub(super) fn describe(e: &::postgres::Error) -> String {
    if let Some(d) = e.as_db_error() {
        let mut text = format!("{} {}: {}", d.severity(), d.code().code(), d.message());
        if let Some(detail) = d.detail() {
            text.push_str(&format!(" ({detail})"));
        }
        return text;
    }
    match std::error::Error::source(e) {
        Some(cause) => format!("{e}: {cause}"),
        None => e.to_string(),
    }
}

/// A client error as the store's.
pub(super) fn db(e: ::postgres::Error) -> StoreError {
    StoreError::Database(describe(&e))
}

/// A count or tick as PostgreSQL's `BIGINT`.
pub(super) fn big(n: u64) -> i64 {
    i64::try_from(n).unwrap_or(i64::MAX)
}
