//! Importing maps researchers already have: a ROS map_server map or a MovingAI grid, read
//! into an occupancy [`Grid`], then converted into one of our maps ([`to_map_file`]) and
//! checked by the same validator as a map written by hand.
//!
//! Every error names the file, and the field or line where it can; nothing a file holds
//! reaches an `unwrap`, and every size is bounded before anything is allocated for it.

use std::path::Path;

use lasertag_core::sim::arena::MapDef;

use crate::maps::format::{FileKind, ImportError, MAX_CELLS, Problem, read_bounded};
use crate::maps::grid::{Grid, MAX_SIDE, round};
use crate::maps::json::{MAX_MAP_BYTES, MapFile, validate};
use crate::maps::{movingai, ros, spawns};
use crate::schema::MAX_VERTICES;

/// How to read an imported map.
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// Metres per cell of a MovingAI grid (which has no unit); 1 m when `None`. A ROS map's
    /// YAML gives its own resolution, so this is refused for one.
    pub cell_size: Option<f64>,
    /// Merge blocks of `coarsen` × `coarsen` cells into one (a wall when any of them is), for
    /// maps too detailed for the 10,000-vertex limit. 1 keeps the grid as it is.
    pub coarsen: usize,
    /// Cut away the rows and columns at the edges that hold no free cell (they are wall
    /// either way, since the arena's border is a wall).
    pub crop: bool,
    /// The map's name; the file's stem made a valid name when `None`.
    pub name: Option<String>,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            cell_size: None,
            coarsen: 1,
            crop: true,
            name: None,
        }
    }
}

/// An imported map: the JSON shape (with round numbers, for writing), the validated
/// definition, and where it lies in the source's frame.
#[derive(Debug, Clone)]
pub struct Imported {
    pub file: MapFile,
    pub def: MapDef,
    /// The source frame's coordinates of the arena's (0, 0), and the source's yaw (radians):
    /// a ROS map's origin moved by the cells cropped away. A ROS export of this map given
    /// this origin lines up with the source.
    pub origin: [f64; 3],
    /// Metres per cell of the grid the obstacles were built from.
    pub cell: f64,
    /// Columns and rows of that grid.
    pub cells: [usize; 2],
}

/// Imports a ROS map_server YAML (`.yaml`) or a MovingAI grid (`.map`).
pub fn import_file(path: &Path, options: &ImportOptions) -> Result<Imported, ImportError> {
    if options.coarsen == 0 || options.coarsen > 64 {
        return Err(
            Problem::field("resolution-scale", "must be a whole number from 1 to 64").in_file(path),
        );
    }
    let name = match &options.name {
        Some(n) => n.clone(),
        None => map_name(
            path.file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or_default(),
        ),
    };
    let (grid, origin) = match FileKind::of(path) {
        Some(FileKind::Ros) => {
            if options.cell_size.is_some() {
                return Err(Problem::field(
                    "cell-size",
                    "applies to MovingAI maps; a ROS map's YAML gives its resolution",
                )
                .in_file(path));
            }
            ros::read(path)?
        }
        Some(FileKind::MovingAi) => {
            let cell = options.cell_size.unwrap_or(1.0);
            if !(cell.is_finite() && cell > 0.0) {
                return Err(
                    Problem::field("cell-size", format!("{cell} must be a number > 0"))
                        .in_file(path),
                );
            }
            let bytes = read_bounded(path)?;
            let grid = movingai::parse(&bytes, cell).map_err(|p| p.in_file(path))?;
            (grid, [0.0; 3])
        }
        _ => {
            return Err(Problem::Content(
                "imports read ROS map_server maps (.yaml) and MovingAI grids (.map)".into(),
            )
            .in_file(path));
        }
    };
    convert(grid, origin, &name, options).map_err(|p| p.in_file(path))
}

/// A grid (row 0 at the bottom) with its origin, made one of our maps: coarsened and
/// cropped as `options` say, walls as rectangles, spawns and landmarks placed, validated.
pub fn convert(
    grid: Grid,
    origin: [f64; 3],
    name: &str,
    options: &ImportOptions,
) -> Result<Imported, Problem> {
    let mut grid = grid.coarsen(options.coarsen);
    let mut origin = origin;
    if options.crop {
        let (cropped, [c0, r0]) = grid.crop().ok_or_else(no_free_cell)?;
        // The cropped grid's (0, 0) is cell (c0, r0) of the source, in the source's frame
        // (rotated by its yaw, as map_server's origin is).
        let (dx, dy) = (c0 as f64 * grid.cell, r0 as f64 * grid.cell);
        let (s, c) = origin[2].sin_cos();
        origin[0] += c * dx - s * dy;
        origin[1] += s * dx + c * dy;
        grid = cropped;
    }
    // Nanometres: the sums above leave digits in the last place that mean nothing.
    let origin = origin.map(|v| (v * 1e9).round() / 1e9 + 0.0);
    let file = to_map_file(&grid, name)?;
    let def = validate(&file)?;
    let text = to_json(&file);
    if text.len() > MAX_MAP_BYTES {
        return Err(Problem::Content(format!(
            "the converted map takes {} bytes of JSON, the limit is {MAX_MAP_BYTES}: coarsen \
             it (--resolution-scale)",
            text.len()
        )));
    }
    Ok(Imported {
        file,
        def,
        origin,
        cell: grid.cell,
        cells: [grid.cols, grid.rows],
    })
}

fn no_free_cell() -> Problem {
    Problem::Content(
        "the map has no free cell: every cell is occupied or unknown (unknown counts as wall)"
            .into(),
    )
}

/// The grid made one of our maps (not yet validated): the arena is the grid's extent, each
/// wall rectangle an obstacle, spawns and landmarks from [`spawns::place`].
pub fn to_map_file(grid: &Grid, name: &str) -> Result<MapFile, Problem> {
    if grid.cols * grid.rows > MAX_CELLS {
        return Err(Problem::Content(format!(
            "{} × {} cells, the limit is {MAX_CELLS}",
            grid.cols, grid.rows
        )));
    }
    let width = round(grid.cols as f64 * grid.cell);
    let height = round(grid.rows as f64 * grid.cell);
    if width > MAX_SIDE || height > MAX_SIDE {
        let most = MAX_SIDE / grid.cols.max(grid.rows) as f64;
        return Err(Problem::Content(format!(
            "the map is {width} m × {height} m ({} × {} cells of {} m), the limit is {MAX_SIDE} \
             m a side: a MovingAI map needs a --cell-size of at most {most:.3}; a ROS map this \
             big is not an arena for robots that see 8 m",
            grid.cols,
            grid.rows,
            round(grid.cell)
        )));
    }
    let count = grid.count_rectangles();
    if count * 4 > MAX_VERTICES {
        return Err(Problem::Content(format!(
            "its walls make {count} rectangles ({} vertices), the limit is {MAX_VERTICES} \
             vertices: coarsen the grid (--resolution-scale 2 or more)",
            count * 4
        )));
    }
    let rects = grid.rectangles();
    let at = |k: usize| round(k as f64 * grid.cell);
    let obstacles = rects
        .iter()
        .map(|q| {
            let (x0, x1, y0, y1) = (at(q.c0), at(q.c1), at(q.r0), at(q.r1));
            vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
        })
        .collect();
    let placed = spawns::place(grid)?;
    Ok(MapFile {
        name: name.to_string(),
        width,
        height,
        obstacles,
        robot_spawns: placed.robots,
        opponent_spawns: placed.opponents,
        landmarks: placed.landmarks,
    })
}

/// A file's stem made a map name: lower case, every character other than `a-z 0-9 - _`
/// turned into `-` (runs of them into one), at most 64 characters; `map` when nothing is left.
pub fn map_name(stem: &str) -> String {
    let mut out = String::new();
    for ch in stem.chars().flat_map(char::to_lowercase) {
        let ok = ch.is_ascii_lowercase() || ch.is_ascii_digit() || ch == '_' || ch == '-';
        if ok {
            out.push(ch);
        } else if !out.ends_with('-') {
            out.push('-');
        }
    }
    let trimmed: String = out.trim_matches('-').chars().take(64).collect();
    let trimmed = trimmed.trim_end_matches('-');
    if trimmed.is_empty() {
        "map".to_string()
    } else {
        trimmed.to_string()
    }
}

/// A map file as JSON text, one polygon or point per line so that a large imported map
/// stays readable and within [`MAX_MAP_BYTES`].
pub fn to_json(file: &MapFile) -> String {
    fn list<T: serde::Serialize>(out: &mut String, key: &str, items: &[T], last: bool) {
        out.push_str(&format!("  \"{key}\": ["));
        for (i, item) in items.iter().enumerate() {
            let text = serde_json::to_string(item).unwrap_or_default();
            let comma = if i + 1 < items.len() { "," } else { "" };
            out.push_str(&format!("\n    {text}{comma}"));
        }
        if !items.is_empty() {
            out.push_str("\n  ");
        }
        out.push_str(if last { "]\n" } else { "],\n" });
    }
    let mut out = String::from("{\n");
    let name = serde_json::to_string(&file.name).unwrap_or_default();
    out.push_str(&format!("  \"name\": {name},\n"));
    out.push_str(&format!("  \"width\": {:?},\n", file.width));
    out.push_str(&format!("  \"height\": {:?},\n", file.height));
    list(&mut out, "obstacles", &file.obstacles, false);
    list(&mut out, "robot_spawns", &file.robot_spawns, false);
    let landmarks = !file.landmarks.is_empty();
    list(
        &mut out,
        "opponent_spawns",
        &file.opponent_spawns,
        !landmarks,
    );
    if landmarks {
        list(&mut out, "landmarks", &file.landmarks, true);
    }
    out.push('}');
    out.push('\n');
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_stems_become_map_names() {
        assert_eq!(map_name("office"), "office");
        assert_eq!(map_name("Berlin_0_256"), "berlin_0_256");
        assert_eq!(map_name("My Lab (2nd floor)"), "my-lab-2nd-floor");
        assert_eq!(map_name("..."), "map");
        assert_eq!(map_name(""), "map");
        assert_eq!(map_name(&"a".repeat(100)).len(), 64);
    }

    #[test]
    fn written_json_parses_back_to_the_same_map() {
        let file = MapFile {
            name: "t".into(),
            width: 10.0,
            height: 6.0,
            obstacles: vec![vec![[4.0, 2.0], [6.0, 2.0], [6.0, 4.0], [4.0, 4.0]]],
            robot_spawns: vec![[1.0, 1.0, 0.5]],
            opponent_spawns: vec![[9.0, 5.0]],
            landmarks: vec![],
        };
        let text = to_json(&file);
        let back: MapFile = serde_json::from_str(&text).unwrap();
        assert_eq!(back, file);
        assert!(crate::maps::parse(&text).is_ok());
    }
}
