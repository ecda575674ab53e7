//! Map files (`docs/map-format.md`): parse, validate, and convert to a [`MapDef`]; and the
//! formats researchers already have (`docs/map-import.md`), converted into ours.
//!
//! The files stand on each other from the bottom up, and this one only names them:
//! - [`json`]: [`MapFile`], the JSON shape, and [`validate`], which enforces every rule of
//!   the spec and reports the first violation as a [`MapError`] naming field and index. Every
//!   other way into the server goes through [`validate`] too, so an imported map obeys the
//!   same rules as one written by hand;
//! - [`format`]: what every imported format shares: the kinds of map file, the bounds, the
//!   [`Problem`]s and [`ImportError`]s;
//! - [`grid`]: an occupancy grid, which every imported format becomes; [`spawns`] places
//!   spawns and landmarks on one;
//! - the formats: [`ros`] (a ROS map_server map: YAML plus a PGM or PNG [`image`]) and
//!   [`movingai`] (a MovingAI grid); [`raster`] the way back, a map drawn onto a grid for a
//!   ROS export;
//! - [`import`]: picks the format by the file's kind, then turns its grid into rectangles,
//!   spawns and landmarks, validated;
//! - [`store`]: [`MapStore`], the shipped and uploaded maps with their built [`Arena`]s,
//!   loaded from a folder of `.json`, `.yaml` and `.map` files;
//! - [`cli`]: the binary's `map import` and `map export` commands.
//!
//! [`MapDef`]: lasertag_core::sim::arena::MapDef
//! [`Arena`]: lasertag_core::sim::arena::Arena

pub mod cli;
pub mod format;
pub mod grid;
pub mod image;
pub mod import;
pub mod json;
pub mod movingai;
pub mod raster;
pub mod ros;
pub mod spawns;
pub mod store;

pub use format::{ImportError, Problem};
pub use import::{ImportOptions, Imported};
pub use json::{MAX_MAP_BYTES, MapError, MapFile, from_value, parse, to_file, validate};
pub use store::{LoadError, MapStore, StoredMap};

pub use crate::schema::{MAX_LANDMARKS, MAX_POLYGON_VERTICES, MAX_SPAWNS, MAX_VERTICES};
