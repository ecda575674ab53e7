//! Searches out to a reach in a window of the grid, and the way to set off toward every
//! cell near a walker read from them as a table: what the belief features ask for each
//! particle of the team's belief at every step.

use nalgebra::Point2;

use super::dial::{
    Exhausted, OpenCells, STRAIGHT, Unwatched, Watch, dial, start_cell, units_within,
};
use crate::sim::arena::ClearanceGrid;

/// The travel distances from a point out to a reach, as [`super::DistanceField::from_point_within`]
/// gives them, searched over only the window of the grid that the reach can touch: its
/// tables are the window's (a few thousand cells), not the map's, so many small searches on
/// a large map cost what they settle. Every cell within the reach has the whole field's
/// distance and predecessor: the window holds every path that short, and the search visits
/// its cells in the whole field's order.
#[derive(Debug, Clone)]
pub struct ReachField {
    /// The window's first column and row in the grid, and its columns.
    col0: usize,
    row0: usize,
    cols: usize,
    /// The grid's columns.
    grid_cols: usize,
    /// The start, as a window cell.
    start: usize,
    /// Travel units and predecessors of the window's cells.
    units: Vec<u32>,
    prev: Vec<u32>,
    /// The most units within the reach, and metres a unit.
    limit: u32,
    scale: f32,
}

impl ReachField {
    /// The field from the passable cell nearest to `from` out to `reach` metres; `None` when
    /// no passable cell is near.
    pub fn new(grid: &ClearanceGrid, from: Point2<f32>, reach: f32) -> Option<ReachField> {
        Some(ReachField::from_start(grid, start_cell(grid, from)?, reach))
    }

    /// The field from grid cell `start` (passable) out to `reach` metres.
    fn from_start(grid: &ClearanceGrid, start: usize, reach: f32) -> ReachField {
        ReachField::search(grid, start, reach, |_, _| Unwatched).0
    }

    /// [`ReachField::from_start`], with a watch on the search that `watch` makes from the
    /// field's window (its place, `start`, `limit` and `scale` set, its tables still empty)
    /// and the window's cells.
    fn search<W: Watch>(
        grid: &ClearanceGrid,
        start: usize,
        reach: f32,
        watch: impl FnOnce(&ReachField, usize) -> W,
    ) -> (ReachField, W) {
        let scale = grid.cell / STRAIGHT as f32;
        let limit = units_within(reach, scale);
        // A step moves one row or column at most and costs at least STRAIGHT units: no cell
        // farther than this many rows or columns is within the limit.
        let span = (limit / STRAIGHT) as usize;
        let (sc, sr) = (start % grid.cols, start / grid.cols);
        let (col0, row0) = (sc.saturating_sub(span), sr.saturating_sub(span));
        let cols = (sc + span).min(grid.cols - 1) - col0 + 1;
        let rows = (sr + span).min(grid.rows - 1) - row0 + 1;
        let open = OpenCells::window(grid, col0, row0, cols, rows);
        let mut field = ReachField {
            col0,
            row0,
            cols,
            grid_cols: grid.cols,
            start: (sr - row0) * cols + (sc - col0),
            units: Vec::new(),
            prev: Vec::new(),
            limit,
            scale,
        };
        let mut watch = watch(&field, cols * rows);
        (field.units, field.prev) = match dial(
            field.start,
            &open,
            None,
            limit,
            &mut u64::MAX.clone(),
            &mut watch,
        ) {
            Ok(search) | Err(Exhausted(search)) => search,
        };
        (field, watch)
    }

    /// The window cell of grid cell `cell`, if the window holds it.
    fn local(&self, cell: usize) -> Option<usize> {
        let (c, r) = (cell % self.grid_cols, cell / self.grid_cols);
        let (c, r) = (c.checked_sub(self.col0)?, r.checked_sub(self.row0)?);
        (c < self.cols && r * self.cols + c < self.units.len()).then_some(r * self.cols + c)
    }

    /// The grid cell of window cell `local`.
    fn global(&self, local: usize) -> usize {
        (self.row0 + local / self.cols) * self.grid_cols + self.col0 + local % self.cols
    }

    /// Metres of travel to grid cell `cell`, when it is within the reach.
    pub fn metres(&self, cell: usize) -> Option<f32> {
        let u = self.units[self.local(cell)?];
        (u <= self.limit).then_some(u as f32 * self.scale)
    }
}

/// No way: the cell is beyond the reach, or no walker fits there.
const NONE: u16 = u16::MAX;

/// For every cell of a [`ReachField`]'s window within its reach, the cell where the
/// cell's shortest path from the start first runs more than `ahead` metres from the start
/// (the cell itself when it is no farther): the way to set off toward it.
///
/// Those waypoints are few (the cells a little more than `ahead` from the start, and the
/// nearer ones), so each window cell holds the number of its waypoint in a short list: a
/// caller that needs something of every waypoint (the belief features: its bearing from
/// the robot) works it out once per waypoint, and a lookup per point reads two bytes. A
/// robot of the research environment keeps two maps, and with 64 worlds on two cores
/// they no longer stay in the caches between its steps: every cache line a lookup touches
/// is a miss, so the table is as narrow as it can be (docs/performance.md).
#[derive(Debug, Clone)]
pub struct WayMap {
    /// The window's first column and row in the grid, its columns and rows.
    col0: usize,
    row0: usize,
    cols: usize,
    rows: usize,
    /// Per window cell: its waypoint's place in `waypoints`, or [`NONE`].
    ids: Vec<u16>,
    /// The waypoints, as grid cells.
    waypoints: Vec<usize>,
}

impl WayMap {
    /// The map `ahead` metres out along the shortest paths from grid cell `start` (passable)
    /// out to `reach` metres, numbered as the search settles each cell (a cell's predecessor
    /// settles before it), without a pass of its own over the field (the tests' `new`
    /// numbers a finished field the same way, by travel).
    ///
    /// Panics if there are 65,535 waypoints or more: they lie within `ahead` and a cell of
    /// the start, so it takes an `ahead` of some 12 m on a 10 cm grid (callers pass a metre).
    pub fn search(grid: &ClearanceGrid, start: usize, reach: f32, ahead: f32) -> WayMap {
        let (field, numbering) = ReachField::search(grid, start, reach, |field, cells| {
            Numbering::new(field, ahead, cells)
        });
        field.ways(numbering)
    }

    /// The waypoints `ahead` metres out along `field`'s shortest paths, numbered in a pass
    /// over the field by travel ([`WayMap::search`] numbers them during the search).
    #[cfg(test)]
    pub fn new(field: &ReachField, ahead: f32) -> WayMap {
        let n = field.units.len();
        // Cells within the reach by their travel: a cell's predecessor is nearer, so its
        // waypoint is known before the cell's own.
        let mut order: Vec<usize> = (0..n).filter(|&c| field.units[c] <= field.limit).collect();
        order.sort_by_key(|&c| field.units[c]);
        let mut numbering = Numbering::new(field, ahead, n);
        for c in order {
            let from = (c != field.start).then(|| {
                let before = field.prev[c] as usize;
                (before, field.units[before])
            });
            numbering.settled(c, field.units[c], from);
        }
        field.ways(numbering)
    }

    /// The waypoints, as grid cells; [`WayMap::id_ahead`] numbers them.
    pub fn waypoints(&self) -> &[usize] {
        &self.waypoints
    }

    /// The grid cell of grid cell `cell`'s waypoint, when `cell` is within the reach.
    pub fn waypoint(&self, grid: &ClearanceGrid, cell: usize) -> Option<usize> {
        let id = self.id(cell % grid.cols, cell / grid.cols)?;
        Some(self.waypoints[id])
    }

    /// The number (in [`WayMap::waypoints`]) of the waypoint of the cell holding `p`, as
    /// `map.waypoint(grid, grid.cell_of(p)?)` finds it.
    #[inline]
    pub fn id_ahead(&self, grid: &ClearanceGrid, p: Point2<f32>) -> Option<usize> {
        if !(p.x >= 0.0 && p.y >= 0.0) {
            return None;
        }
        // As `ClearanceGrid::cell_of`.
        let (c, r) = ((p.x / grid.cell) as usize, (p.y / grid.cell) as usize);
        if c >= grid.cols || r >= grid.rows {
            return None;
        }
        self.id(c, r)
    }

    /// The waypoint number of the cell at grid column `c`, row `r`.
    #[inline]
    fn id(&self, c: usize, r: usize) -> Option<usize> {
        let (c, r) = (c.checked_sub(self.col0)?, r.checked_sub(self.row0)?);
        if c >= self.cols || r >= self.rows {
            return None;
        }
        let id = self.ids[r * self.cols + c];
        (id != NONE).then_some(id as usize)
    }
}

/// Numbers the waypoints of a [`ReachField`]'s cells as its search settles them: each
/// cell's predecessor is settled before it.
struct Numbering {
    /// The most travel units no farther than `ahead` metres.
    inner: u32,
    /// Per window cell: its waypoint's number, or [`NONE`] while unsettled.
    ids: Vec<u16>,
    /// The waypoints, as window cells.
    waypoints: Vec<usize>,
}

impl Numbering {
    fn new(field: &ReachField, ahead: f32, cells: usize) -> Numbering {
        Numbering {
            inner: units_within(ahead, field.scale),
            ids: vec![NONE; cells],
            waypoints: Vec::new(),
        }
    }
}

impl Watch for Numbering {
    // Called for every cell the search settles: inlined into it.
    #[inline(always)]
    fn settled(&mut self, cell: usize, units: u32, from: Option<(usize, u32)>) {
        self.ids[cell] = match from {
            Some((before, before_units)) if units > self.inner && before_units > self.inner => {
                self.ids[before]
            }
            // The start, or a cell no farther than `ahead`, or the first past it: its own
            // waypoint.
            _ => {
                let id = u16::try_from(self.waypoints.len())
                    .ok()
                    .filter(|&id| id != NONE)
                    .expect("fewer than 65,535 waypoints within `ahead` of the start");
                self.waypoints.push(cell);
                id
            }
        };
    }

    fn go_on(&mut self, _: u32) -> bool {
        true
    }
}

impl ReachField {
    /// The map of this field's window from its waypoints' numbering.
    fn ways(&self, numbering: Numbering) -> WayMap {
        WayMap {
            col0: self.col0,
            row0: self.row0,
            cols: self.cols,
            rows: self.units.len() / self.cols,
            ids: numbering.ids,
            waypoints: numbering
                .waypoints
                .into_iter()
                .map(|c| self.global(c))
                .collect(),
        }
    }
}

/// The last two [`WayMap`]s of one walker on one grid (a robot in its match), kept by
/// their start cells: a map depends on nothing else (with its reach and `ahead`), so a
/// robot that has not left its cell since the last search, or has stepped back into the
/// cell before, is given the same map without a search. A robot at full speed crosses a
/// cell in about two ticks, one standing still never, and one that dithers (as a policy's
/// random actions early in training do) moves between two cells: examples/env_profile's
/// random actions search for 25% of the observations with one map kept and 8% with two.
#[derive(Debug, Clone, Default)]
pub struct ReachCache {
    /// Maps with the start cell, the reach and `ahead` (as bits) each was made for; the
    /// latest used first.
    kept: Vec<(usize, u32, u32, WayMap)>,
}

/// Maps a [`ReachCache`] keeps (about 30 KB each for the belief features' 6 m).
const REACH_FIELDS_KEPT: usize = 2;

impl ReachCache {
    /// The [`WayMap`] of the field from `from` out to `reach`, from the cache when a
    /// kept map has the start cell, the reach and `ahead`. `grid` must be every call's.
    pub fn ways(
        &mut self,
        grid: &ClearanceGrid,
        from: Point2<f32>,
        reach: f32,
        ahead: f32,
    ) -> Option<&WayMap> {
        let key = (start_cell(grid, from)?, reach.to_bits(), ahead.to_bits());
        if let Some(i) = self
            .kept
            .iter()
            .position(|(s, r, a, _)| (*s, *r, *a) == key)
        {
            self.kept[..=i].rotate_right(1);
        } else {
            let map = WayMap::search(grid, key.0, reach, ahead);
            self.kept.truncate(REACH_FIELDS_KEPT - 1);
            self.kept.insert(0, (key.0, key.1, key.2, map));
        }
        self.kept.first().map(|(.., map)| map)
    }
}
