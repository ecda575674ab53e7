//! The maps the import tests draw: a ROS picture of rectangles in any image kind, a
//! folder per test, and the checks and distances the tests compare against.

use std::path::{Path, PathBuf};

use lasertag::maps::image;
use lasertag_core::nav::DistanceField;
use lasertag_core::sim::arena::Arena;
use nalgebra::Point2;

/// A fresh, empty folder for one test.
pub fn folder(test: &str) -> PathBuf {
    let dir =
        std::env::temp_dir().join(format!("lasertag-map-import-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A wall rectangle `[x0, y0, x1, y1]` in arena metres.
pub type Rect = [f64; 4];

pub fn polygon(r: Rect) -> Vec<[f64; 2]> {
    vec![[r[0], r[1]], [r[2], r[1]], [r[2], r[3]], [r[0], r[3]]]
}

/// A ROS picture of an arena `cols` × `rows` cells of `res` metres with `walls` drawn black
/// (a cell is a wall when its centre is in one), free white (254), and a `margin` of unknown
/// grey (205) around it, rows from the top.
pub struct Picture {
    pub cols: usize,
    pub rows: usize,
    pub margin: usize,
    pub res: f64,
    pub walls: Vec<Rect>,
}

impl Picture {
    fn size(&self) -> (usize, usize) {
        (self.cols + 2 * self.margin, self.rows + 2 * self.margin)
    }

    /// 0 for wall, 254 for free, 205 for unknown, by pixel (x from the left, y from the top).
    fn grey(&self, x: usize, y: usize) -> u8 {
        let (_, h) = self.size();
        let m = self.margin as isize;
        let (c, r) = (x as isize - m, (h - 1 - y) as isize - m);
        if c < 0 || r < 0 || c >= self.cols as isize || r >= self.rows as isize {
            return 205;
        }
        let (cx, cy) = ((c as f64 + 0.5) * self.res, (r as f64 + 0.5) * self.res);
        let inside = self
            .walls
            .iter()
            .any(|q| cx > q[0] && cx < q[2] && cy > q[1] && cy < q[3]);
        if inside { 0 } else { 254 }
    }

    fn greys(&self) -> Vec<u8> {
        let (w, h) = self.size();
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| self.grey(x, y))
            .collect()
    }

    /// Writes `<stem>.yaml` and its image (`kind`: p5, p2, png, rgb-negated or rgba-scale)
    /// into `dir`.
    pub fn write(&self, dir: &Path, stem: &str, kind: &str, origin: [f64; 2]) -> PathBuf {
        let (w, h) = self.size();
        let greys = self.greys();
        let (file, bytes, negate) = match kind {
            "p5" => (
                format!("{stem}.pgm"),
                image::encode_pgm(w, h, &greys, "CREATOR: test"),
                0,
            ),
            "p2" => {
                let mut text = format!("P2\n# plain\n{w} {h}\n255\n");
                for row in greys.chunks(w) {
                    let line: Vec<String> = row.iter().map(u8::to_string).collect();
                    text.push_str(&line.join(" "));
                    text.push('\n');
                }
                (format!("{stem}.pgm"), text.into_bytes(), 0)
            }
            "png" => (
                format!("{stem}.png"),
                image::encode_png(w, h, &greys).unwrap(),
                0,
            ),
            "rgb-negated" => {
                // White walls on black: negate 1 reads them as the same map.
                let rgb: Vec<u8> = greys.iter().flat_map(|&g| [255 - g; 3]).collect();
                (
                    format!("{stem}.png"),
                    png_of(w, h, png::ColorType::Rgb, &rgb),
                    1,
                )
            }
            "rgba-scale" => {
                // Opaque colour in scale mode, where alpha is not averaged in: unknown grey
                // reads as a shade (1), a wall all the same.
                let rgba: Vec<u8> = greys.iter().flat_map(|&g| [g, g, g, 255]).collect();
                (
                    format!("{stem}.png"),
                    png_of(w, h, png::ColorType::Rgba, &rgba),
                    0,
                )
            }
            other => panic!("no image kind {other}"),
        };
        std::fs::write(dir.join(&file), bytes).unwrap();
        let yaml = dir.join(format!("{stem}.yaml"));
        std::fs::write(
            &yaml,
            format!(
                "image: {file}\nresolution: {}\norigin: [{}, {}, 0.0]\nnegate: {negate}\n\
                 occupied_thresh: 0.65\nfree_thresh: 0.196\nmode: {}\n",
                self.res,
                origin[0],
                origin[1],
                if kind == "rgba-scale" {
                    "scale"
                } else {
                    "trinary"
                }
            ),
        )
        .unwrap();
        yaml
    }
}

pub fn png_of(w: usize, h: usize, colour: png::ColorType, samples: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut enc = png::Encoder::new(&mut out, w as u32, h as u32);
    enc.set_color(colour);
    let mut writer = enc.write_header().unwrap();
    writer.write_image_data(samples).unwrap();
    writer.finish().unwrap();
    out
}

/// A 10 m × 7.5 m room at 0.25 m with a pillar, a wall from the top with a gap, and a crate
/// on the bottom edge; two cells of unknown around it (cropped away on import).
pub fn room() -> Picture {
    Picture {
        cols: 40,
        rows: 30,
        margin: 2,
        res: 0.25,
        walls: vec![
            [2.0, 2.0, 3.0, 3.5],
            [6.0, 4.0, 6.5, 7.5],
            [8.0, 0.0, 9.25, 0.75],
        ],
    }
}

/// Every spawn of `def` can reach every other through free space (as `shipped_maps` checks).
pub fn spawns_reach_each_other(arena: &Arena) {
    let def = &arena.def;
    let spawns: Vec<Point2<f32>> = def
        .robot_spawns
        .iter()
        .map(|s| Point2::new(s[0], s[1]))
        .chain(def.opponent_spawns.iter().copied())
        .collect();
    let field = DistanceField::from_point(&arena.grid, spawns[0]).expect("first spawn free");
    for (k, s) in spawns.iter().enumerate() {
        let cell = arena
            .grid
            .nearest_passable(*s, 10)
            .expect("spawn not boxed in");
        assert!(field.reachable(cell), "spawn {k} at {s:?} is unreachable");
    }
}

/// Distance from `p` along `dir` to the first of `walls` or the arena's border.
pub fn analytic_range(p: [f64; 2], dir: [f64; 2], walls: &[Rect], size: [f64; 2]) -> f64 {
    let mut best = f64::INFINITY;
    // The border, as the inside of a box.
    for axis in 0..2 {
        if dir[axis] > 1e-12 {
            best = best.min((size[axis] - p[axis]) / dir[axis]);
        } else if dir[axis] < -1e-12 {
            best = best.min(-p[axis] / dir[axis]);
        }
    }
    // Each wall, by the slab method.
    for q in walls {
        let (lo, hi) = ([q[0], q[1]], [q[2], q[3]]);
        let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
        for axis in 0..2 {
            if dir[axis].abs() < 1e-12 {
                if p[axis] < lo[axis] || p[axis] > hi[axis] {
                    t0 = f64::INFINITY;
                }
                continue;
            }
            let a = (lo[axis] - p[axis]) / dir[axis];
            let b = (hi[axis] - p[axis]) / dir[axis];
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        if t0 <= t1 {
            best = best.min(t0);
        }
    }
    best
}
