//! lasertag-core: a laser-tag match between a robot team and its opponents, as plain data and
//! pure steps.
//!
//! A match is a pure function of (map, settings, seed, inputs by tick): nothing here reads a
//! clock, does I/O, spawns tasks or serialises; every random draw comes from a seeded
//! `ChaCha8Rng` stream. The modules form floors, each importing only those listed before it
//! (`tests/tidy.rs` checks the order):
//!
//! - [`checkpoint`]: a match's state as bytes and back (what a resumed match starts from).
//! - [`settings`]: settings groups declared once (name, type, default, range, doc).
//! - [`sim`]: the physical world: static [`sim::arena`], kinematics and collisions, laser and
//!   landmark sensors, tagging rules, candidate views.
//! - [`nav`]: travel-time fields and path following over the arena's clearance grid.
//! - [`localise`]: each robot's own pose by Monte Carlo localisation, or dead reckoning.
//! - [`tracker`]: the team's role-factored particle filters over the unseen opponents.
//! - [`radio`]: what robots tell each other, delayed and dropped.
//! - [`planner`]: the robot team's decisions (coordinated, baseline, idle).
//! - [`bots`]: the opponents' bot behaviours (part of the environment: they may read truth).
//! - [`world`]: one match, its tick pipeline and its event log.
//! - [`difficulty`]: the robot team's presets a person chooses (recruit, veteran, elite).
//! - [`env`]: the research environment's episodes as flat arrays (observation vectors,
//!   rewards, episode ends) for in-process engines.

pub mod checkpoint;

pub mod settings;

pub mod sim;

pub mod nav;

pub mod localise;

pub mod tracker;

pub mod radio;

pub mod planner;

pub mod bots;

pub mod world;

pub mod difficulty;

pub mod env;
