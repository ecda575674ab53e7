//! Dial's algorithm on the clearance grid: the search under [`super::DistanceField`] and
//! [`super::path_within`]. Step costs are small integers, so a ring of buckets replaces the
//! binary heap.

use nalgebra::Point2;

use crate::sim::arena::ClearanceGrid;

/// Step costs in twelfths of a cell: straight, and diagonal (√2 within 0.2%).
pub(super) const STRAIGHT: u32 = 12;
const DIAGONAL: u32 = 17;

/// No predecessor.
const NONE: u32 = u32::MAX;

/// Travel units (twelfths of a cell) and predecessors of one search.
pub(super) type Search = (Vec<u32>, Vec<u32>);

/// A bounded search ran out of work (what it had settled so far).
#[derive(Debug)]
pub(super) struct Exhausted(pub(super) Search);

/// The cells a search may enter: passable and outside every disc to avoid. Held with a closed
/// border one cell wide around the grid, so that every cell the search settles has all eight
/// neighbours in the table: the search then needs no bounds checks, and no division to find
/// a cell's row and column (the two took about half of its time).
pub(super) struct OpenCells {
    /// Columns plus the border's two.
    pub(super) stride: usize,
    pub(super) open: Vec<bool>,
}

impl OpenCells {
    pub(super) fn new(grid: &ClearanceGrid, avoid: &[(Point2<f32>, f32)]) -> OpenCells {
        let stride = grid.cols + 2;
        let open = grid.passable_bordered().to_vec();
        let mut cells = OpenCells { stride, open };
        for &(p, radius) in avoid {
            cells.close_disc(grid, p, radius);
        }
        cells
    }

    /// The passable cells of a window of `grid`, `cols` × `rows` cells from column `col0`
    /// and row `row0`, with a closed border around the window: a search in it indexes
    /// cells by the window's rows and columns and never leaves it.
    pub(super) fn window(
        grid: &ClearanceGrid,
        col0: usize,
        row0: usize,
        cols: usize,
        rows: usize,
    ) -> OpenCells {
        let stride = cols + 2;
        let whole = grid.passable_bordered();
        let whole_stride = grid.cols + 2;
        let mut open = vec![false; stride * (rows + 2)];
        for r in 0..rows {
            let from = (row0 + r + 1) * whole_stride + col0 + 1;
            let to = (r + 1) * stride + 1;
            open[to..to + cols].copy_from_slice(&whole[from..from + cols]);
        }
        OpenCells { stride, open }
    }

    /// Columns and cells of the grid (or window) the table covers.
    fn shape(&self) -> (usize, usize) {
        let cols = self.stride - 2;
        let rows = self.open.len() / self.stride - 2;
        (cols, cols * rows)
    }

    /// Closes the cells whose centre lies inside the disc: those of its bounding box (a cell
    /// wider on each side, against rounding) that fail `|centre − p|² ≥ radius²`. Only the
    /// box is tested: no centre outside it can pass.
    fn close_disc(&mut self, grid: &ClearanceGrid, p: Point2<f32>, radius: f32) {
        let (cols, rows) = (grid.cols, grid.rows);
        let span = |lo: f32, hi: f32, n: usize| -> (usize, usize) {
            if !(lo.is_finite() && hi.is_finite()) {
                return (0, n - 1); // no box to trust: test them all
            }
            let first = (lo / grid.cell - 1.5).floor().clamp(0.0, (n - 1) as f32) as usize;
            let last = (hi / grid.cell + 0.5).ceil().clamp(0.0, (n - 1) as f32) as usize;
            (first, last)
        };
        let (c0, c1) = span(p.x - radius, p.x + radius, cols);
        let (r0, r1) = span(p.y - radius, p.y + radius, rows);
        for r in r0..=r1 {
            for c in c0..=c1 {
                let idx = r * cols + c;
                let outside = (grid.centre(idx) - p).norm_squared() >= radius * radius;
                if !outside {
                    self.open[(r + 1) * self.stride + c + 1] = false;
                }
            }
        }
    }
}

/// What a caller follows of a search as it grows: the cells it settles, and whether it should
/// go on to the next distance. The search asks before settling the cells `units` away, so a
/// caller that says no leaves every cell nearer settled (final units and predecessors) and
/// every other one unreached or with more units than it will finally have.
pub trait Watch {
    /// Whether [`Watch::settled`] reads where a cell was reached from (looking it up costs
    /// the search a little on every cell: a watch that ignores it says no).
    const READS_FROM: bool = true;
    /// `cell` has its final `units`, reached from `from` (a cell and its units; `None` for
    /// the start), its final predecessor.
    fn settled(&mut self, cell: usize, units: u32, from: Option<(usize, u32)>);
    /// Whether to settle the cells `units` away.
    fn go_on(&mut self, units: u32) -> bool;
}

/// Watches nothing and lets the search run to its end: the whole field.
pub struct Unwatched;

impl Watch for Unwatched {
    const READS_FROM: bool = false;
    #[inline(always)]
    fn settled(&mut self, _: usize, _: u32, _: Option<(usize, u32)>) {}
    #[inline(always)]
    fn go_on(&mut self, _: u32) -> bool {
        true
    }
}

/// Dial's algorithm from `start` over the `open` cells (of the grid, or of a window of it). With a `goal` it stops once the goal
/// is settled: every cell on the goal's shortest path was settled before it, and a cell's
/// predecessor changes only on a strictly shorter way, so the path is the one a full search
/// finds. Each settled cell takes one unit of `work`; none left, it gives up. It also stops
/// once every cell within `limit` units is settled: those have their final units, and every
/// other cell holds `u32::MAX` or more than `limit`; and where `watch` says so.
pub(super) fn dial<W: Watch>(
    start: usize,
    open: &OpenCells,
    goal: Option<usize>,
    limit: u32,
    work: &mut u64,
    watch: &mut W,
) -> Result<Search, Exhausted> {
    const RING: usize = DIAGONAL as usize + 1;
    let (cols, n) = open.shape();
    let stride = open.stride;
    let open = &open.open[..];
    let mut units = vec![u32::MAX; n];
    let mut prev = vec![NONE; n];
    // Each entry: a cell's index in the grid and in the bordered table.
    let mut buckets: Vec<Vec<(u32, u32)>> = vec![Vec::new(); RING];
    units[start] = 0;
    let bordered = |idx: usize| (idx / cols + 1) * stride + idx % cols + 1;
    buckets[0].push((start as u32, bordered(start) as u32));
    let mut pending = 1usize;
    let mut d: u32 = 0;
    while pending > 0 && d <= limit && watch.go_on(d) {
        let slot = d as usize % RING;
        let cells = std::mem::take(&mut buckets[slot]);
        pending -= cells.len();
        for &(idx, at) in &cells {
            let (idx, at) = (idx as usize, at as usize);
            if units[idx] != d {
                continue; // a stale entry: reached sooner by another way
            }
            let from = if W::READS_FROM && prev[idx] != NONE {
                let from = prev[idx] as usize;
                Some((from, units[from]))
            } else {
                None
            };
            watch.settled(idx, d, from);
            if goal == Some(idx) {
                return Ok((units, prev));
            }
            if *work == 0 {
                return Err(Exhausted((units, prev)));
            }
            *work -= 1;
            // Straight neighbours first; a diagonal needs both straight ones it passes
            // between to be open (no corner cutting). The border is closed, so a cell at the
            // grid's edge finds no neighbour beyond it.
            let e = open[at + 1];
            let w = open[at - 1];
            let nn = open[at + stride];
            let s = open[at - stride];
            let mut relax =
                |to: usize, to_at: usize, cost: u32, buckets: &mut Vec<Vec<(u32, u32)>>| {
                    let nd = d + cost;
                    if nd < units[to] {
                        units[to] = nd;
                        prev[to] = idx as u32;
                        buckets[nd as usize % RING].push((to as u32, to_at as u32));
                        pending += 1;
                    }
                };
            if e {
                relax(idx + 1, at + 1, STRAIGHT, &mut buckets);
            }
            if w {
                relax(idx - 1, at - 1, STRAIGHT, &mut buckets);
            }
            if nn {
                relax(idx + cols, at + stride, STRAIGHT, &mut buckets);
            }
            if s {
                relax(idx - cols, at - stride, STRAIGHT, &mut buckets);
            }
            if nn && e && open[at + stride + 1] {
                relax(idx + cols + 1, at + stride + 1, DIAGONAL, &mut buckets);
            }
            if nn && w && open[at + stride - 1] {
                relax(idx + cols - 1, at + stride - 1, DIAGONAL, &mut buckets);
            }
            if s && e && open[at - stride + 1] {
                relax(idx - cols + 1, at - stride + 1, DIAGONAL, &mut buckets);
            }
            if s && w && open[at - stride - 1] {
                relax(idx - cols - 1, at - stride - 1, DIAGONAL, &mut buckets);
            }
        }
        // Hand the emptied bucket's allocation back for reuse.
        let mut cells = cells;
        cells.clear();
        if buckets[slot].is_empty() {
            buckets[slot] = cells;
        }
        d += 1;
    }
    Ok((units, prev))
}

/// The passable cell a search from `from` starts at: the nearest within a metre and two cells
/// (an agent pressed against a wall stands on a cell where it does not fit).
pub(super) fn start_cell(grid: &ClearanceGrid, from: Point2<f32>) -> Option<usize> {
    grid.nearest_passable(from, (1.0 / grid.cell).ceil() as usize + 2)
}

/// The most travel units whose distance in metres (`units × scale` in f32) is within
/// `reach`: one unit more is past it.
pub(super) fn units_within(reach: f32, scale: f32) -> u32 {
    let mut limit = (reach / scale).max(0.0).floor().min(u32::MAX as f32 / 2.0) as u32;
    while limit > 0 && limit as f32 * scale > reach {
        limit -= 1;
    }
    while ((limit + 1) as f32 * scale) <= reach {
        limit += 1;
    }
    limit
}
