//! Shortest paths on the arena's clearance grid, shared by robots and opponent bots.
//!
//! [`DistanceField`] runs Dijkstra (as Dial's bucket queue) from one cell over the cells where a disc fits (8-connected,
//! step costs 12 and 17 per 12ths of a cell, √2 within 0.2%): one run answers "how far is every reachable point" (used to score
//! candidate destinations by travel time) and "what is the path to this one" (predecessor
//! links, then string-pulled with [`smooth`] so agents walk straight lines, not staircases).
//! [`path_within`] finds one path with its work bounded (it stops at the goal and gives up
//! past a budget), for orders given from outside. [`PathFollower`] walks a path waypoint by
//! waypoint.

use nalgebra::Point2;

use crate::sim::arena::ClearanceGrid;
use dial::{Exhausted, OpenCells, STRAIGHT, dial, start_cell, units_within};
pub use dial::{Unwatched, Watch};
pub use follow::{PathFollower, steer, turn_to};

mod dial;
mod follow;
mod ways;

pub use ways::{ReachCache, ReachField, WayMap};

/// Travel distances from one start cell to every reachable cell.
#[derive(Debug, Clone)]
pub struct DistanceField {
    pub start: usize,
    pub dist: Vec<f32>,
    prev: Vec<u32>,
}

impl DistanceField {
    /// Dijkstra from the passable cell nearest to `from`; `None` when no passable cell is near.
    pub fn from_point(grid: &ClearanceGrid, from: Point2<f32>) -> Option<DistanceField> {
        let start = start_cell(grid, from)?;
        Some(DistanceField::from_cell(grid, start))
    }

    pub fn from_cell(grid: &ClearanceGrid, start: usize) -> DistanceField {
        DistanceField::from_cell_avoiding(grid, start, &[])
    }

    /// The field from `from` out to `reach` metres of travel only: every cell within `reach`
    /// has its distance and path exactly as [`DistanceField::from_point`] gives them; every
    /// other cell reads as unreachable or farther than `reach`. The search stops there, so a
    /// short reach on a big map costs a fraction of the whole field.
    pub fn from_point_within(
        grid: &ClearanceGrid,
        from: Point2<f32>,
        reach: f32,
    ) -> Option<DistanceField> {
        let start = start_cell(grid, from)?;
        let limit = units_within(reach, grid.cell / STRAIGHT as f32);
        Some(DistanceField::search(
            grid,
            start,
            &OpenCells::new(grid, &[]),
            limit,
        ))
    }

    /// Dijkstra from `from` that also treats the discs `avoid` (centre, radius) as walls:
    /// how an agent replans around teammates that block its way.
    pub fn from_point_avoiding(
        grid: &ClearanceGrid,
        from: Point2<f32>,
        avoid: &[(Point2<f32>, f32)],
    ) -> Option<DistanceField> {
        let start = start_cell(grid, from)?;
        Some(DistanceField::from_cell_avoiding(grid, start, avoid))
    }

    /// Dial's algorithm: step costs are small integers (12 straight, 17 diagonal: √2 within
    /// 0.2%), so a ring of buckets replaces the binary heap and a field over the 38,400
    /// cells of `office` costs about a millisecond instead of three.
    fn from_cell_avoiding(
        grid: &ClearanceGrid,
        start: usize,
        avoid: &[(Point2<f32>, f32)],
    ) -> DistanceField {
        DistanceField::search(grid, start, &OpenCells::new(grid, avoid), u32::MAX)
    }

    /// The field over `open` of every cell up to `limit` travel units away (`u32::MAX`: all).
    fn search(grid: &ClearanceGrid, start: usize, open: &OpenCells, limit: u32) -> DistanceField {
        // With no goal and no bound on the work, the search settles every cell within reach.
        DistanceField::search_watched(grid, start, open, limit, &mut Unwatched)
    }

    /// [`DistanceField::from_point_avoiding`] that grows only as long as `watch` lets it: the
    /// cells it settled have their distances and paths exactly as the whole field gives
    /// them; the cells beyond read as unreachable or farther than they are. `watch` sees
    /// travel in the search's own units: [`DistanceField::metres_of`] turns them into metres
    /// as the field does.
    pub fn from_point_watched(
        grid: &ClearanceGrid,
        from: Point2<f32>,
        avoid: &[(Point2<f32>, f32)],
        watch: &mut impl Watch,
    ) -> Option<DistanceField> {
        let start = start_cell(grid, from)?;
        let open = OpenCells::new(grid, avoid);
        Some(DistanceField::search_watched(
            grid,
            start,
            &open,
            u32::MAX,
            watch,
        ))
    }

    /// Metres of `units` of travel on `grid`, as a field's `dist` holds them.
    pub fn metres_of(grid: &ClearanceGrid, units: u32) -> f32 {
        units as f32 * (grid.cell / STRAIGHT as f32)
    }

    fn search_watched(
        grid: &ClearanceGrid,
        start: usize,
        open: &OpenCells,
        limit: u32,
        watch: &mut impl Watch,
    ) -> DistanceField {
        let (units, prev) = match dial(start, open, None, limit, &mut u64::MAX.clone(), watch) {
            Ok(search) | Err(Exhausted(search)) => search,
        };
        let scale = grid.cell / STRAIGHT as f32;
        let dist = units
            .iter()
            .map(|&u| {
                if u == u32::MAX {
                    f32::INFINITY
                } else {
                    u as f32 * scale
                }
            })
            .collect();
        DistanceField { start, dist, prev }
    }

    pub fn reachable(&self, cell: usize) -> bool {
        self.dist[cell].is_finite()
    }

    /// Cells from the start to `goal` (inclusive), or `None` when unreachable.
    pub fn cells_to(&self, goal: usize) -> Option<Vec<usize>> {
        if !self.reachable(goal) {
            return None;
        }
        let mut cells = vec![goal];
        let mut at = goal;
        while at != self.start {
            at = self.prev[at] as usize;
            cells.push(at);
        }
        cells.reverse();
        Some(cells)
    }

    /// For every cell, the metres of its shortest path from the start that run through
    /// `narrow` cells (see [`narrow_cells`]); infinite for unreachable cells. One pass over
    /// the predecessor tree, each cell's sum built on its predecessor's, so all cells cost
    /// about what one long path would.
    pub fn narrow_metres(&self, narrow: &[bool]) -> Vec<f32> {
        let n = self.dist.len();
        let mut out = vec![f32::NAN; n];
        out[self.start] = 0.0;
        let mut stack = Vec::new();
        for c in 0..n {
            if !self.reachable(c) || !out[c].is_nan() {
                continue;
            }
            let mut at = c;
            while out[at].is_nan() {
                stack.push(at);
                at = self.prev[at] as usize;
            }
            let mut acc = out[at];
            while let Some(x) = stack.pop() {
                if narrow.get(x).copied().unwrap_or(false) {
                    acc += self.dist[x] - self.dist[self.prev[x] as usize];
                }
                out[x] = acc;
            }
        }
        for v in &mut out {
            if v.is_nan() {
                *v = f32::INFINITY;
            }
        }
        out
    }

    /// A smoothed path of waypoints from `from` to the centre of `goal`.
    pub fn path_to(
        &self,
        grid: &ClearanceGrid,
        from: Point2<f32>,
        goal: usize,
    ) -> Option<Vec<Point2<f32>>> {
        let cells = self.cells_to(goal)?;
        let mut pts = Vec::with_capacity(cells.len() + 1);
        pts.push(from);
        pts.extend(cells.iter().map(|&c| grid.centre(c)));
        Some(smooth(grid, &pts))
    }
}

/// Units of [`path_within`]'s work that setting a search up over a grid of `cells` takes
/// (its tables are filled once per search; a cell set up costs about an eighth of one
/// settled).
pub fn search_setup_work(cells: usize) -> u64 {
    cells as u64 / 8 + 1
}

/// A search ran out of its budget of work.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the path search ran out of its budget")]
pub struct OverBudget;

/// Takes `units` of `work`, or none when fewer are left.
fn charge(work: &mut u64, units: u64) -> Result<(), OverBudget> {
    *work = work.checked_sub(units).ok_or(OverBudget)?;
    Ok(())
}

/// The smoothed path from `from` to the centre of `goal`, as
/// `DistanceField::from_point(grid, from)?.path_to(grid, from, goal)` finds it, with its
/// work bounded: the set-up ([`search_setup_work`]), each cell the search settles before
/// it reaches the goal and each point string pulling tests take one unit of `work`.
/// `Ok(None)` when no path exists; [`OverBudget`] when the work would exceed what is left.
pub fn path_within(
    grid: &ClearanceGrid,
    from: Point2<f32>,
    goal: usize,
    work: &mut u64,
) -> Result<Option<Vec<Point2<f32>>>, OverBudget> {
    let Some(start) = start_cell(grid, from) else {
        return Ok(None);
    };
    charge(work, search_setup_work(grid.len()))?;
    let open = OpenCells::new(grid, &[]);
    let (units, prev) =
        dial(start, &open, Some(goal), u32::MAX, work, &mut Unwatched).map_err(|_| OverBudget)?;
    if units.get(goal).is_none_or(|&u| u == u32::MAX) {
        return Ok(None);
    }
    let mut cells = vec![goal];
    let mut at = goal;
    while at != start {
        at = prev[at] as usize;
        cells.push(at);
    }
    cells.reverse();
    let mut pts = Vec::with_capacity(cells.len() + 1);
    pts.push(from);
    pts.extend(cells.iter().map(|&c| grid.centre(c)));
    smooth_within(grid, &pts, work).map(Some)
}

/// Cells of narrow passages: passable cells with no cell of clearance `half_width` or more
/// within `reach` metres (a square window). A cell's own clearance is not enough: shortest
/// paths hug corners, so every path through a wide room would pass low-clearance cells, but
/// a short step off such a path is roomy; in a passage narrower than `2 · half_width` even
/// the middle is close to a wall. Keep `reach` well under `half_width`, or the room in
/// front of a door in a thin wall makes the door itself look wide.
pub fn narrow_cells(grid: &ClearanceGrid, half_width: f32, reach: f32) -> Vec<bool> {
    let k = (reach / grid.cell).round().max(0.0) as usize;
    let (cols, rows) = (grid.cols, grid.rows);
    // Separable max filter over a (2k+1)² square: rows, then columns.
    let mut across = vec![0.0f32; grid.len()];
    for r in 0..rows {
        for c in 0..cols {
            let (a, b) = (c.saturating_sub(k), (c + k).min(cols - 1));
            across[r * cols + c] = grid.clearance[r * cols + a..=r * cols + b]
                .iter()
                .fold(f32::NEG_INFINITY, |m, &v| m.max(v));
        }
    }
    (0..grid.len())
        .map(|idx| {
            let (r, c) = (idx / cols, idx % cols);
            let (a, b) = (r.saturating_sub(k), (r + k).min(rows - 1));
            grid.passable(idx) && (a..=b).all(|rr| across[rr * cols + c] < half_width)
        })
        .collect()
}

/// True when every point of the segment `a`–`b` lies in a passable cell (sampled at half-cell steps).
pub fn segment_passable(grid: &ClearanceGrid, a: Point2<f32>, b: Point2<f32>) -> bool {
    let len = (b - a).norm();
    let steps = (len / (grid.cell * 0.5)).ceil().max(1.0) as usize;
    (0..=steps).all(|k| {
        let p = a + (b - a) * (k as f32 / steps as f32);
        grid.cell_of(p).is_some_and(|c| grid.passable(c))
    })
}

/// String-pulls a path: keeps only the waypoints needed for straight, passable legs.
/// The first point (the agent's own position) is always kept, even if it is off the grid.
pub fn smooth(grid: &ClearanceGrid, pts: &[Point2<f32>]) -> Vec<Point2<f32>> {
    smooth_within(grid, pts, &mut u64::MAX.clone()).unwrap_or_else(|_| pts.to_vec())
}

/// [`smooth`], each point it tests taking one unit of `work`.
fn smooth_within(
    grid: &ClearanceGrid,
    pts: &[Point2<f32>],
    work: &mut u64,
) -> Result<Vec<Point2<f32>>, OverBudget> {
    if pts.len() <= 2 {
        return Ok(pts.to_vec());
    }
    let mut out = vec![pts[0]];
    let mut anchor = 1; // the first grid point; legs are checked from grid points only
    out.push(pts[1]);
    while anchor < pts.len() - 1 {
        let mut far = anchor + 1;
        for j in (anchor + 1..pts.len()).rev() {
            if segment_passable_within(grid, pts[anchor], pts[j], work)? {
                far = j;
                break;
            }
        }
        out.push(pts[far]);
        anchor = far;
    }
    // Drop the first grid point when the agent can go straight past it.
    if out.len() > 2 && segment_passable_within(grid, out[0], out[2], work)? {
        out.remove(1);
    }
    Ok(out)
}

/// [`segment_passable`], each point tested taking one unit of `work`.
fn segment_passable_within(
    grid: &ClearanceGrid,
    a: Point2<f32>,
    b: Point2<f32>,
    work: &mut u64,
) -> Result<bool, OverBudget> {
    let len = (b - a).norm();
    let steps = (len / (grid.cell * 0.5)).ceil().max(1.0) as usize;
    for k in 0..=steps {
        charge(work, 1)?;
        let p = a + (b - a) * (k as f32 / steps as f32);
        if !grid.cell_of(p).is_some_and(|c| grid.passable(c)) {
            return Ok(false);
        }
    }
    Ok(true)
}

#[cfg(test)]
mod tests;
