//! The wall segments bucketed on a uniform grid, for fast ray casts: a ray walks the
//! cells it crosses and tests only the segments listed there.

use nalgebra::{Point2, Vector2};
use parry2d::shape::Polyline;

/// Wall segments bucketed on a uniform grid: each cell lists the segments that touch it.
#[derive(Debug)]
pub(crate) struct SegmentGrid {
    cell: f32,
    cols: usize,
    rows: usize,
    /// `starts[c]..starts[c + 1]` indexes `items` for cell `c`.
    starts: Vec<u32>,
    items: Vec<[Point2<f32>; 2]>,
}

impl SegmentGrid {
    const CELL: f32 = 0.5;

    /// Cell size, columns and rows for a `width` × `height` arena: 0.5 m cells, coarser on
    /// huge maps so that there are at most about 250k.
    fn shape(width: f32, height: f32) -> (f32, usize, usize) {
        let cell = Self::CELL.max((width * height / 250_000.0).sqrt());
        let cols = (width / cell).ceil().max(1.0) as usize;
        let rows = (height / cell).ceil().max(1.0) as usize;
        (cell, cols, rows)
    }

    /// Entries in the index (a segment once per cell it is listed in).
    #[cfg(test)]
    pub(crate) fn len(&self) -> usize {
        self.items.len()
    }

    /// Bytes it holds on the heap.
    pub(crate) fn heap_bytes(&self) -> usize {
        self.starts.len() * std::mem::size_of::<u32>()
            + self.items.len() * std::mem::size_of::<[Point2<f32>; 2]>()
    }

    pub(crate) fn build(width: f32, height: f32, walls: &Polyline) -> SegmentGrid {
        let (cell, cols, rows) = Self::shape(width, height);
        let mut per_cell: Vec<Vec<[Point2<f32>; 2]>> = vec![Vec::new(); cols * rows];
        for seg in walls.segments() {
            for (r, c0, c1) in cells_along(seg.a, seg.b, cell, cols, rows) {
                for c in c0..=c1 {
                    per_cell[r * cols + c].push([seg.a, seg.b]);
                }
            }
        }
        Self::packed(cell, cols, rows, per_cell)
    }

    /// The index of per-cell lists, packed into one vector with offsets.
    fn packed(cell: f32, cols: usize, rows: usize, per_cell: Vec<Vec<[Point2<f32>; 2]>>) -> Self {
        let mut starts = Vec::with_capacity(cols * rows + 1);
        let mut items = Vec::new();
        for segs in per_cell {
            starts.push(items.len() as u32);
            items.extend(segs);
        }
        starts.push(items.len() as u32);
        SegmentGrid {
            cell,
            cols,
            rows,
            starts,
            items,
        }
    }

    /// The segment index as it was built before: every segment in every cell of its
    /// slightly grown bounding box.
    #[cfg(test)]
    pub(crate) fn by_bounding_boxes(width: f32, height: f32, walls: &Polyline) -> SegmentGrid {
        let (cell, cols, rows) = Self::shape(width, height);
        let mut per_cell: Vec<Vec<[Point2<f32>; 2]>> = vec![Vec::new(); cols * rows];
        for seg in walls.segments() {
            let pad = 1e-3;
            let c0 = (((seg.a.x.min(seg.b.x) - pad) / cell).floor().max(0.0)) as usize;
            let c1 = (((seg.a.x.max(seg.b.x) + pad) / cell).floor() as usize).min(cols - 1);
            let r0 = (((seg.a.y.min(seg.b.y) - pad) / cell).floor().max(0.0)) as usize;
            let r1 = (((seg.a.y.max(seg.b.y) + pad) / cell).floor() as usize).min(rows - 1);
            for r in r0..=r1 {
                for c in c0..=c1 {
                    per_cell[r * cols + c].push([seg.a, seg.b]);
                }
            }
        }
        Self::packed(cell, cols, rows, per_cell)
    }

    pub(crate) fn cast(&self, o: Point2<f32>, d: Vector2<f32>, max: f32) -> f32 {
        let cross = |a: Vector2<f32>, b: Vector2<f32>| a.x * b.y - a.y * b.x;
        let mut cx = (o.x / self.cell).floor() as isize;
        let mut cy = (o.y / self.cell).floor() as isize;
        let step_x: isize = if d.x >= 0.0 { 1 } else { -1 };
        let step_y: isize = if d.y >= 0.0 { 1 } else { -1 };
        let next_boundary = |c: isize, step: isize| (c + (step > 0) as isize) as f32 * self.cell;
        let mut t_max_x = if d.x.abs() < 1e-12 {
            f32::INFINITY
        } else {
            (next_boundary(cx, step_x) - o.x) / d.x
        };
        let mut t_max_y = if d.y.abs() < 1e-12 {
            f32::INFINITY
        } else {
            (next_boundary(cy, step_y) - o.y) / d.y
        };
        let t_delta_x = if d.x.abs() < 1e-12 {
            f32::INFINITY
        } else {
            self.cell / d.x.abs()
        };
        let t_delta_y = if d.y.abs() < 1e-12 {
            f32::INFINITY
        } else {
            self.cell / d.y.abs()
        };
        let mut best = max;
        loop {
            if cx >= 0 && cy >= 0 && (cx as usize) < self.cols && (cy as usize) < self.rows {
                let c = cy as usize * self.cols + cx as usize;
                for [a, b] in &self.items[self.starts[c] as usize..self.starts[c + 1] as usize] {
                    let e = b - a;
                    let denom = cross(d, e);
                    if denom.abs() < 1e-12 {
                        continue;
                    }
                    let ao = a - o;
                    let t = cross(ao, e) / denom;
                    let u = cross(ao, d) / denom;
                    if t >= 0.0 && t < best && (-1e-6..=1.0 + 1e-6).contains(&u) {
                        best = t;
                    }
                }
            }
            // A hit inside this cell cannot be beaten by any later cell.
            let t_exit = t_max_x.min(t_max_y);
            if best <= t_exit || t_exit >= max {
                return best;
            }
            if t_max_x < t_max_y {
                cx += step_x;
                t_max_x += t_delta_x;
            } else {
                cy += step_y;
                t_max_y += t_delta_y;
            }
        }
    }
}

/// The cells a segment passes through, slightly grown: for each row of its bounding box,
/// the columns where the part of the segment inside that row (padded by a millimetre)
/// lies. Conservative, so a ray that hits the segment finds it in the cell of the hit;
/// and unlike the whole bounding box, a long diagonal wall costs cells in proportion to
/// its length, not to the area it spans (a 700 m diagonal took a quarter of a million).
fn cells_along(
    a: Point2<f32>,
    b: Point2<f32>,
    cell: f32,
    cols: usize,
    rows: usize,
) -> impl Iterator<Item = (usize, usize, usize)> {
    let pad = 1e-3;
    let col = move |x: f32| ((x / cell).floor().max(0.0) as usize).min(cols - 1);
    let r0 = (((a.y.min(b.y) - pad) / cell).floor().max(0.0)) as usize;
    let r1 = (((a.y.max(b.y) + pad) / cell).floor() as usize).min(rows - 1);
    let dy = b.y - a.y;
    (r0..=r1).filter_map(move |r| {
        let (lo, hi) = (r as f32 * cell - pad, (r + 1) as f32 * cell + pad);
        let (x0, x1) = if dy.abs() < 1e-9 {
            (a.x.min(b.x), a.x.max(b.x))
        } else {
            let (t0, t1) = ((lo - a.y) / dy, (hi - a.y) / dy);
            let (t0, t1) = (t0.min(t1).max(0.0), t0.max(t1).min(1.0));
            if t0 > t1 {
                return None;
            }
            let (xa, xb) = (a.x + (b.x - a.x) * t0, a.x + (b.x - a.x) * t1);
            (xa.min(xb), xa.max(xb))
        };
        Some((r, col(x0 - pad), col(x1 + pad)))
    })
}
