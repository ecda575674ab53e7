//! What a robot could see from each candidate destination: the planner's precomputed
//! laser footprints.
//!
//! A [`ViewTable`] lists candidate poses — the centres of a coarse grid of reachable points,
//! each with a few evenly spaced headings — and, for each pose, the cells of a *scoring grid*
//! (coarser than the clearance grid, finer than the candidates) whose centre its laser would
//! see against the static map: within range, inside the field of view, and not behind a wall.
//! Each visible cell carries how centred it is in the view (the cosine of its bearing off
//! the heading), so that the planner can prefer poses that look straight at what they search.
//!
//! Building one costs a ray cast per (position, cell in range) — tens to hundreds of
//! milliseconds on the shipped maps — so an [`Arena`] keeps the tables it has built
//! ([`ViewTable::of`], cached by `Arena::derived`) and every match on that map shares them.

use nalgebra::{Point2, Vector2};

use std::sync::Arc;

use crate::sim::arena::Arena;
use crate::sim::wrap_angle;

/// The parameters a table is built for; matches with other laser settings get their own.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViewSpec {
    /// Spacing of candidate positions (metres).
    pub spacing: f32,
    /// Number of headings per position, evenly spaced from 0.
    pub headings: usize,
    /// Side of a scoring cell (metres).
    pub cell: f32,
    pub fov: f32,
    pub range: f32,
}

#[derive(Debug)]
pub struct ViewTable {
    pub spec: ViewSpec,
    /// Scoring grid dimensions (cells of `spec.cell`).
    pub cols: usize,
    pub rows: usize,
    /// Candidate positions; pose `k` is position `k / headings`, heading `k % headings`.
    pub positions: Vec<Point2<f32>>,
    /// `starts[k]..starts[k + 1]` indexes `cells` and `centring` for pose `k`.
    starts: Vec<u32>,
    cells: Vec<u32>,
    centring: Vec<f32>,
}

/// Candidate positions: one per cell of a `spacing` grid that has room for an agent disc —
/// the cell's centre, or when a wall covers it the passable point nearest to it inside the
/// cell, so that corridors narrower than the spacing and strips along the border still get
/// candidates.
pub fn candidate_points(arena: &Arena, spacing: f32) -> Vec<Point2<f32>> {
    let grid = &arena.grid;
    let cols = (arena.width() / spacing).ceil() as usize;
    let rows = (arena.height() / spacing).ceil() as usize;
    let rings = ((spacing / 2.0) / grid.cell).floor() as usize;
    let mut out = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            let centre = Point2::new((c as f32 + 0.5) * spacing, (r as f32 + 0.5) * spacing);
            if grid.cell_of(centre).is_some_and(|i| grid.passable(i)) {
                out.push(centre);
                continue;
            }
            let inside = |p: Point2<f32>| {
                (p.x - centre.x).abs() <= spacing / 2.0 && (p.y - centre.y).abs() <= spacing / 2.0
            };
            if let Some(i) = grid.nearest_passable(centre, rings)
                && inside(grid.centre(i))
            {
                out.push(grid.centre(i));
            }
        }
    }
    out
}

impl ViewTable {
    /// The table for `spec` on `arena`, built on first use and shared afterwards.
    pub fn of(arena: &Arena, spec: ViewSpec) -> Arc<ViewTable> {
        arena.derived(spec, |arena| ViewTable::build(arena, spec))
    }

    pub fn build(arena: &Arena, spec: ViewSpec) -> ViewTable {
        let cols = (arena.width() / spec.cell).ceil().max(1.0) as usize;
        let rows = (arena.height() / spec.cell).ceil().max(1.0) as usize;
        let positions = candidate_points(arena, spec.spacing);
        let half_fov = spec.fov * 0.5;
        let reach = (spec.range / spec.cell).ceil() as isize + 1;
        let mut starts = Vec::with_capacity(positions.len() * spec.headings + 1);
        let mut cells = Vec::new();
        let mut centring = Vec::new();
        starts.push(0);
        // (cell, bearing) of every cell visible from the current position, any heading.
        let mut around: Vec<(u32, f32)> = Vec::new();
        for &p in &positions {
            around.clear();
            let (pc, pr) = ((p.x / spec.cell) as isize, (p.y / spec.cell) as isize);
            for r in (pr - reach).max(0)..(pr + reach + 1).min(rows as isize) {
                for c in (pc - reach).max(0)..(pc + reach + 1).min(cols as isize) {
                    let centre =
                        Point2::new((c as f32 + 0.5) * spec.cell, (r as f32 + 0.5) * spec.cell);
                    let d: Vector2<f32> = centre - p;
                    let dist = d.norm();
                    if dist > spec.range {
                        continue;
                    }
                    if dist > 1e-4 && arena.cast_ray(p, d / dist, dist) < dist - 1e-3 {
                        continue;
                    }
                    around.push(((r as usize * cols + c as usize) as u32, d.y.atan2(d.x)));
                }
            }
            for h in 0..spec.headings {
                let heading = heading_angle(spec.headings, h);
                for &(cell, bearing) in &around {
                    let off = wrap_angle(bearing - heading);
                    if off.abs() <= half_fov {
                        cells.push(cell);
                        centring.push(off.cos().max(0.0));
                    }
                }
                starts.push(cells.len() as u32);
            }
        }
        ViewTable {
            spec,
            cols,
            rows,
            positions,
            starts,
            cells,
            centring,
        }
    }

    /// Number of candidate poses.
    pub fn len(&self) -> usize {
        self.starts.len() - 1
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The position and heading of pose `k`.
    pub fn pose(&self, k: usize) -> (Point2<f32>, f32) {
        let h = self.spec.headings;
        (self.positions[k / h], heading_angle(h, k % h))
    }

    /// The scoring cells pose `k` sees, and how centred each is (cosine of its bearing).
    pub fn view(&self, k: usize) -> (&[u32], &[f32]) {
        let (a, b) = (self.starts[k] as usize, self.starts[k + 1] as usize);
        (&self.cells[a..b], &self.centring[a..b])
    }

    /// The scoring cell containing `p`, if inside the arena.
    pub fn cell_of(&self, p: Point2<f32>) -> Option<usize> {
        if !(p.x >= 0.0 && p.y >= 0.0) {
            return None;
        }
        let c = (p.x / self.spec.cell) as usize;
        let r = (p.y / self.spec.cell) as usize;
        (c < self.cols && r < self.rows).then_some(r * self.cols + c)
    }

    pub fn cell_count(&self) -> usize {
        self.cols * self.rows
    }

    /// Bytes held, for the record.
    pub fn memory(&self) -> usize {
        self.starts.len() * 4 + self.cells.len() * 4 + self.centring.len() * 4
    }
}

/// Heading `h` of `headings` evenly spaced ones, in (-π, π].
pub fn heading_angle(headings: usize, h: usize) -> f32 {
    wrap_angle(h as f32 * std::f32::consts::TAU / headings as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::arena::MapDef;

    fn two_rooms() -> Arena {
        // 10 × 5 with a wall at x = 5 from y = 0 to 4 (a gap at the top).
        Arena::new(MapDef {
            name: "t".into(),
            width: 10.0,
            height: 5.0,
            obstacles: vec![vec![
                Point2::new(4.9, 0.0),
                Point2::new(5.1, 0.0),
                Point2::new(5.1, 4.0),
                Point2::new(4.9, 4.0),
            ]],
            robot_spawns: vec![[1.0, 1.0, 0.0]],
            opponent_spawns: vec![Point2::new(8.0, 1.0)],
            landmarks: vec![],
        })
    }

    fn spec() -> ViewSpec {
        ViewSpec {
            spacing: 1.0,
            headings: 8,
            cell: 0.5,
            fov: std::f32::consts::PI,
            range: 8.0,
        }
    }

    fn pose_at(t: &ViewTable, p: Point2<f32>, heading: usize) -> usize {
        let i = t
            .positions
            .iter()
            .position(|q| (q - p).norm() < 1e-3)
            .expect("a candidate there");
        i * t.spec.headings + heading
    }

    #[test]
    fn a_pose_sees_ahead_not_behind_and_not_through_walls() {
        let arena = two_rooms();
        let t = ViewTable::build(&arena, spec());
        // At (2.5, 1.5) facing +x (heading 0): sees (4.25, 1.25), not (0.75, 1.25) behind it,
        // and not (6.25, 1.25) behind the wall.
        let k = pose_at(&t, Point2::new(2.5, 1.5), 0);
        let (cells, centring) = t.view(k);
        let has = |p: Point2<f32>| cells.contains(&(t.cell_of(p).unwrap() as u32));
        assert!(has(Point2::new(4.25, 1.25)));
        assert!(!has(Point2::new(0.75, 1.25)));
        assert!(!has(Point2::new(6.25, 1.25)));
        assert!(centring.iter().all(|c| (0.0..=1.0).contains(c)));
        // Facing -x (heading 4) it sees behind.
        let (cells, _) = t.view(pose_at(&t, Point2::new(2.5, 1.5), 4));
        assert!(cells.contains(&(t.cell_of(Point2::new(0.75, 1.25)).unwrap() as u32)));
    }

    /// Review finding: a corridor narrower than the candidate spacing, off the grid's
    /// centres, had no candidate in it, so no robot was ever sent into it.
    #[test]
    fn a_narrow_corridor_off_the_grid_centres_still_gets_candidates() {
        // 8 × 3 m; a wall fills y ∈ [0, 1.8] and y ∈ [2.7, 3] leaves a 0.9 m corridor whose
        // middle (y = 2.25) is no 1 m grid centre.
        let arena = Arena::new(MapDef {
            name: "narrow".into(),
            width: 8.0,
            height: 3.0,
            obstacles: vec![
                vec![
                    Point2::new(0.0, 0.0),
                    Point2::new(8.0, 0.0),
                    Point2::new(8.0, 1.8),
                    Point2::new(0.0, 1.8),
                ],
                vec![
                    Point2::new(0.0, 2.7),
                    Point2::new(8.0, 2.7),
                    Point2::new(8.0, 3.0),
                    Point2::new(0.0, 3.0),
                ],
            ],
            robot_spawns: vec![[1.0, 2.25, 0.0]],
            opponent_spawns: vec![Point2::new(7.0, 2.25)],
            landmarks: vec![],
        });
        let points = candidate_points(&arena, 1.0);
        assert!(points.len() >= 6, "{points:?}");
        for p in &points {
            assert!(
                arena.grid.passable(arena.grid.cell_of(*p).unwrap()),
                "{p:?}"
            );
        }
    }

    #[test]
    fn every_pose_has_a_view() {
        let arena = two_rooms();
        let t = ViewTable::build(&arena, spec());
        assert_eq!(t.len(), t.positions.len() * 8);
        assert!((0..t.len()).all(|k| !t.view(k).0.is_empty()));
    }
}
