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
        let (starts, items) = pack(per_cell);
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
                    if let Some(t) = hit_before(o, d, *a, *b, best) {
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

/// Where the ray from `o` along `d` meets the segment from `a` to `b`, if it does so before
/// `best`: [`hits_before`] for one beam, so that the grid walk and the fan, which share that
/// one ray–segment test, give the same distances.
#[inline]
fn hit_before(
    o: Point2<f32>,
    d: Vector2<f32>,
    a: Point2<f32>,
    b: Point2<f32>,
    best: f32,
) -> Option<f32> {
    let mut t = [best];
    hits_before(o, a, b, (&[d.x], &[d.y]), &mut t);
    // Replaced only by a strictly nearer hit.
    (t[0] < best).then_some(t[0])
}

/// The pseudo-angle of `v` around a point, counted counter-clockwise from straight behind
/// the unit vector `heading`, in `[0, 4]`: behind is 0 and 4, the heading 2. Monotone in the
/// true angle (a diamond angle: one division, no trigonometry), so a laser's fan increases
/// along it without a wrap.
fn pseudo_angle(heading: Vector2<f32>, v: Vector2<f32>) -> f32 {
    let (x, y) = (-v.dot(&heading), heading.x * v.y - heading.y * v.x);
    // Diamond angle of (x, y) in [0, 4), monotone in the true angle, from +x.
    let p = y / (x.abs() + y.abs()).max(f32::MIN_POSITIVE);
    let from_x = if x >= 0.0 {
        if y >= 0.0 { p } else { 4.0 + p }
    } else {
        2.0 - p
    };
    // Flip so that counter-clockwise increases.
    4.0 - from_x
}

/// How many of a laser fan's beams lie before each bin of [`pseudo_angle`]: what the fan
/// cast looks up for each wall's ends to find the beams between them, in place of two
/// bisections a wall (they were most of its time once the hit tests ran several beams at
/// once). Counted once for a fan's shape (beams and field of view) on the ideal beam
/// directions; the cast widens what it looks up by a beam each way for the rounding of a
/// scan's own directions.
#[derive(Debug, Clone, PartialEq)]
pub struct FanBins {
    beams: usize,
    /// `below[k]` beams lie before bin `k`'s start; `below[BINS]` is every beam.
    below: Vec<u32>,
}

impl FanBins {
    /// Bins a unit of pseudo-angle: a power of two, so that a pseudo-angle's bin is exact.
    const PER_UNIT: f32 = 64.0;
    const BINS: usize = 4 * Self::PER_UNIT as usize;

    /// The bins of `beams` spread evenly over `fov` (less than a full turn) around a heading.
    pub fn new(beams: usize, fov: f32) -> FanBins {
        let step = if beams <= 1 {
            0.0
        } else {
            fov / (beams - 1) as f32
        };
        let heading = Vector2::new(1.0, 0.0);
        let angles: Vec<f32> = (0..beams)
            .map(|i| {
                let (y, x) = (-fov / 2.0 + step * i as f32).sin_cos();
                pseudo_angle(heading, Vector2::new(x, y))
            })
            .collect();
        let mut below = vec![0u32; Self::BINS + 1];
        let mut j = 0;
        for (k, b) in below.iter_mut().enumerate().take(Self::BINS) {
            let start = k as f32 / Self::PER_UNIT;
            while j < beams && angles[j] < start {
                j += 1;
            }
            *b = j as u32;
        }
        below[Self::BINS] = beams as u32;
        FanBins { beams, below }
    }

    pub fn beams(&self) -> usize {
        self.beams
    }

    fn bin(a: f32) -> usize {
        ((a * Self::PER_UNIT) as usize).min(Self::BINS - 1)
    }

    /// At most the number of beams before pseudo-angle `a`.
    fn before(&self, a: f32) -> usize {
        self.below[Self::bin(a)] as usize
    }

    /// At least the number of beams before pseudo-angle `a` or at it.
    fn through(&self, a: f32) -> usize {
        self.below[Self::bin(a) + 1] as usize
    }
}

/// Where each beam `(xs[i], ys[i])` from `o` meets the segment from `a` to `b` (a millionth
/// of the segment's length of slack at its ends), replacing `best[i]` where that is nearer:
/// written without branches so that the compiler tests several beams in one instruction
/// (most of a fan cast's time is this loop).
#[inline]
fn hits_before(
    o: Point2<f32>,
    a: Point2<f32>,
    b: Point2<f32>,
    (xs, ys): (&[f32], &[f32]),
    best: &mut [f32],
) {
    let e = b - a;
    let ao = a - o;
    let along = ao.x * e.y - ao.y * e.x;
    for ((x, y), best) in xs.iter().zip(ys).zip(best) {
        let denom = x * e.y - y * e.x;
        let t = along / denom;
        let u = (ao.x * y - ao.y * x) / denom;
        let hit =
            (denom.abs() >= 1e-12) & (t >= 0.0) & (t < *best) & (-1e-6..=1.0 + 1e-6).contains(&u);
        *best = if hit { t } else { *best };
    }
}

/// Per-cell lists as one vector of items and the offsets where each cell's list starts
/// (cell `c` is `items[starts[c]..starts[c + 1]]`).
fn pack<T>(per_cell: Vec<Vec<T>>) -> (Vec<u32>, Vec<T>) {
    let mut starts = Vec::with_capacity(per_cell.len() + 1);
    let mut items = Vec::new();
    for list in per_cell {
        starts.push(items.len() as u32);
        items.extend(list);
    }
    starts.push(items.len() as u32);
    (starts, items)
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

/// The wall segments binned by coarse cells of their bounding boxes, for casting a whole fan
/// of rays from one point: each segment within reach is tested only against the beams
/// whose directions lie in the angle it subtends, found by bisection, rather than every
/// beam walking the fine grid on its own.
///
/// A beam's distance is the smallest `t` of the same ray–segment test [`SegmentGrid::cast`]
/// makes, over a superset of the segments that walk would test (every segment within reach
/// whose angle holds the beam, widened by a beam on each side), so the two agree bit for bit
/// (a test compares them on random fans).
#[derive(Debug)]
pub(crate) struct SegmentBins {
    cell: f32,
    cols: usize,
    rows: usize,
    /// `starts[c]..starts[c + 1]` indexes `items` for cell `c`.
    starts: Vec<u32>,
    /// Segment indices.
    items: Vec<u32>,
    segments: Vec<[Point2<f32>; 2]>,
    /// Each segment's cells: first column, first row (where it is tested once per query).
    first_cell: Vec<[u32; 2]>,
}

impl SegmentBins {
    const CELL: f32 = 2.0;

    pub(crate) fn build(width: f32, height: f32, walls: &Polyline) -> SegmentBins {
        let cell = Self::CELL.max((width * height / 250_000.0).sqrt());
        let cols = (width / cell).ceil().max(1.0) as usize;
        let rows = (height / cell).ceil().max(1.0) as usize;
        let clamp = |v: f32, n: usize| ((v / cell).floor().max(0.0) as usize).min(n - 1);
        let mut per_cell: Vec<Vec<u32>> = vec![Vec::new(); cols * rows];
        let mut segments = Vec::new();
        let mut first_cell = Vec::new();
        for (k, seg) in walls.segments().enumerate() {
            let (c0, c1) = (
                clamp(seg.a.x.min(seg.b.x), cols),
                clamp(seg.a.x.max(seg.b.x), cols),
            );
            let (r0, r1) = (
                clamp(seg.a.y.min(seg.b.y), rows),
                clamp(seg.a.y.max(seg.b.y), rows),
            );
            for r in r0..=r1 {
                for c in c0..=c1 {
                    per_cell[r * cols + c].push(k as u32);
                }
            }
            segments.push([seg.a, seg.b]);
            first_cell.push([c0 as u32, r0 as u32]);
        }
        let (starts, items) = pack(per_cell);
        SegmentBins {
            cell,
            cols,
            rows,
            starts,
            items,
            segments,
            first_cell,
        }
    }

    /// Bytes it holds on the heap.
    pub(crate) fn heap_bytes(&self) -> usize {
        (self.starts.len() + self.items.len()) * std::mem::size_of::<u32>()
            + self.segments.len() * std::mem::size_of::<[Point2<f32>; 2]>()
            + self.first_cell.len() * std::mem::size_of::<[u32; 2]>()
    }

    /// Distance along each beam from `o` to the first wall, capped at `max`, into `out`.
    /// Beam `i` is the unit vector `(xs[i], ys[i])`: the beams of `fan` turned to the unit
    /// vector `heading` (each within rounding of its bearing's direction).
    pub(crate) fn cast_fan(
        &self,
        o: Point2<f32>,
        heading: Vector2<f32>,
        fan: &FanBins,
        (xs, ys): (&[f32], &[f32]),
        max: f32,
        out: &mut [f32],
    ) {
        let n = xs.len().min(ys.len()).min(out.len()).min(fan.beams());
        out[..n].fill(max);
        if n == 0 {
            return;
        }
        let pseudo = |v: Vector2<f32>| pseudo_angle(heading, v);
        // The beams between a wall's ends `a` and `b`, two beams wider each way than the bins
        // give: one for the rounding of the ends' angles against the hit test, one for that
        // of this scan's directions against the ideal fan the bins were counted on.
        let first_after = |a: f32| fan.before(a).saturating_sub(2);
        let last_before = |b: f32| (fan.through(b) + 2).min(n);
        let cross = |a: Vector2<f32>, b: Vector2<f32>| a.x * b.y - a.y * b.x;
        let clamp = |v: f32, k: usize| ((v / self.cell).floor().max(0.0) as usize).min(k - 1);
        let (q0, q1) = (clamp(o.x - max, self.cols), clamp(o.x + max, self.cols));
        let (p0, p1) = (clamp(o.y - max, self.rows), clamp(o.y + max, self.rows));
        for r in p0..=p1 {
            for c in q0..=q1 {
                let cell = r * self.cols + c;
                let list = &self.items[self.starts[cell] as usize..self.starts[cell + 1] as usize];
                for &k in list {
                    let k = k as usize;
                    // Tested in the first of its cells the query covers, once.
                    let [fc, fr] = self.first_cell[k];
                    if (fc as usize).max(q0) != c || (fr as usize).max(p0) != r {
                        continue;
                    }
                    let [a, b] = self.segments[k];
                    let (va, vb) = (a - o, b - o);
                    let e = b - a;
                    // Beyond reach (the closest point of the segment): no beam can hit it.
                    let t = (-va.dot(&e) / e.norm_squared().max(f32::MIN_POSITIVE)).clamp(0.0, 1.0);
                    let closest = (va + e * t).norm();
                    if closest > max {
                        continue;
                    }
                    // The beams between the two ends, counter-clockwise from `pa` to `pb`;
                    // across the back of the fan, those after `pa` and those before `pb`.
                    let ranges = if closest < 1e-3 {
                        // On (or nearly on) the segment's line: every beam.
                        [(0, n), (0, 0)]
                    } else {
                        let (mut pa, mut pb) = (pseudo(va), pseudo(vb));
                        if cross(va, vb) < 0.0 {
                            std::mem::swap(&mut pa, &mut pb);
                        }
                        let (from, to) = (first_after(pa), last_before(pb));
                        if pa <= pb {
                            [(from, to), (0, 0)]
                        } else {
                            [(from, n), (0, to)]
                        }
                    };
                    for (lo, hi) in ranges {
                        hits_before(o, a, b, (&xs[lo..hi], &ys[lo..hi]), &mut out[lo..hi]);
                    }
                }
            }
        }
    }
}
