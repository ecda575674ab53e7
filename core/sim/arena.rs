//! The static map as the simulation sees it: walls for ray casts and collisions (a parry2d
//! `Polyline` with its bounding-volume hierarchy) and a clearance grid for navigation.
//!
//! An `Arena` is built once per map from a validated [`MapDef`] and shared (`Arc`) by every
//! match on that map: it never changes while a match runs.
//!
//! Long file: each fast path (the segment grid's ray cast, the fan cast, the clearance grid)
//! sits beside the test that pins it to its reference, bit for bit.

use nalgebra::{Point2, Vector2};
use parry2d::query::{PointQuery, Ray, RayCast};
use parry2d::shape::Polyline;

use std::any::Any;
use std::sync::{Arc, Mutex};

use crate::sim::AGENT_RADIUS;
use crate::sim::segments::{FanBins, SegmentBins, SegmentGrid};

/// A map after validation: plain data, no serialisation concerns (see `maps.rs` for the file format).
#[derive(Debug, Clone, PartialEq)]
pub struct MapDef {
    pub name: String,
    pub width: f32,
    pub height: f32,
    pub obstacles: Vec<Vec<Point2<f32>>>,
    /// `(x, y, heading)`.
    pub robot_spawns: Vec<[f32; 3]>,
    pub opponent_spawns: Vec<Point2<f32>>,
    pub landmarks: Vec<Point2<f32>>,
}

/// Extra distance kept from walls by planned paths, on top of the agent radius, so that a
/// disc following a path with small tracking errors does not scrape along walls.
pub const NAV_MARGIN: f32 = 0.08;

/// The static world: walls, obstacles and a clearance grid.
#[derive(Debug)]
pub struct Arena {
    pub def: MapDef,
    /// Every obstacle edge plus the arena border, as one polyline with a BVH.
    walls: Polyline,
    /// The same edges bucketed on a coarse grid, for the laser's many short ray casts.
    buckets: SegmentGrid,
    /// The same edges binned coarsely, for a whole fan of rays from one point.
    bins: SegmentBins,
    pub grid: ClearanceGrid,
    /// Tables derived from the map and built once (the planner's candidate views, the
    /// localiser's likelihood fields), shared by every match on it. The arena keeps them
    /// without knowing their types, so the floors above it can cache here without the arena
    /// importing them.
    derived: Mutex<Vec<Derived>>,
}

/// One derived table and the key it was built for (both type-erased).
type Derived = (Box<dyn Any + Send + Sync>, Arc<dyn Any + Send + Sync>);

impl Arena {
    pub fn new(def: MapDef) -> Arena {
        let mut vertices = Vec::new();
        let mut indices = Vec::new();
        let border = vec![
            Point2::new(0.0, 0.0),
            Point2::new(def.width, 0.0),
            Point2::new(def.width, def.height),
            Point2::new(0.0, def.height),
        ];
        for poly in std::iter::once(&border).chain(def.obstacles.iter()) {
            let base = vertices.len() as u32;
            let n = poly.len() as u32;
            vertices.extend(poly.iter().copied());
            indices.extend((0..n).map(|i| [base + i, base + (i + 1) % n]));
        }
        let walls = Polyline::new(vertices, Some(indices));
        let grid = ClearanceGrid::build(&def, &walls);
        let buckets = SegmentGrid::build(def.width, def.height, &walls);
        let bins = SegmentBins::build(def.width, def.height, &walls);
        Arena {
            def,
            walls,
            buckets,
            bins,
            grid,
            derived: Mutex::new(Vec::new()),
        }
    }

    /// The table of type `T` derived from this map for `key`, built by `build` on first use
    /// and shared afterwards (the candidate-view tables, the likelihood fields).
    ///
    /// Building can take tens to hundreds of milliseconds, so the server builds what a match
    /// needs off the async runtime before the match starts rather than in its first tick.
    pub fn derived<K, T>(&self, key: K, build: impl FnOnce(&Arena) -> T) -> Arc<T>
    where
        K: PartialEq + Send + Sync + 'static,
        T: Send + Sync + 'static,
    {
        // A poisoned lock only means another builder panicked; the list itself is intact.
        let mut tables = self.derived.lock().unwrap_or_else(|e| e.into_inner());
        let found = tables.iter().find_map(|(k, t)| {
            (k.downcast_ref::<K>() == Some(&key))
                .then(|| t.clone().downcast::<T>().ok())
                .flatten()
        });
        if let Some(table) = found {
            return table;
        }
        let table = Arc::new(build(self));
        tables.push((Box::new(key), table.clone()));
        table
    }

    pub fn width(&self) -> f32 {
        self.def.width
    }

    pub fn height(&self) -> f32 {
        self.def.height
    }

    /// Distance along `dir` (unit) from `origin` to the first wall, capped at `max`.
    ///
    /// The hot path of the simulation (181 rays per robot per tick): it walks the segment
    /// grid cell by cell (Amanatides–Woo) and stops at the first cell that holds a hit,
    /// about three times faster than the general BVH query ([`Arena::cast_ray_bvh`]).
    pub fn cast_ray(&self, origin: Point2<f32>, dir: Vector2<f32>, max: f32) -> f32 {
        self.buckets.cast(origin, dir, max)
    }

    /// [`Arena::cast_ray`] for every ray of a laser's fan from `origin`, into `out`: ray `i`
    /// is the unit vector `(xs[i], ys[i])`, beam `i` of `fan` turned to the unit vector
    /// `heading`. The same distances as one `cast_ray` a ray, bit for bit, in a fraction of
    /// the time: each wall near the origin is tested only against the rays within the angle
    /// it subtends.
    pub fn cast_fan(
        &self,
        origin: Point2<f32>,
        heading: Vector2<f32>,
        fan: &FanBins,
        rays: (&[f32], &[f32]),
        max: f32,
        out: &mut [f32],
    ) {
        self.bins.cast_fan(origin, heading, fan, rays, max, out)
    }

    /// [`Arena::cast_ray`] through parry's BVH: the reference the fast path is tested against.
    pub fn cast_ray_bvh(&self, origin: Point2<f32>, dir: Vector2<f32>, max: f32) -> f32 {
        self.walls
            .cast_local_ray(&Ray::new(origin, dir), max, false)
            .unwrap_or(max)
    }

    /// True when the straight segment from `a` to `b` crosses no wall.
    pub fn line_of_sight(&self, a: Point2<f32>, b: Point2<f32>) -> bool {
        let d = b - a;
        let len = d.norm();
        if len < 1e-6 {
            return !self.inside_obstacle(a);
        }
        self.walls
            .cast_local_ray(&Ray::new(a, d / len), len, false)
            .is_none()
    }

    /// The closest point of any wall to `p`.
    pub fn closest_wall_point(&self, p: Point2<f32>) -> Point2<f32> {
        self.walls.project_local_point(&p, false).point
    }

    /// True when `p` lies inside an obstacle polygon or outside the arena.
    pub fn inside_obstacle(&self, p: Point2<f32>) -> bool {
        if p.x <= 0.0 || p.y <= 0.0 || p.x >= self.def.width || p.y >= self.def.height {
            return true;
        }
        self.def
            .obstacles
            .iter()
            .any(|poly| point_in_polygon(p, poly))
    }

    /// Distance from `p` to the nearest wall, or 0 inside an obstacle.
    pub fn clearance(&self, p: Point2<f32>) -> f32 {
        if self.inside_obstacle(p) {
            0.0
        } else {
            (self.closest_wall_point(p) - p).norm()
        }
    }

    /// Bytes the arena holds on the heap for its walls, segment index and clearance grid
    /// (the tables derived later, such as view tables, are not counted).
    pub fn heap_bytes(&self) -> usize {
        let vertices: usize = self.def.obstacles.iter().map(Vec::len).sum::<usize>() + 4;
        // The polyline keeps vertices and index pairs, and a BVH of about two nodes per
        // segment; the definition keeps its own copy of the vertices.
        vertices * (2 * 8 + 8 + 2 * 64)
            + self.buckets.heap_bytes()
            + self.bins.heap_bytes()
            + self.grid.clearance.len() * std::mem::size_of::<f32>()
    }

    /// True when the clearance grid alone shows that no wall lies within `radius` of `p`: the
    /// distance from `p`'s cell centre to the nearest wall, less the way from `p` to that
    /// centre, bounds `p`'s own from below (distance to a set changes no faster than the
    /// point moves). False means "not shown", not "blocked": the cheap test that spares
    /// most discs the exact query through the wall hierarchy.
    pub fn surely_clear(&self, p: Point2<f32>, radius: f32) -> bool {
        /// Slack for the rounding of the grid's distances and of the exact query's.
        const SLACK: f32 = 1e-3;
        self.grid.cell_of(p).is_some_and(|c| {
            self.grid.clearance[c] - (p - self.grid.centre(c)).norm() >= radius + SLACK
        })
    }

    /// True when a disc of `radius` at `p` overlaps no wall or obstacle.
    pub fn disc_is_free(&self, p: Point2<f32>, radius: f32) -> bool {
        self.surely_clear(p, radius) || self.clearance(p) >= radius
    }
}

/// The lowest and highest corners of the box around `poly`'s vertices.
pub fn bounding_box(poly: &[Point2<f32>]) -> (Point2<f32>, Point2<f32>) {
    poly.iter().fold(
        (
            Point2::new(f32::MAX, f32::MAX),
            Point2::new(f32::MIN, f32::MIN),
        ),
        |(lo, hi), v| (lo.inf(v), hi.sup(v)),
    )
}

/// Even-odd point-in-polygon test (either winding).
pub fn point_in_polygon(p: Point2<f32>, poly: &[Point2<f32>]) -> bool {
    let mut inside = false;
    let n = poly.len();
    let mut j = n - 1;
    for i in 0..n {
        let (a, b) = (poly[i], poly[j]);
        if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// A regular grid over the arena; each cell stores the distance from its centre to the nearest
/// wall (0 inside obstacles). Navigation treats a cell as passable when a disc plus
/// [`NAV_MARGIN`] fits there.
#[derive(Debug, Clone)]
pub struct ClearanceGrid {
    pub cell: f32,
    pub cols: usize,
    pub rows: usize,
    pub clearance: Vec<f32>,
    /// Whether an agent's disc fits at each cell's centre (`clearance >= AGENT_RADIUS`): a
    /// byte a cell rather than a float, so the tracker's motion stage, which asks it for
    /// every particle every tick, reads a table a quarter the size.
    agent_fits: Vec<bool>,
    /// [`ClearanceGrid::passable`] for every cell, in a table with a closed border one cell
    /// wide (`cols + 2` a row): the start of every path search's table of open cells, built
    /// once per map rather than once per search.
    passable_bordered: Vec<bool>,
}

/// Upper bound on grid cells, so that a 500 m × 500 m map does not cost gigabytes.
const MAX_GRID_CELLS: f32 = 400_000.0;

impl ClearanceGrid {
    /// Cell size, columns and rows for a `width` × `height` arena: 10 cm cells, coarser on
    /// maps so big that there would be more than 400,000.
    pub fn shape(width: f32, height: f32) -> (f32, usize, usize) {
        let cell = (0.1f32).max((width * height / MAX_GRID_CELLS).sqrt());
        let cols = (width / cell).ceil().max(1.0) as usize;
        let rows = (height / cell).ceil().max(1.0) as usize;
        (cell, cols, rows)
    }

    fn build(def: &MapDef, walls: &Polyline) -> ClearanceGrid {
        let (cell, cols, rows) = Self::shape(def.width, def.height);
        let centre =
            |c: usize, r: usize| Point2::new((c as f32 + 0.5) * cell, (r as f32 + 0.5) * cell);
        // Each obstacle tests only the cells of its bounding box (grown by a millimetre
        // against rounding): no point outside the box is inside it, and testing every cell
        // against every polygon cost cells × vertices (seconds for a big map of many small
        // obstacles).
        let mut inside = vec![false; cols * rows];
        for poly in &def.obstacles {
            let (lo, hi) = bounding_box(poly);
            let first = |v: f32| ((v - 1e-3) / cell - 0.5).ceil().max(0.0) as usize;
            let last = |v: f32, n: usize| {
                let k = ((v + 1e-3) / cell - 0.5).floor();
                (k >= 0.0).then(|| (k as usize).min(n - 1))
            };
            let (Some(c1), Some(r1)) = (last(hi.x, cols), last(hi.y, rows)) else {
                continue;
            };
            for r in first(lo.y)..=r1 {
                for c in first(lo.x)..=c1 {
                    let k = r * cols + c;
                    if !inside[k] && point_in_polygon(centre(c, r), poly) {
                        inside[k] = true;
                    }
                }
            }
        }
        let mut clearance = vec![0.0; cols * rows];
        for r in 0..rows {
            for c in 0..cols {
                let p = centre(c, r);
                let inside = p.x >= def.width || p.y >= def.height || inside[r * cols + c];
                clearance[r * cols + c] = if inside {
                    0.0
                } else {
                    (walls.project_local_point(&p, false).point - p).norm()
                };
            }
        }
        let agent_fits = clearance.iter().map(|&d| d >= AGENT_RADIUS).collect();
        let mut grid = ClearanceGrid {
            cell,
            cols,
            rows,
            clearance,
            agent_fits,
            passable_bordered: Vec::new(),
        };
        let stride = cols + 2;
        let mut bordered = vec![false; stride * (rows + 2)];
        for r in 0..rows {
            let row = &mut bordered[(r + 1) * stride + 1..][..cols];
            for (c, open) in row.iter_mut().enumerate() {
                *open = grid.passable(r * cols + c);
            }
        }
        grid.passable_bordered = bordered;
        grid
    }

    pub fn len(&self) -> usize {
        self.clearance.len()
    }

    pub fn is_empty(&self) -> bool {
        self.clearance.is_empty()
    }

    /// The cell containing `p`, if inside the grid.
    pub fn cell_of(&self, p: Point2<f32>) -> Option<usize> {
        if !(p.x >= 0.0 && p.y >= 0.0) {
            return None;
        }
        let c = (p.x / self.cell) as usize;
        let r = (p.y / self.cell) as usize;
        (c < self.cols && r < self.rows).then_some(r * self.cols + c)
    }

    /// Whether each cell is passable, in a table with a closed border one cell wide: row `r`,
    /// column `c` at `(r + 1) × (cols + 2) + c + 1`.
    pub fn passable_bordered(&self) -> &[bool] {
        &self.passable_bordered
    }

    /// True when `p` is inside the grid and an agent's disc fits at its cell's centre.
    pub fn fits_agent(&self, p: Point2<f32>) -> bool {
        self.cell_of(p).is_some_and(|c| self.agent_fits[c])
    }

    /// True when an agent's disc fits at the centre of cell `idx` (`clearance >=
    /// AGENT_RADIUS`).
    pub fn agent_fits(&self, idx: usize) -> bool {
        self.agent_fits[idx]
    }

    pub fn centre(&self, idx: usize) -> Point2<f32> {
        let (r, c) = (idx / self.cols, idx % self.cols);
        Point2::new((c as f32 + 0.5) * self.cell, (r as f32 + 0.5) * self.cell)
    }

    /// True when an agent disc (with the navigation margin) fits at this cell's centre.
    pub fn passable(&self, idx: usize) -> bool {
        self.clearance[idx] >= AGENT_RADIUS + NAV_MARGIN
    }

    /// The passable cell nearest to `p` (searching outward ring by ring), if any within `max_rings`.
    pub fn nearest_passable(&self, p: Point2<f32>, max_rings: usize) -> Option<usize> {
        let c0 = ((p.x / self.cell) as isize).clamp(0, self.cols as isize - 1);
        let r0 = ((p.y / self.cell) as isize).clamp(0, self.rows as isize - 1);
        for ring in 0..=max_rings as isize {
            let mut best: Option<(f32, usize)> = None;
            for dr in -ring..=ring {
                for dc in -ring..=ring {
                    if dr.abs() != ring && dc.abs() != ring {
                        continue;
                    }
                    let (r, c) = (r0 + dr, c0 + dc);
                    if r < 0 || c < 0 || r >= self.rows as isize || c >= self.cols as isize {
                        continue;
                    }
                    let idx = r as usize * self.cols + c as usize;
                    if self.passable(idx) {
                        let d = (self.centre(idx) - p).norm_squared();
                        if best.is_none_or(|(bd, _)| d < bd) {
                            best = Some((d, idx));
                        }
                    }
                }
            }
            if let Some((_, idx)) = best {
                return Some(idx);
            }
        }
        None
    }
}

/// An empty 12 m × 6 m room with one robot spawn and one opponent spawn at (11, 3): the
/// fixture of the tracker's and the team's unit tests.
#[cfg(test)]
pub(crate) fn open_room(robot_spawn: [f32; 3]) -> Arena {
    Arena::new(MapDef {
        name: "open".into(),
        width: 12.0,
        height: 6.0,
        obstacles: vec![],
        robot_spawns: vec![robot_spawn],
        opponent_spawns: vec![Point2::new(11.0, 3.0)],
        landmarks: vec![],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(crate) fn square_room() -> Arena {
        Arena::new(MapDef {
            name: "room".into(),
            width: 10.0,
            height: 6.0,
            obstacles: vec![vec![
                Point2::new(4.0, 2.0),
                Point2::new(6.0, 2.0),
                Point2::new(6.0, 4.0),
                Point2::new(4.0, 4.0),
            ]],
            robot_spawns: vec![[1.0, 1.0, 0.0]],
            opponent_spawns: vec![Point2::new(9.0, 5.0)],
            landmarks: vec![],
        })
    }

    #[test]
    fn rays_stop_at_obstacles_and_border() {
        let a = square_room();
        let d = a.cast_ray(Point2::new(1.0, 3.0), Vector2::new(1.0, 0.0), 8.0);
        assert!((d - 3.0).abs() < 1e-4, "{d}");
        let d = a.cast_ray(Point2::new(1.0, 1.0), Vector2::new(0.0, 1.0), 8.0);
        assert!((d - 5.0).abs() < 1e-4, "{d}");
        let d = a.cast_ray(Point2::new(1.0, 1.0), Vector2::new(1.0, 0.0), 8.0);
        assert!((d - 8.0).abs() < 1e-4, "max range when nothing is hit: {d}");
    }

    #[test]
    fn the_fast_ray_cast_agrees_with_parry() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let a = square_room();
        for _ in 0..20_000 {
            let o = Point2::new(rng.random_range(0.01..9.99), rng.random_range(0.01..5.99));
            if a.inside_obstacle(o) {
                continue;
            }
            let ang: f32 = rng.random_range(0.0..std::f32::consts::TAU);
            let dir = Vector2::new(ang.cos(), ang.sin());
            let fast = a.cast_ray(o, dir, 8.0);
            let reference = a.cast_ray_bvh(o, dir, 8.0);
            // Grazing rays differ in the last f32 digits; the laser noise is 2 cm.
            assert!(
                (fast - reference).abs() < 3e-3,
                "{o:?} {ang}: {fast} vs {reference}"
            );
        }
        // Axis-aligned rays and rays along grid lines.
        for dir in [
            Vector2::new(1.0, 0.0),
            Vector2::new(0.0, -1.0),
            Vector2::new(-1.0, 0.0),
        ] {
            let o = Point2::new(2.0, 3.0);
            assert!((a.cast_ray(o, dir, 8.0) - a.cast_ray_bvh(o, dir, 8.0)).abs() < 1e-4);
        }
    }

    #[test]
    fn long_diagonal_walls_cost_cells_along_them_and_rays_still_find_them() {
        use rand::{RngExt, SeedableRng};
        // Thin parallel slivers across a 500 m map: their bounding boxes span the whole grid.
        let sliver = |x0: f32, y0: f32, x1: f32, y1: f32| {
            vec![
                Point2::new(x0, y0),
                Point2::new(x1, y1),
                Point2::new(x1 + 0.5, y1),
                Point2::new(x0 + 0.5, y0),
            ]
        };
        let a = Arena::new(MapDef {
            name: "diagonals".into(),
            width: 500.0,
            height: 500.0,
            obstacles: vec![
                sliver(10.0, 10.0, 480.0, 490.0),
                sliver(60.0, 10.0, 490.0, 440.0),
                sliver(10.0, 60.0, 430.0, 490.0),
            ],
            robot_spawns: vec![[5.0, 250.0, 0.0]],
            opponent_spawns: vec![Point2::new(495.0, 250.0)],
            landmarks: vec![],
        });
        // Twelve edges of up to 700 m on 1 m cells: a few thousand entries, where whole
        // bounding boxes took about a million.
        let entries = a.buckets.len();
        assert!(entries < 20_000, "{entries} segment index entries");
        // The same answers, bit for bit, as an index of whole bounding boxes.
        let boxes = SegmentGrid::by_bounding_boxes(a.def.width, a.def.height, &a.walls);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..20_000 {
            let o = Point2::new(rng.random_range(1.0..499.0), rng.random_range(1.0..499.0));
            let ang: f32 = rng.random_range(0.0..std::f32::consts::TAU);
            let dir = Vector2::new(ang.cos(), ang.sin());
            let (along, boxed) = (a.buckets.cast(o, dir, 300.0), boxes.cast(o, dir, 300.0));
            assert_eq!(
                along.to_bits(),
                boxed.to_bits(),
                "{o:?} {ang}: {along} vs {boxed}"
            );
        }
    }

    #[test]
    fn the_clearance_grid_is_what_testing_every_polygon_gives() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut obstacles: Vec<Vec<Point2<f32>>> = (0..60)
            .map(|_| {
                let (x, y) = (rng.random_range(1.0..37.0), rng.random_range(1.0..27.0));
                let s = rng.random_range(0.2..2.0);
                vec![
                    Point2::new(x, y),
                    Point2::new(x + s, y),
                    Point2::new(x + s, y + s),
                    Point2::new(x, y + s),
                ]
            })
            .collect();
        // A concave polygon and one touching the border.
        obstacles.push(vec![
            Point2::new(5.0, 5.0),
            Point2::new(15.0, 5.0),
            Point2::new(15.0, 15.0),
            Point2::new(10.0, 8.0),
            Point2::new(5.0, 15.0),
        ]);
        obstacles.push(vec![
            Point2::new(38.0, 0.0),
            Point2::new(40.0, 0.0),
            Point2::new(40.0, 30.0),
        ]);
        let def = MapDef {
            name: "scatter".into(),
            width: 40.0,
            height: 30.0,
            obstacles,
            robot_spawns: vec![[0.5, 0.5, 0.0]],
            opponent_spawns: vec![Point2::new(39.0, 29.0)],
            landmarks: vec![],
        };
        let a = Arena::new(def.clone());
        let g = &a.grid;
        for r in 0..g.rows {
            for c in 0..g.cols {
                let p = Point2::new((c as f32 + 0.5) * g.cell, (r as f32 + 0.5) * g.cell);
                let inside = p.x >= def.width
                    || p.y >= def.height
                    || def.obstacles.iter().any(|poly| point_in_polygon(p, poly));
                let expected = if inside {
                    0.0
                } else {
                    (a.walls.project_local_point(&p, false).point - p).norm()
                };
                let got = g.clearance[r * g.cols + c];
                assert_eq!(got.to_bits(), expected.to_bits(), "cell ({c}, {r})");
            }
        }
    }

    #[test]
    fn line_of_sight_and_clearance() {
        let a = square_room();
        assert!(!a.line_of_sight(Point2::new(1.0, 3.0), Point2::new(9.0, 3.0)));
        assert!(a.line_of_sight(Point2::new(1.0, 1.0), Point2::new(9.0, 1.0)));
        assert!(a.inside_obstacle(Point2::new(5.0, 3.0)));
        assert!((a.clearance(Point2::new(3.0, 3.0)) - 1.0).abs() < 1e-4);
        assert!(a.disc_is_free(Point2::new(3.0, 3.0), 0.25));
        assert!(!a.disc_is_free(Point2::new(0.1, 3.0), 0.25));
    }

    #[test]
    fn surely_clear_never_says_so_of_a_disc_that_touches_a_wall() {
        use rand::{RngExt, SeedableRng};
        let a = square_room();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let (mut shown, mut free) = (0, 0);
        for _ in 0..20_000 {
            let p = Point2::new(rng.random_range(-0.5..10.5), rng.random_range(-0.5..6.5));
            let radius = rng.random_range(0.05..1.0f32);
            let exact = a.clearance(p) >= radius;
            if a.surely_clear(p, radius) {
                assert!(exact, "{p:?} at {radius} m: clearance {}", a.clearance(p));
                shown += 1;
            }
            free += exact as usize;
        }
        // It spares the exact query for most discs that are free.
        assert!(shown * 10 > free * 8, "{shown} of {free}");
    }

    #[test]
    fn grid_marks_obstacles_impassable() {
        let a = square_room();
        let inside = a.grid.cell_of(Point2::new(5.0, 3.0)).unwrap();
        assert!(!a.grid.passable(inside));
        let open = a.grid.cell_of(Point2::new(2.0, 3.0)).unwrap();
        assert!(a.grid.passable(open));
        let near = a.grid.nearest_passable(Point2::new(5.0, 3.0), 30).unwrap();
        assert!(a.grid.passable(near));
    }

    #[test]
    fn a_fan_cast_gives_every_ray_cast_bit_for_bit() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        // Rooms of random rectangles and thin, tilted walls; a 180° laser and a wider one.
        for map in 0..6 {
            let (w, h) = (
                rng.random_range(8.0..40.0f32),
                rng.random_range(6.0..30.0f32),
            );
            let mut obstacles = Vec::new();
            for _ in 0..rng.random_range(3..40) {
                let (x, y) = (
                    rng.random_range(0.0..w - 1.0),
                    rng.random_range(0.0..h - 1.0),
                );
                let (dx, dy) = (rng.random_range(0.1..4.0f32), rng.random_range(0.1..4.0f32));
                let tilt = rng.random_range(-1.0..1.0f32);
                obstacles.push(vec![
                    Point2::new(x, y),
                    Point2::new((x + dx).min(w), (y + tilt).clamp(0.0, h)),
                    Point2::new((x + dx).min(w), (y + tilt + dy).clamp(0.0, h)),
                    Point2::new(x, (y + dy).min(h)),
                ]);
            }
            let a = Arena::new(MapDef {
                name: format!("random{map}"),
                width: w,
                height: h,
                obstacles,
                robot_spawns: vec![[0.5, 0.5, 0.0]],
                opponent_spawns: vec![Point2::new(w - 0.5, h - 0.5)],
                landmarks: vec![],
            });
            for fan in 0..300 {
                let o = Point2::new(
                    rng.random_range(0.01..w - 0.01),
                    rng.random_range(0.01..h - 0.01),
                );
                let theta = rng.random_range(-4.0..4.0f32);
                let (n, fov) = if fan % 2 == 0 {
                    (181, std::f32::consts::PI)
                } else {
                    (64, 5.5)
                };
                let dirs: Vec<Vector2<f32>> = (0..n)
                    .map(|i| {
                        let b = theta - fov / 2.0 + fov * i as f32 / (n - 1) as f32;
                        Vector2::new(b.cos(), b.sin())
                    })
                    .collect();
                let heading = Vector2::new(theta.cos(), theta.sin());
                let fan_bins = FanBins::new(n, fov);
                let mut out = vec![0.0; n];
                let xs: Vec<f32> = dirs.iter().map(|d| d.x).collect();
                let ys: Vec<f32> = dirs.iter().map(|d| d.y).collect();
                a.cast_fan(o, heading, &fan_bins, (&xs, &ys), 8.0, &mut out);
                for (i, d) in dirs.iter().enumerate() {
                    let want = a.cast_ray(o, *d, 8.0);
                    assert_eq!(
                        out[i].to_bits(),
                        want.to_bits(),
                        "map {map}, fan {fan}, beam {i}: {} against {want}",
                        out[i]
                    );
                }
            }
        }
    }
}
