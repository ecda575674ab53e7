//! Admission's tick prices against the measured ones: every row of
//! docs/results/admission_calibration.csv (each shipped map × `calibration_settings`, measured
//! by `examples/admission_calibration.rs`) must be priced today as it was when measured, and
//! within 1.5× of its measured p99 tick. A change to the price function, or to what a tick
//! costs, shows here: re-measure (the command is in the file's error) and look at the table.

use std::path::Path;

use lasertag::game::admission::{calibration_settings, match_on};
use lasertag::maps::MapStore;

const TABLE: &str = "docs/results/admission_calibration.csv";
const REMEASURE: &str = "cargo run --release --example admission_calibration -- --out docs/results/admission_calibration.csv";

#[test]
fn every_shipped_map_and_setting_is_priced_within_one_and_a_half_times_its_measured_p99() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let maps = MapStore::load_dir(&root.join("maps")).expect("the shipped maps load");
    let text = std::fs::read_to_string(root.join(TABLE)).expect("the calibration table");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (map_c, setting_c, priced_c, p99_c) =
        (col("map"), col("setting"), col("priced_ms"), col("p99_ms"));
    let settings = calibration_settings();
    let mut checked = std::collections::BTreeSet::new();
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        let (map, setting) = (f[map_c], f[setting_c]);
        let recorded: f64 = f[priced_c].parse().expect("priced_ms");
        let p99: f64 = f[p99_c].parse().expect("p99_ms");
        let arena = &maps
            .get(map)
            .unwrap_or_else(|| panic!("{map} is not shipped"))
            .arena;
        let (_, config) = settings
            .iter()
            .find(|(name, _)| *name == setting)
            .unwrap_or_else(|| panic!("{setting} is not a calibration setting"));
        let priced = match_on(&arena.def, config).tick_ms;
        assert!(
            (priced - recorded).abs() < 1e-3,
            "{map} {setting}: priced {priced:.3} ms now, {recorded:.3} ms when measured; re-measure: {REMEASURE}"
        );
        let ratio = priced / p99;
        assert!(
            (1.0 / 1.5..=1.5).contains(&ratio),
            "{map} {setting}: priced {priced:.2} ms against a measured p99 of {p99:.2} ms ({ratio:.2}×)"
        );
        checked.insert((map.to_string(), setting.to_string()));
    }
    // Every shipped map with every setting, none left out.
    for m in maps.iter() {
        for (setting, _) in &settings {
            assert!(
                checked.contains(&(m.arena.def.name.clone(), setting.to_string())),
                "{} {setting} is not in {TABLE}; re-measure: {REMEASURE}",
                m.arena.def.name
            );
        }
    }
}

/// A match priced past `HEAVY_TICK_MS` runs its ticks off the runtime's workers, so that its
/// long ticks do not hold the other matches' ticks and reads queued behind them: the `search`
/// planner choosing every tick five deep over six branches is such a match on every shipped
/// map, and every ordinary setting (its price near its p99 of about a millisecond) stays on
/// the workers, where hundreds of matches tick without a thread hand-off each.
#[test]
fn only_a_deep_search_runs_its_ticks_off_the_workers() {
    use lasertag::game::admission::holds_a_worker;
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let maps = MapStore::load_dir(&root.join("maps")).expect("the shipped maps load");
    for m in maps.iter() {
        for (setting, config) in calibration_settings() {
            let price = match_on(&m.arena.def, &config);
            assert_eq!(
                holds_a_worker(&price),
                setting == "search_deep_2r_3o",
                "{} {setting}: priced {:.2} ms a tick",
                m.arena.def.name,
                price.tick_ms
            );
        }
    }
}
