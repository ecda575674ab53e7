//! Shortest paths on small arenas: through doors, in straight legs, within a reach, around
//! discs, and the waypoint where a path sets off.

use super::*;
use crate::sim::arena::{Arena, MapDef};

/// Two rooms joined by a door in a wall at x = 5.
fn two_rooms() -> Arena {
    Arena::new(MapDef {
        name: "two".into(),
        width: 10.0,
        height: 6.0,
        obstacles: vec![
            vec![
                Point2::new(4.9, 0.0),
                Point2::new(5.1, 0.0),
                Point2::new(5.1, 4.0),
                Point2::new(4.9, 4.0),
            ],
            vec![
                Point2::new(4.9, 5.2),
                Point2::new(5.1, 5.2),
                Point2::new(5.1, 6.0),
                Point2::new(4.9, 6.0),
            ],
        ],
        robot_spawns: vec![[1.0, 1.0, 0.0]],
        opponent_spawns: vec![Point2::new(9.0, 1.0)],
        landmarks: vec![],
    })
}

#[test]
fn paths_go_through_the_door_in_straight_legs() {
    let a = two_rooms();
    let g = &a.grid;
    let f = DistanceField::from_point(g, Point2::new(1.0, 1.0)).unwrap();
    let goal = g.cell_of(Point2::new(9.0, 1.0)).unwrap();
    let path = f.path_to(g, Point2::new(1.0, 1.0), goal).unwrap();
    assert!(path.len() <= 5, "smoothed: {path:?}");
    assert!(
        path.iter().any(|p| p.y > 4.0 && (p.x - 5.0).abs() < 1.0),
        "via the door: {path:?}"
    );
    for w in path.windows(2).skip(1) {
        assert!(segment_passable(g, w[0], w[1]));
    }
    // The travel distance exceeds the straight-line 8 m because of the detour.
    assert!(f.dist[goal] > 10.0);
}

#[test]
fn only_a_narrow_door_counts_as_narrow() {
    let wide = two_rooms(); // a 1.2 m door
    let mut def = wide.def.clone();
    def.obstacles[1][0].y = 4.9; // a 0.9 m door
    def.obstacles[1][1].y = 4.9;
    let tight = Arena::new(def);
    let (from, to) = (Point2::new(1.0, 1.0), Point2::new(9.0, 1.0));
    let through = |a: &Arena| {
        let narrow = narrow_cells(&a.grid, 0.5, 0.2);
        let f = DistanceField::from_point(&a.grid, from).unwrap();
        let m = f.narrow_metres(&narrow);
        (
            m[a.grid.cell_of(to).unwrap()],
            m[a.grid.cell_of(Point2::new(2.0, 2.0)).unwrap()],
        )
    };
    let (wide_door, wide_room) = through(&wide);
    let (tight_door, tight_room) = through(&tight);
    // Hugging the door's corners in a wide door is not a narrow passage; the tight door
    // is, over about its wall's thickness and a little either side.
    assert_eq!((wide_door, wide_room, tight_room), (0.0, 0.0, 0.0));
    assert!(tight_door > 0.15 && tight_door < 1.5, "{tight_door}");
}

#[test]
fn the_bordered_table_opens_what_testing_every_cell_opens() {
    let arena = two_rooms();
    let grid = &arena.grid;
    let discs = [
        vec![],
        vec![(Point2::new(2.0, 1.0), 0.6)],
        // At the grid's corner, past its edge, of no size, and two overlapping.
        vec![(Point2::new(0.0, 0.0), 1.0), (Point2::new(10.3, 4.2), 0.75)],
        vec![(Point2::new(5.0, 1.5), 0.0), (Point2::new(-3.0, 1.0), 3.2)],
        vec![(Point2::new(4.0, 2.0), 0.5), (Point2::new(4.3, 2.1), 0.5)],
    ];
    for avoid in &discs {
        let table = OpenCells::new(grid, avoid);
        for idx in 0..grid.len() {
            let c = grid.centre(idx);
            let want =
                grid.passable(idx) && avoid.iter().all(|(p, r)| (c - p).norm_squared() >= r * r);
            let (row, col) = (idx / grid.cols, idx % grid.cols);
            let got = table.open[(row + 1) * table.stride + col + 1];
            assert_eq!(got, want, "cell {idx} with {avoid:?}");
        }
        // The border stays closed.
        let rows = grid.rows + 2;
        for r in 0..rows {
            assert!(!table.open[r * table.stride]);
            assert!(!table.open[r * table.stride + table.stride - 1]);
        }
    }
}

#[test]
fn a_field_within_a_reach_is_the_whole_fields_inside_it() {
    let arena = two_rooms();
    let grid = &arena.grid;
    let from = Point2::new(1.0, 1.0);
    let whole = DistanceField::from_point(grid, from).unwrap();
    for reach in [0.0, 0.35, 3.0, 7.5, 100.0] {
        let near = DistanceField::from_point_within(grid, from, reach).unwrap();
        for cell in 0..grid.len() {
            if whole.reachable(cell) && whole.dist[cell] <= reach {
                assert_eq!(
                    near.dist[cell], whole.dist[cell],
                    "cell {cell}, reach {reach}"
                );
                assert_eq!(near.cells_to(cell), whole.cells_to(cell));
            } else {
                assert!(
                    !near.reachable(cell) || near.dist[cell] > reach,
                    "cell {cell}"
                );
            }
        }
    }
}

/// Stops where told, and tells every settled cell once, in order of distance.
struct StopAt {
    metres: f32,
    grid_cell: f32,
    settled: Vec<(usize, u32)>,
}

impl Watch for StopAt {
    fn settled(&mut self, cell: usize, units: u32, from: Option<(usize, u32)>) {
        if let Some((_, before)) = from {
            assert!(before < units);
        }
        self.settled.push((cell, units));
    }
    fn go_on(&mut self, units: u32) -> bool {
        units as f32 * (self.grid_cell / STRAIGHT as f32) <= self.metres
    }
}

#[test]
fn a_watched_field_is_the_whole_fields_as_far_as_it_grew() {
    let arena = two_rooms();
    let grid = &arena.grid;
    let from = Point2::new(1.0, 1.0);
    let whole = DistanceField::from_point(grid, from).unwrap();
    let all = DistanceField::from_point_watched(grid, from, &[], &mut Unwatched).unwrap();
    assert_eq!(all.dist, whole.dist);
    for metres in [0.0, 2.0, 6.5] {
        let mut watch = StopAt {
            metres,
            grid_cell: grid.cell,
            settled: Vec::new(),
        };
        let grown = DistanceField::from_point_watched(grid, from, &[], &mut watch).unwrap();
        let mut told = 0;
        for cell in 0..grid.len() {
            if whole.reachable(cell) && whole.dist[cell] <= metres {
                assert_eq!(grown.dist[cell], whole.dist[cell], "cell {cell}");
                assert_eq!(grown.cells_to(cell), whole.cells_to(cell));
                told += 1;
            } else {
                assert!(!grown.reachable(cell) || grown.dist[cell] >= whole.dist[cell]);
            }
        }
        assert_eq!(watch.settled.len(), told, "{metres} m");
        assert!(watch.settled.windows(2).all(|w| w[0].1 <= w[1].1));
        for &(cell, units) in &watch.settled {
            assert_eq!(DistanceField::metres_of(grid, units), whole.dist[cell]);
        }
    }
}

#[test]
fn a_walled_off_room_is_unreachable() {
    let mut def = two_rooms().def.clone();
    def.obstacles[1][0].y = 3.9;
    def.obstacles[1][1].y = 3.9;
    let a = Arena::new(def);
    let f = DistanceField::from_point(&a.grid, Point2::new(1.0, 1.0)).unwrap();
    assert!(!f.reachable(a.grid.cell_of(Point2::new(9.0, 1.0)).unwrap()));
}

#[test]
fn a_bounded_search_finds_the_full_searchs_path_or_gives_up() {
    let a = two_rooms();
    let g = &a.grid;
    let starts = [(1.0, 1.0), (4.5, 5.5), (9.5, 0.5), (2.0, 3.0)];
    let goals = [(9.0, 1.0), (6.0, 5.0), (1.0, 5.5), (4.0, 1.0), (2.1, 3.0)];
    for &(fx, fy) in &starts {
        let from = Point2::new(fx, fy);
        let field = DistanceField::from_point(g, from).unwrap();
        for &(gx, gy) in &goals {
            let goal = g.cell_of(Point2::new(gx, gy)).unwrap();
            let full = field.path_to(g, from, goal);
            let mut work = u64::MAX;
            assert_eq!(path_within(g, from, goal, &mut work), Ok(full));
            // A goal near the start settles a few cells, not the grid.
            let used = u64::MAX - work;
            if (gx - fx).abs() + (gy - fy).abs() < 0.5 {
                assert!(used < g.len() as u64 / 4, "{used}");
            }
        }
    }
    let goal = g.cell_of(Point2::new(9.0, 1.0)).unwrap();
    let mut work = 1_000;
    assert_eq!(
        path_within(g, Point2::new(1.0, 1.0), goal, &mut work),
        Err(OverBudget)
    );
}

/// Where the shortest path to `cell` in `f` first runs more than `ahead` metres from the
/// start, by walking its predecessors (what [`WayMap::waypoint`] answers).
fn waypoint_by_walking(f: &DistanceField, cell: usize, ahead: f32) -> usize {
    let mut at = cell;
    while at != f.start && f.dist[f.prev[at] as usize] > ahead {
        at = f.prev[at] as usize;
    }
    at
}

#[test]
fn a_reach_field_is_the_whole_fields_inside_its_reach() {
    let rooms = two_rooms();
    // Smaller than the reach every way: the window is the grid.
    let tight = Arena::new(MapDef {
        name: "small".into(),
        width: 7.0,
        height: 3.0,
        obstacles: vec![],
        robot_spawns: vec![[1.0, 1.0, 0.0]],
        opponent_spawns: vec![Point2::new(6.0, 2.0)],
        landmarks: vec![],
    });
    for (a, from, reach) in [
        (&rooms, Point2::new(1.0, 1.0), 6.0),
        (&rooms, Point2::new(4.2, 2.0), 6.0),
        (&rooms, Point2::new(5.6, 4.6), 3.5),
        (&rooms, Point2::new(9.7, 5.7), 20.0),
        (&tight, Point2::new(3.5, 1.5), 6.0),
    ] {
        let g = &a.grid;
        let whole = DistanceField::from_point_within(g, from, reach).unwrap();
        let near = ReachField::new(g, from, reach).unwrap();
        let ways = WayMap::new(&near, 1.0);
        let mut within = 0;
        for cell in 0..g.len() {
            let d = whole.dist[cell];
            let expected = (d <= reach).then_some(d);
            assert_eq!(near.metres(cell), expected, "cell {cell} from {from:?}");
            let way = ways.waypoint(g, cell);
            if expected.is_some() {
                within += 1;
                assert_eq!(way, Some(waypoint_by_walking(&whole, cell, 1.0)));
            } else {
                assert_eq!(way, None);
            }
        }
        assert!(within > 100, "{within} cells within {reach} m of {from:?}");
    }
}

#[test]
fn a_waypoint_ahead_is_where_the_path_sets_off() {
    let a = two_rooms();
    let g = &a.grid;
    let from = Point2::new(1.0, 1.0);
    let f = WayMap::new(&ReachField::new(g, from, 20.0).unwrap(), 1.0);
    let whole = DistanceField::from_point(g, from).unwrap();
    // Beyond the wall: the first metre of the way leads toward the door, on that way.
    let far = g.cell_of(Point2::new(9.0, 1.0)).unwrap();
    let way = f.waypoint(g, far).unwrap();
    assert!(whole.dist[way] > 1.0 && whole.dist[whole.prev[way] as usize] <= 1.0);
    assert!(whole.cells_to(far).unwrap().contains(&way));
    // A cell on the same way has the same waypoint.
    let on_the_way = whole.cells_to(far).unwrap()[30];
    assert_eq!(f.waypoint(g, on_the_way), Some(way));
    // A cell nearer than the metre is its own waypoint.
    let near = g.cell_of(Point2::new(1.5, 1.0)).unwrap();
    assert_eq!(f.waypoint(g, near), Some(near));
    // The waypoints are few: the cells a little past the metre, and the nearer ones.
    assert!(f.waypoints().len() < 1_000, "{}", f.waypoints().len());
}

#[test]
fn a_kept_reach_field_answers_as_a_fresh_one_from_wherever_its_walker_stands() {
    let a = two_rooms();
    let g = &a.grid;
    let mut cache = ReachCache::default();
    // A walk across the door in steps smaller than a cell: some keep the cell, some leave it.
    let walk: Vec<Point2<f32>> = (0..60)
        .map(|i| Point2::new(3.0 + i as f32 * 0.04, 4.6))
        .collect();
    let mut searched = 0;
    let mut last_start = None;
    for from in walk {
        let fresh = WayMap::new(&ReachField::new(g, from, 6.0).unwrap(), 1.0);
        let start = start_cell(g, from).unwrap();
        if last_start != Some(start) {
            searched += 1;
            last_start = Some(start);
        }
        let kept = cache.ways(g, from, 6.0, 1.0).unwrap();
        for cell in (0..g.len()).step_by(7) {
            assert_eq!(
                kept.waypoint(g, cell),
                fresh.waypoint(g, cell),
                "cell {cell} from {from:?}"
            );
        }
    }
    // The walk both stayed in cells and left them: the cache was used and renewed.
    assert!((10..60).contains(&searched), "{searched} cells on the walk");
}

#[test]
fn a_points_waypoint_is_its_cells() {
    let a = two_rooms();
    let g = &a.grid;
    for from in [
        Point2::new(1.0, 1.0),
        Point2::new(4.6, 4.6),
        Point2::new(9.5, 5.5),
    ] {
        let f = WayMap::new(&ReachField::new(g, from, 6.0).unwrap(), 1.0);
        let mut found = 0;
        for i in -3..110 {
            for j in -3..70 {
                let p = Point2::new(i as f32 * 0.097, j as f32 * 0.091);
                let by_cell = g.cell_of(p).and_then(|c| f.waypoint(g, c));
                assert_eq!(
                    f.id_ahead(g, p).map(|id| f.waypoints()[id]),
                    by_cell,
                    "{p:?} from {from:?}"
                );
                found += usize::from(by_cell.is_some());
            }
        }
        assert!(found > 1000, "{found} points within reach of {from:?}");
    }
}
