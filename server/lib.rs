//! lasertag: a team of autonomous robots plays laser tag against people.
//!
//! The crate is a functional core wrapped in an imperative shell:
//! - core (deterministic, no tokio, no clocks, no I/O): [`sim`] (the world and its tick
//!   pipeline), [`nav`] (shortest paths), [`tracker`] (role-factored particle filters), [`localise`] (each robot's own pose by MCL), [`planner`] (the robot team's decisions), [`radio`] (what
//!   robots tell each other, delayed and dropped);
//! - edge: [`maps`] (map files), [`protocol`] (every JSON shape of the API);
//! - shell: [`game`] (one tokio task per match), [`http`] (the axum router), [`experiment`]
//!   (the paper's experiments over all cores), `main.rs` (CLI).
//!
//! Invariants: a match is a pure function of (map, settings, seed, inputs by tick); robots'
//! decisions read only what a robot could know; only a match's own task mutates it.

pub mod config;
pub mod experiment;
pub mod game;
pub mod http;
pub mod localise;
pub mod maps;
pub mod metrics;
pub mod nav;
pub mod planner;
pub mod protocol;
pub mod radio;
pub mod sim;
pub mod tracker;
