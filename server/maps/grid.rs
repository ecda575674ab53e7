//! An occupancy grid (a wall or free per cell), coarsened, cropped and its walls merged
//! into few rectangles, which `import` makes the obstacles of one of our maps.
//!
//! Rectangles rather than traced outlines: they are exact (every wall cell is covered and
//! no free cell is), never self-intersecting, and greedy merging (runs along each row, then
//! equal runs of the rows above) keeps an ordinary indoor map well under the 10,000-vertex
//! limit of the format.

/// The largest arena side the map format allows (metres).
pub const MAX_SIDE: f64 = 500.0;

/// A grid of square cells; row 0 is the bottom (y grows up), as in our maps and in ROS's
/// `OccupancyGrid`.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    pub cols: usize,
    pub rows: usize,
    /// Metres per cell.
    pub cell: f64,
    /// Row-major, `true` for a wall (occupied or unknown).
    pub blocked: Vec<bool>,
}

/// A rectangle of cells: columns `c0..c1`, rows `r0..r1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rect {
    pub c0: usize,
    pub c1: usize,
    pub r0: usize,
    pub r1: usize,
}

impl Grid {
    /// A grid of free cells.
    pub fn free(cols: usize, rows: usize, cell: f64) -> Grid {
        Grid {
            cols,
            rows,
            cell,
            blocked: vec![false; cols * rows],
        }
    }

    pub fn is_blocked(&self, c: usize, r: usize) -> bool {
        self.blocked[r * self.cols + c]
    }

    pub fn set(&mut self, c: usize, r: usize, blocked: bool) {
        self.blocked[r * self.cols + c] = blocked;
    }

    /// Blocks of `k` × `k` cells merged into one, a wall when any of its cells is (walls never
    /// shrink). Cells past the grid's edge, in a last partial block, count as wall: outside
    /// the map is unknown.
    pub fn coarsen(self, k: usize) -> Grid {
        if k <= 1 {
            return self;
        }
        let cols = self.cols.div_ceil(k);
        let rows = self.rows.div_ceil(k);
        let mut out = Grid::free(cols, rows, self.cell * k as f64);
        for r in 0..rows {
            for c in 0..cols {
                let partial = (c + 1) * k > self.cols || (r + 1) * k > self.rows;
                let any = (r * k..((r + 1) * k).min(self.rows)).any(|rr| {
                    (c * k..((c + 1) * k).min(self.cols)).any(|cc| self.is_blocked(cc, rr))
                });
                out.set(c, r, partial || any);
            }
        }
        out
    }

    /// The grid cut to the bounding box of its free cells, with that box's first column and
    /// row; `None` when no cell is free.
    pub fn crop(&self) -> Option<(Grid, [usize; 2])> {
        let (mut c0, mut c1, mut r0, mut r1) = (usize::MAX, 0, usize::MAX, 0);
        for r in 0..self.rows {
            for c in 0..self.cols {
                if !self.is_blocked(c, r) {
                    c0 = c0.min(c);
                    c1 = c1.max(c + 1);
                    r0 = r0.min(r);
                    r1 = r1.max(r + 1);
                }
            }
        }
        if c0 == usize::MAX {
            return None;
        }
        let mut out = Grid::free(c1 - c0, r1 - r0, self.cell);
        for r in r0..r1 {
            for c in c0..c1 {
                out.set(c - c0, r - r0, self.is_blocked(c, r));
            }
        }
        Some((out, [c0, r0]))
    }

    /// The wall cells as rectangles: maximal runs along each row, then each run merged with
    /// the same run (same columns) in the rows above it. Every wall cell is in exactly one.
    /// Sorted by lowest row, then first column.
    pub fn rectangles(&self) -> Vec<Rect> {
        let mut all = Vec::new();
        self.sweep(|q| all.push(q));
        all.sort_by_key(|q| (q.r0, q.c0));
        all
    }

    /// How many rectangles [`Grid::rectangles`] makes, in memory for one row only (a noisy
    /// grid can make millions, which are refused, not built).
    pub fn count_rectangles(&self) -> usize {
        let mut n = 0;
        self.sweep(|_| n += 1);
        n
    }

    /// Calls `emit` with each rectangle once it stops growing.
    fn sweep(&self, mut emit: impl FnMut(Rect)) {
        // Rectangles still growing upward, in column order (disjoint, as the runs of a row).
        let mut open: Vec<Rect> = Vec::new();
        let mut next: Vec<Rect> = Vec::new();
        for r in 0..self.rows {
            let row = &self.blocked[r * self.cols..(r + 1) * self.cols];
            let mut k = 0;
            let mut c = 0;
            while c < self.cols {
                if !row[c] {
                    c += 1;
                    continue;
                }
                let c0 = c;
                while c < self.cols && row[c] {
                    c += 1;
                }
                // Open rectangles starting left of this run cannot continue: close them.
                while k < open.len() && open[k].c0 < c0 {
                    emit(open[k]);
                    k += 1;
                }
                if k < open.len() && open[k].c0 == c0 && open[k].c1 == c {
                    next.push(Rect {
                        r1: r + 1,
                        ..open[k]
                    });
                    k += 1;
                } else {
                    next.push(Rect {
                        c0,
                        c1: c,
                        r0: r,
                        r1: r + 1,
                    });
                }
            }
            for &q in &open[k..] {
                emit(q);
            }
            std::mem::swap(&mut open, &mut next);
            next.clear();
        }
        for q in open {
            emit(q);
        }
    }
}

/// A length in metres rounded to a micrometre, so that written maps read `1.85`, not
/// `1.8500000000000003`; far below any cell.
pub fn round(v: f64) -> f64 {
    (v * 1e6).round() / 1e6
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid from text rows, the first row at the top, `#` a wall.
    pub(crate) fn grid(rows: &[&str], cell: f64) -> Grid {
        let cols = rows[0].len();
        let mut g = Grid::free(cols, rows.len(), cell);
        for (i, line) in rows.iter().enumerate() {
            for (c, ch) in line.chars().enumerate() {
                g.set(c, rows.len() - 1 - i, ch == '#');
            }
        }
        g
    }

    fn covered(g: &Grid, rects: &[Rect]) -> Vec<u32> {
        let mut count = vec![0; g.cols * g.rows];
        for q in rects {
            for r in q.r0..q.r1 {
                for c in q.c0..q.c1 {
                    count[r * g.cols + c] += 1;
                }
            }
        }
        count
    }

    #[test]
    fn rectangles_cover_every_wall_cell_once_and_no_free_cell() {
        let g = grid(
            &[
                "##########",
                "#....#...#",
                "#....#...#",
                "#..###...#",
                "#........#",
                "##########",
            ],
            1.0,
        );
        let rects = g.rectangles();
        let count = covered(&g, &rects);
        for (i, &b) in g.blocked.iter().enumerate() {
            assert_eq!(count[i], u32::from(b), "cell {i}");
        }
        // The bottom and top rows, the two side columns over four rows, and the wall in the
        // middle as a run three wide and the column above it.
        assert_eq!(rects.len(), 6, "{rects:?}");
        assert_eq!(g.count_rectangles(), 6);
    }

    #[test]
    fn coarsening_keeps_every_wall_and_walls_off_the_partial_edge() {
        let g = grid(&["#....", ".....", "....."], 1.0);
        let c = g.coarsen(2);
        assert_eq!((c.cols, c.rows, c.cell), (3, 2, 2.0));
        // Rows from the bottom: row 0 holds source rows 0-1, row 1 holds source row 2 (the
        // top, with the wall) and a missing row.
        assert_eq!(c.blocked, vec![false, false, true, true, true, true]);
    }

    #[test]
    fn cropping_cuts_margins_without_free_cells() {
        let g = grid(&["#####", "##..#", "##.##", "#####"], 0.5);
        let (c, at) = g.crop().unwrap();
        assert_eq!(at, [2, 1]);
        assert_eq!((c.cols, c.rows), (2, 2));
        assert_eq!(c.blocked, vec![false, true, false, false]);
        assert!(grid(&["##", "##"], 1.0).crop().is_none());
    }
}
