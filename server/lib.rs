//! lasertag: the server around the deterministic match of `lasertag-core`.
//!
//! An imperative shell over a functional core (the core is its own crate, so the compiler
//! keeps clocks, tasks, I/O and serialisation out of it). Its floors, from the ground up
//! (each imports only those below it; `tests/tidy.rs` checks):
//! - [`config`] (limits), [`access`] (owners, their tokens, per-client keys), [`names`]
//!   (what a player's name may be, and its look-alikes' key), [`metrics`]
//!   (Prometheus), [`schema`] (hand-written OpenAPI pieces and lenient number parsing),
//!   [`maps`] (map files);
//! - [`store`] (the history of matches: SQLite, or PostgreSQL for a fleet);
//! - [`game`] (one tokio task per match, the registry, admission prices, replays, and what a
//!   match shows of itself, in its own types);
//! - [`protocol`] (every JSON shape of the API, converted from the game's and the core's
//!   types);
//! - [`fleet`] (the directory of servers in Redis, with `--fleet`), `agones` (with the
//!   `agones` feature: the Agones SDK lifecycle);
//! - [`service`] (the use cases the handlers call), [`http`] (the axum router);
//! - [`process`] (the server process: its settings, serving, the drain and shutdown);
//! - `main.rs` (CLI; its `experiment` command runs `lasertag-lab`).
//!
//! Invariants: a match is a pure function of (map, settings, seed, inputs by tick); robots'
//! decisions read only what a robot could know; only a match's own task mutates it; this
//! library never imports `lasertag-lab`.

pub mod access;
#[cfg(feature = "agones")]
pub mod agones;
pub mod config;
pub mod fleet;
pub mod game;
pub mod http;
pub mod maps;
pub mod metrics;
pub mod names;
pub mod process;
pub mod protocol;
pub mod schema;
pub mod service;
pub mod store;
