//! Our maps drawn onto a grid, the way back from polygons to pixels (for a ROS export).
//!
//! A pixel is a wall when any part of its inside is wall: its centre lies in an obstacle,
//! an obstacle's edge or the arena's border passes through it, or it lies outside the
//! arena. So a wall thinner than a pixel is never lost, and a wall that runs along pixel
//! edges (as every imported one does) covers exactly its own pixels: importing a map,
//! exporting it at the same resolution and importing that gives the same cells back.
//! The grid has a ring of wall pixels around the arena: the border, drawn for ROS tools
//! that know nothing of it.

use lasertag_core::sim::arena::MapDef;

use crate::maps::format::{MAX_CELLS, Problem};
use crate::maps::grid::Grid;

/// How close (in pixels) a point may come to a pixel edge and still count as on it: far
/// above the rounding of `f32` coordinates, far below anything drawn.
const ON_EDGE: f64 = 1e-3;

/// `def` drawn at `resolution` metres a pixel. Cell (c, r) covers x from (c - 1) ×
/// resolution to c × resolution (and y likewise): the ring of cells 0 and the last lies
/// outside the arena.
pub fn rasterise(def: &MapDef, resolution: f64) -> Result<Grid, Problem> {
    if !(resolution.is_finite() && resolution > 0.0) {
        return Err(Problem::field(
            "resolution",
            format!("{resolution} must be a number of metres per pixel > 0"),
        ));
    }
    let (w, h) = (f64::from(def.width), f64::from(def.height));
    let span = |v: f64| (v / resolution - ON_EDGE).ceil().max(1.0) + 2.0;
    let (cols, rows) = (span(w), span(h));
    if cols * rows > MAX_CELLS as f64 {
        let least = ((w + 2.0 * resolution) * (h + 2.0 * resolution) / MAX_CELLS as f64).sqrt();
        return Err(Problem::field(
            "resolution",
            format!(
                "at {resolution} m a pixel the {w} m × {h} m map is {cols} × {rows} pixels, the \
                 limit is {MAX_CELLS}: use {least:.3} m a pixel or more"
            ),
        ));
    }
    let (cols, rows) = (cols as usize, rows as usize);
    let mut grid = Grid::free(cols, rows, resolution);
    // The border: every cell reaching outside the arena.
    for r in 0..rows {
        for c in 0..cols {
            let outside = |k: usize, side: f64| {
                k == 0 || (k as f64) * resolution > side + ON_EDGE * resolution
            };
            if outside(c, w) || outside(r, h) {
                grid.set(c, r, true);
            }
        }
    }
    for poly in &def.obstacles {
        let pts: Vec<[f64; 2]> = poly
            .iter()
            .map(|p| [f64::from(p.x), f64::from(p.y)])
            .collect();
        fill_inside(&mut grid, &pts);
        for i in 0..pts.len() {
            trace_edge(&mut grid, pts[i], pts[(i + 1) % pts.len()]);
        }
    }
    Ok(grid)
}

/// Marks the cells whose centre lies inside `poly` (even-odd, as the core's
/// `point_in_polygon`), one row of centres at a time.
fn fill_inside(grid: &mut Grid, poly: &[[f64; 2]]) {
    let res = grid.cell;
    let (lo, hi) = poly.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
        (lo.min(p[1]), hi.max(p[1]))
    });
    // Cell r's centre is at (r - 0.5) × res.
    let first = ((lo / res + 0.5).floor().max(0.0)) as usize;
    let last = ((hi / res + 0.5).ceil() as usize).min(grid.rows.saturating_sub(1));
    let n = poly.len();
    let mut crossings = Vec::new();
    for r in first..=last {
        let y = (r as f64 - 0.5) * res;
        crossings.clear();
        for i in 0..n {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            if (a[1] > y) != (b[1] > y) {
                crossings.push(a[0] + (y - a[1]) * (b[0] - a[0]) / (b[1] - a[1]));
            }
        }
        crossings.sort_by(f64::total_cmp);
        for pair in crossings.chunks_exact(2) {
            let start = ((pair[0] / res + 0.5).ceil().max(0.0)) as usize;
            let mut c = start;
            while c < grid.cols && (c as f64 - 0.5) * res < pair[1] {
                grid.set(c, r, true);
                c += 1;
            }
        }
    }
}

/// Marks the cells whose inside the segment from `a` to `b` passes through (not those it
/// only runs along the edge of).
fn trace_edge(grid: &mut Grid, a: [f64; 2], b: [f64; 2]) {
    let res = grid.cell;
    // Cell coordinates: cell (c, r) spans [c, c + 1) × [r, r + 1).
    let to_cell = |v: f64| v / res + 1.0;
    let (ax, ay, bx, by) = (to_cell(a[0]), to_cell(a[1]), to_cell(b[0]), to_cell(b[1]));
    let mut ts = vec![0.0, 1.0];
    for (from, to) in [(ax, bx), (ay, by)] {
        if (to - from).abs() > f64::EPSILON {
            let (lo, hi) = (from.min(to), from.max(to));
            let mut k = lo.ceil();
            while k <= hi {
                ts.push((k - from) / (to - from));
                k += 1.0;
            }
        }
    }
    ts.sort_by(f64::total_cmp);
    for pair in ts.windows(2) {
        if pair[1] - pair[0] < 1e-12 {
            continue;
        }
        let t = (pair[0] + pair[1]) / 2.0;
        let (x, y) = (ax + (bx - ax) * t, ay + (by - ay) * t);
        let on_line = |v: f64| (v - v.round()).abs() < ON_EDGE;
        if on_line(x) || on_line(y) || x < 0.0 || y < 0.0 {
            continue;
        }
        let (c, r) = (x.floor() as usize, y.floor() as usize);
        if c < grid.cols && r < grid.rows {
            grid.set(c, r, true);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point2;

    fn map(width: f32, height: f32, obstacles: Vec<Vec<[f32; 2]>>) -> MapDef {
        MapDef {
            name: "t".into(),
            width,
            height,
            obstacles: obstacles
                .into_iter()
                .map(|p| p.into_iter().map(|v| Point2::new(v[0], v[1])).collect())
                .collect(),
            robot_spawns: vec![[0.5, 0.5, 0.0]],
            opponent_spawns: vec![Point2::new(1.5, 1.5)],
            landmarks: vec![],
        }
    }

    /// The grid as text rows, the top first.
    fn rows(g: &Grid) -> Vec<String> {
        (0..g.rows)
            .rev()
            .map(|r| {
                (0..g.cols)
                    .map(|c| if g.is_blocked(c, r) { '#' } else { '.' })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn an_aligned_rectangle_covers_exactly_its_cells_inside_a_border_ring() {
        let def = map(
            3.0,
            2.0,
            vec![vec![[1.0, 0.5], [2.0, 0.5], [2.0, 1.5], [1.0, 1.5]]],
        );
        let g = rasterise(&def, 0.5).unwrap();
        assert_eq!(
            rows(&g),
            [
                "########", "#......#", "#..##..#", "#..##..#", "#......#", "########"
            ]
        );
    }

    #[test]
    fn thin_and_slanted_walls_are_not_lost() {
        // A wall 0.1 m thick between pixel centres, and a thin diagonal.
        let def = map(
            2.0,
            2.0,
            vec![
                vec![[0.55, 0.0], [0.65, 0.0], [0.65, 1.0], [0.55, 1.0]],
                vec![[1.0, 1.0], [1.9, 1.9], [1.9, 1.95]],
            ],
        );
        let g = rasterise(&def, 0.5).unwrap();
        assert_eq!(
            rows(&g),
            ["######", "#..###", "#..#.#", "#.#..#", "#.#..#", "######"]
        );
    }

    #[test]
    fn a_partial_last_pixel_is_wall_and_bad_resolutions_are_refused() {
        let g = rasterise(&map(1.2, 1.0, vec![]), 0.5).unwrap();
        assert_eq!(rows(&g), ["#####", "#..##", "#..##", "#####"]);
        assert!(rasterise(&map(1.0, 1.0, vec![]), 0.0).is_err());
        let e = rasterise(&map(500.0, 500.0, vec![]), 0.01)
            .unwrap_err()
            .to_string();
        assert!(e.contains("use 0.12"), "{e}");
    }
}
