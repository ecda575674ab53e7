//! Unit tests of admission: prices from settings, and the budgets that hold them.

use super::*;

fn empty(side: f32) -> MapDef {
    MapDef {
        name: "t".into(),
        width: side,
        height: side,
        obstacles: vec![],
        robot_spawns: vec![[1.0, 1.0, 0.0]],
        opponent_spawns: vec![Point2::new(2.0, 2.0)],
        landmarks: vec![],
    }
}

#[test]
fn long_diagonal_walls_are_priced_by_the_area_of_their_boxes() {
    let mut def = empty(500.0);
    let plain = map(&def).build_s;
    def.obstacles = (0..64)
        .map(|k| {
            let y = 1.0 + k as f32 * 0.01;
            vec![
                Point2::new(10.0, y),
                Point2::new(490.0, y + 480.0),
                Point2::new(490.5, y + 480.0),
                Point2::new(10.5, y),
            ]
        })
        .collect();
    let slivers = map(&def).build_s;
    // Measured: about 2.4 s to build the arena and 2 s more for the match's field.
    assert!(plain < 0.2 && slivers > 2.0, "{plain} {slivers}");
}

#[test]
fn the_search_planners_travel_table_is_priced_within_its_bound() {
    let config = |planner| MatchConfig {
        planner,
        ..MatchConfig::default()
    };
    let office = empty(24.0);
    let (greedy, search) = (
        match_on(
            &office,
            &config(lasertag_core::planner::PlannerKind::Coordinated),
        ),
        match_on(
            &office,
            &config(lasertag_core::planner::PlannerKind::Search),
        ),
    );
    // Measured on `office` (24 m × 16 m): 0.29 s and 0.4 MB for its table.
    assert!(search.build_s - greedy.build_s > 0.3, "{search:?}");
    assert!(search.memory - greedy.memory > 1_000_000, "{search:?}");
    // A huge map's table is bounded: at most 0.6 s and 2.6 MB more, or none at all.
    let huge = empty(500.0);
    let extra = match_on(&huge, &config(lasertag_core::planner::PlannerKind::Search)).build_s
        - match_on(
            &huge,
            &config(lasertag_core::planner::PlannerKind::Coordinated),
        )
        .build_s;
    assert!(extra <= 0.61, "{extra}");
}

#[test]
fn a_fine_merge_grid_behind_a_lossy_radio_is_priced_per_robot() {
    let def = empty(500.0);
    let mut config = MatchConfig {
        robots: 8,
        opponents: 8,
        ..MatchConfig::default()
    };
    config.tracker.grid_cell = 0.1;
    let shared = match_on(&def, &config).memory;
    config.radio.loss = 0.5;
    let lossy = match_on(&def, &config).memory;
    // Measured: 210 MB kept with one tracker, 1.62 GB with eight.
    assert!(
        shared > 200_000_000 && lossy > 1_600_000_000,
        "{shared} {lossy}"
    );
}

#[test]
fn the_default_match_on_a_shipped_sized_map_is_cheap() {
    let def = empty(24.0);
    let p = map(&def) + match_on(&def, &MatchConfig::default());
    assert!(
        p.memory < 30_000_000 && p.tick_ms < 2.0 && p.build_s < 0.5,
        "{p:?}"
    );
}
