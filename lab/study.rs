//! A study: an experiment's fixed list of runs, what each run measured, and the files made
//! from all of them. Every experiment is written as three steps: run the matches, one
//! [`Record`] per run; then, from the records in the study's order, aggregate and plot
//! ([`Study::write`]). Run as shards, each writes its records to a part ([`crate::part`]) and
//! `merge` reads them back bit for bit; run whole, a study is the merge of its one shard,
//! held in memory ([`crate::execute`]). Either way the same records reach the same `write`,
//! so the merged files are the single run's, byte for byte.

use std::path::Path;
use std::sync::Arc;

use lasertag_core::settings::{Group, Value};
use lasertag_core::sim::arena::{Arena, MapDef};

use crate::error::LabError;
use crate::part::Params;
use crate::record::Record;

/// One experiment's study, as its parameters define it.
pub trait Study: Sized {
    /// The experiment's command name, also the part files' name.
    const NAME: &'static str;
    /// The progress bar's label.
    const LABEL: &'static str;
    /// What one run measured: everything [`Study::write`] reads.
    type Run: Record + Send;
    /// What the command prints.
    type Report;

    /// Every parameter, in a fixed order: parts of one study have equal ones.
    fn params(&self) -> Params;
    /// The study back from its parameters (the inverse of [`Study::params`]).
    fn from_params(params: &Params) -> Result<Self, String>;
    /// Runs in the study.
    fn runs(&self) -> usize;
    /// Aggregates and plots the runs (all of them, in the study's order) into `out`.
    fn write(&self, runs: Vec<Self::Run>, out: &Path) -> Result<Self::Report, LabError>;
}

/// A map as a study names it: its name and a fingerprint of its contents, so that parts run
/// against different copies of a map file do not merge.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MapStamp {
    pub name: String,
    pub fingerprint: String,
}

impl MapStamp {
    pub fn of(def: &MapDef) -> MapStamp {
        MapStamp {
            name: def.name.clone(),
            fingerprint: fingerprint(def),
        }
    }

    /// The stamps of `maps` in order.
    pub fn all<'a>(maps: impl IntoIterator<Item = &'a Arc<Arena>>) -> Vec<MapStamp> {
        maps.into_iter().map(|a| MapStamp::of(&a.def)).collect()
    }

    /// `maps` (the names, comma-separated, in order) and `map.<name>` (each fingerprint).
    pub fn to_params(maps: &[MapStamp], params: &mut Params) {
        let names: Vec<&str> = maps.iter().map(|m| m.name.as_str()).collect();
        params.set("maps", names.join(","));
        for m in maps {
            params.set(format!("map.{}", m.name), &m.fingerprint);
        }
    }

    pub fn from_params(params: &Params) -> Result<Vec<MapStamp>, String> {
        params
            .get("maps")?
            .split(',')
            .filter(|n| !n.is_empty())
            .map(|name| {
                Ok(MapStamp {
                    name: name.to_string(),
                    fingerprint: params.get(&format!("map.{name}"))?.to_string(),
                })
            })
            .collect()
    }
}

/// FNV-1a (64 bits) over everything a map defines, numbers by their bits: the same on every
/// machine, and different for any change to the map.
fn fingerprint(def: &MapDef) -> String {
    struct Fnv(u64);
    impl Fnv {
        fn bytes(&mut self, bytes: &[u8]) {
            for &b in bytes {
                self.0 = (self.0 ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3);
            }
        }
        /// A list's length first, so that `[a, b] [c]` and `[a] [b, c]` differ.
        fn floats(&mut self, xs: impl ExactSizeIterator<Item = f32>) {
            self.bytes(&(xs.len() as u64).to_le_bytes());
            xs.for_each(|x| self.bytes(&x.to_bits().to_le_bytes()));
        }
    }
    let xy = |ps: &[nalgebra::Point2<f32>]| ps.iter().flat_map(|p| [p.x, p.y]).collect::<Vec<_>>();
    let mut h = Fnv(0xcbf2_9ce4_8422_2325);
    h.bytes(&(def.name.len() as u64).to_le_bytes());
    h.bytes(def.name.as_bytes());
    h.floats([def.width, def.height].into_iter());
    h.bytes(&(def.obstacles.len() as u64).to_le_bytes());
    for o in &def.obstacles {
        h.floats(xy(o).into_iter());
    }
    h.floats(
        def.robot_spawns
            .iter()
            .flatten()
            .copied()
            .collect::<Vec<_>>()
            .into_iter(),
    );
    h.floats(xy(&def.opponent_spawns).into_iter());
    h.floats(xy(&def.landmarks).into_iter());
    format!("fnv1a64:{:016x}", h.0)
}

/// Every declared field of a settings group as `<prefix>.<name>` parameters.
pub fn group_to_params<G: Group>(group: &G, prefix: &str, params: &mut Params) {
    for f in G::FIELDS {
        let text = match group.get(f.name) {
            Some(Value::Integer(i)) => i.to_string(),
            // An `f32` field's value is already its shortest decimal (`FieldType`).
            Some(Value::Number(x)) => x.to_string(),
            Some(Value::Bool(b)) => b.to_string(),
            None => continue,
        };
        params.set(format!("{prefix}.{}", f.name), text);
    }
}

/// A settings group from its `<prefix>.<name>` parameters, each set by name and checked.
pub fn group_from_params<G: Group>(params: &Params, prefix: &str) -> Result<G, String> {
    let mut group = G::default();
    for f in G::FIELDS {
        let text = params.get(&format!("{prefix}.{}", f.name))?;
        group
            .set_text(f.name, text)
            .map_err(|e| format!("parameter {prefix}.{e}"))?;
    }
    Ok(group)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point2;

    fn def() -> MapDef {
        MapDef {
            name: "t".into(),
            width: 10.0,
            height: 6.0,
            obstacles: vec![vec![Point2::new(1.0, 1.0), Point2::new(2.0, 1.0)]],
            robot_spawns: vec![[1.0, 1.0, 0.0]],
            opponent_spawns: vec![Point2::new(5.0, 5.0)],
            landmarks: vec![Point2::new(0.5, 0.5)],
        }
    }

    #[test]
    fn a_maps_fingerprint_changes_with_anything_in_it() {
        let base = MapStamp::of(&def());
        assert_eq!(base, MapStamp::of(&def()));
        let mut moved = def();
        moved.landmarks[0].x = 0.6;
        let mut bare = def();
        bare.landmarks.clear();
        for other in [moved, bare] {
            assert_ne!(MapStamp::of(&other).fingerprint, base.fingerprint);
        }
        let mut params = Params::default();
        MapStamp::to_params(std::slice::from_ref(&base), &mut params);
        assert_eq!(MapStamp::from_params(&params), Ok(vec![base]));
    }

    #[test]
    fn a_settings_group_reads_back_from_its_params() {
        let mut radio = lasertag_core::radio::Settings::default();
        radio.set_text("loss", "0.2").unwrap();
        radio.set_text("latency_ticks", "5").unwrap();
        let mut params = Params::default();
        group_to_params(&radio, "radio", &mut params);
        assert_eq!(params.get("radio.loss"), Ok("0.2"));
        assert_eq!(group_from_params(&params, "radio"), Ok(radio));
        let coordination = lasertag_core::planner::coordinated::Settings::default();
        let mut params = Params::default();
        group_to_params(&coordination, "coordination", &mut params);
        assert_eq!(group_from_params(&params, "coordination"), Ok(coordination));
    }
}
