//! Every shipped map loads, and every spawn can reach every other one.

use std::path::Path;

use lasertag::maps::MapStore;
use lasertag_core::nav::DistanceField;
use nalgebra::Point2;

#[test]
fn every_shipped_map_loads_and_its_spawns_are_mutually_reachable() {
    let store = MapStore::load_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("maps").as_path())
        .expect("shipped maps load");
    let names: Vec<String> = store.iter().map(|m| m.arena.def.name.clone()).collect();
    for want in ["hallway", "office", "warehouse", "maze"] {
        assert!(
            names.iter().any(|n| n == want),
            "{want} is shipped: {names:?}"
        );
    }
    for m in store.iter() {
        let def = &m.arena.def;
        let grid = &m.arena.grid;
        let spawns: Vec<Point2<f32>> = def
            .robot_spawns
            .iter()
            .map(|s| Point2::new(s[0], s[1]))
            .chain(def.opponent_spawns.iter().copied())
            .collect();
        let field = DistanceField::from_point(grid, spawns[0])
            .unwrap_or_else(|| panic!("{}: first spawn has no passable cell near", def.name));
        for (k, s) in spawns.iter().enumerate() {
            let cell = grid
                .nearest_passable(*s, 10)
                .unwrap_or_else(|| panic!("{}: spawn {k} boxed in", def.name));
            assert!(
                field.reachable(cell),
                "{}: spawn {k} at {s:?} is unreachable",
                def.name
            );
        }
    }
}
