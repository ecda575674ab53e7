//! ROS map_server maps: a YAML file of metadata and the image it names, read with
//! map_server's own semantics (ROS 1 `map_server/src/image_loader.cpp`), and our maps
//! written back out as such a pair.
//!
//! Each pixel becomes the value map_server would publish in its `OccupancyGrid`
//! ([`cell_value`]); a cell is free for us exactly when that value is 0 (free), so occupied
//! (100), unknown (-1) and, in `scale` mode, the shades between (1 to 99) are all walls: a
//! robot should not drive where nobody knows what is.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::maps::format::{ImportError, Problem, read_bounded};
use crate::maps::grid::Grid;
use crate::maps::image::{self, Image};
use crate::maps::json::MAX_MAP_BYTES;
use crate::maps::raster;
use lasertag_core::sim::arena::MapDef;

/// How map_server turns a pixel into an occupancy value (the YAML's `mode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// Occupied (100), free (0) or unknown (-1): the default.
    Trinary,
    /// As trinary, but the shades between the thresholds become 1 to 99, and a fully
    /// transparent one unknown.
    Scale,
    /// The (negated) pixel value itself.
    Raw,
}

/// The YAML file, as map_server reads it. Keys it does not know are ignored, as there.
#[derive(Debug, Deserialize)]
struct RosYaml {
    image: String,
    resolution: f64,
    origin: Vec<f64>,
    #[serde(deserialize_with = "zero_or_one")]
    negate: bool,
    occupied_thresh: f64,
    free_thresh: f64,
    #[serde(default)]
    mode: Option<String>,
}

/// map_server reads `negate` as an integer (non-zero is true); `true` and `false` are taken
/// too.
fn zero_or_one<'de, D: serde::Deserializer<'de>>(d: D) -> Result<bool, D::Error> {
    struct Flag;
    impl serde::de::Visitor<'_> for Flag {
        type Value = bool;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("0, 1, true or false")
        }
        fn visit_bool<E>(self, v: bool) -> Result<bool, E> {
            Ok(v)
        }
        fn visit_i64<E>(self, v: i64) -> Result<bool, E> {
            Ok(v != 0)
        }
        fn visit_u64<E>(self, v: u64) -> Result<bool, E> {
            Ok(v != 0)
        }
    }
    d.deserialize_any(Flag)
}

/// A ROS map's metadata, checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Meta {
    /// The image, resolved against the YAML file's folder when relative.
    pub image: PathBuf,
    /// Metres per pixel.
    pub resolution: f64,
    /// The pose of the lower-left pixel's corner: x, y (metres) and yaw (radians).
    pub origin: [f64; 3],
    pub negate: bool,
    pub occupied_thresh: f64,
    pub free_thresh: f64,
    pub mode: Mode,
}

/// Parses and checks the YAML text of `yaml_path` (which resolves a relative image).
pub fn parse_meta(text: &str, yaml_path: &Path) -> Result<Meta, Problem> {
    let y: RosYaml = serde_yaml_ng::from_str(text).map_err(|e| Problem::Content(e.to_string()))?;
    if !(y.resolution.is_finite() && y.resolution > 0.0) {
        return Err(Problem::field(
            "resolution",
            format!("{} must be a number of metres per pixel > 0", y.resolution),
        ));
    }
    let origin: [f64; 3] = match y.origin[..] {
        [x, y, yaw] if x.is_finite() && y.is_finite() && yaw.is_finite() => [x, y, yaw],
        _ => {
            return Err(Problem::field(
                "origin",
                format!("needs 3 finite numbers [x, y, yaw], got {:?}", y.origin),
            ));
        }
    };
    for (field, v) in [
        ("occupied_thresh", y.occupied_thresh),
        ("free_thresh", y.free_thresh),
    ] {
        if !(0.0..=1.0).contains(&v) {
            return Err(Problem::field(
                field,
                format!("{v} must be a probability from 0 to 1"),
            ));
        }
    }
    let mode = match y.mode.as_deref() {
        None | Some("trinary") => Mode::Trinary,
        Some("scale") => Mode::Scale,
        Some("raw") => Mode::Raw,
        Some(other) => {
            return Err(Problem::field(
                "mode",
                format!("{other:?} is not trinary, scale or raw"),
            ));
        }
    };
    if y.image.trim().is_empty() {
        return Err(Problem::field("image", "names no file"));
    }
    let image = Path::new(&y.image);
    let image = if image.is_absolute() {
        image.to_path_buf()
    } else {
        yaml_path
            .parent()
            .unwrap_or_else(|| Path::new(""))
            .join(image)
    };
    Ok(Meta {
        image,
        resolution: y.resolution,
        origin,
        negate: y.negate,
        occupied_thresh: y.occupied_thresh,
        free_thresh: y.free_thresh,
        mode,
    })
}

/// The value map_server publishes for one pixel's samples (`channels` of them, the last
/// one alpha when `alpha`):
/// - the mean of the channels (alpha among them in trinary mode, as map_server does),
///   turned over by `negate`;
/// - raw: that mean, as an `int8` (so 255 is -1, unknown);
/// - otherwise p = (255 - mean) / 255: occupied (100) when p > occupied_thresh, free (0)
///   when p < free_thresh, else unknown (-1) in trinary mode or for a fully transparent
///   pixel, and 1 + 98 (p - free) / (occupied - free) in scale mode.
///
/// map_server takes the third byte of an RGB pixel without alpha for its alpha; here such a
/// pixel is opaque. Either way the result is not 0, so the cell is a wall all the same.
pub fn cell_value(px: &[u8], alpha: bool, meta: &Meta) -> i8 {
    let n = px.len().max(1);
    let averaged = if meta.mode == Mode::Trinary || !alpha {
        n
    } else {
        n - 1
    };
    let sum: u32 = px.iter().take(averaged).map(|&v| u32::from(v)).sum();
    let mut mean = f64::from(sum) / averaged.max(1) as f64;
    let opaque = !alpha || px.last().is_some_and(|&a| a > 0);
    if meta.negate {
        mean = 255.0 - mean;
    }
    if meta.mode == Mode::Raw {
        // An int, then stored in the message's int8, as map_server does.
        return (mean as i32) as i8;
    }
    let occ = (255.0 - mean) / 255.0;
    if occ > meta.occupied_thresh {
        100
    } else if occ < meta.free_thresh {
        0
    } else if meta.mode == Mode::Trinary || !opaque {
        -1
    } else {
        let span = meta.occupied_thresh - meta.free_thresh;
        let ratio = if span > 0.0 {
            (occ - meta.free_thresh) / span
        } else {
            0.0
        };
        (1.0 + 98.0 * ratio) as i32 as i8
    }
}

/// map_server's `OccupancyGrid` data for `image`: row 0 is the image's bottom row.
pub fn occupancy(image: &Image, meta: &Meta) -> Vec<i8> {
    let mut data = Vec::with_capacity(image.width * image.height);
    for row in 0..image.height {
        let y = image.height - 1 - row;
        for x in 0..image.width {
            data.push(cell_value(image.pixel(x, y), image.has_alpha(), meta));
        }
    }
    data
}

/// Reads a ROS map: its occupancy as our grid (free exactly where map_server says 0) and
/// its origin.
pub fn read(yaml_path: &Path) -> Result<(Grid, [f64; 3]), ImportError> {
    let bytes = read_bounded(yaml_path)?;
    if bytes.len() > MAX_MAP_BYTES {
        return Err(Problem::Content(format!(
            "{} bytes, the limit for a map's YAML is {MAX_MAP_BYTES}",
            bytes.len()
        ))
        .in_file(yaml_path));
    }
    let text = String::from_utf8(bytes)
        .map_err(|_| Problem::Content("not UTF-8 text".into()).in_file(yaml_path))?;
    let meta = parse_meta(&text, yaml_path).map_err(|p| p.in_file(yaml_path))?;
    if !meta.image.is_file() {
        return Err(
            Problem::field("image", format!("{} is not a file", meta.image.display()))
                .in_file(yaml_path),
        );
    }
    let bytes = read_bounded(&meta.image)?;
    let image = image::decode(&bytes).map_err(|p| p.in_file(&meta.image))?;
    let data = occupancy(&image, &meta);
    let grid = Grid {
        cols: image.width,
        rows: image.height,
        cell: meta.resolution,
        blocked: data.iter().map(|&v| v != 0).collect(),
    };
    Ok((grid, meta.origin))
}

/// A map that could not be exported: the file (or folder), then what went wrong.
#[derive(Debug, thiserror::Error)]
#[error("{file}: {problem}")]
pub struct ExportError {
    pub file: String,
    pub problem: Problem,
}

/// The files an export wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct Exported {
    pub yaml: PathBuf,
    pub image: PathBuf,
    /// The image's columns and rows.
    pub pixels: [usize; 2],
}

/// Writes `def` into `dir` as `<name>.yaml` and `<name>.pgm` at `resolution` metres per
/// pixel, in trinary mode with map_saver's values (0 occupied, 254 free) and thresholds.
/// The border becomes a ring of occupied pixels around the arena (`raster::rasterise`),
/// so the image's lower-left corner is one pixel below and left of the arena's (0, 0),
/// which lies at `origin` (x, y, yaw) in the ROS frame.
pub fn export(
    def: &MapDef,
    origin: [f64; 3],
    resolution: f64,
    dir: &Path,
) -> Result<Exported, ExportError> {
    let fail = |file: &Path, problem: Problem| ExportError {
        file: file.display().to_string(),
        problem,
    };
    if !origin.iter().all(|v| v.is_finite()) {
        return Err(fail(
            dir,
            Problem::field("origin", format!("{origin:?} must be 3 finite numbers")),
        ));
    }
    let grid = raster::rasterise(def, resolution).map_err(|p| fail(dir, p))?;
    let mut samples = Vec::with_capacity(grid.cols * grid.rows);
    for row in (0..grid.rows).rev() {
        for c in 0..grid.cols {
            samples.push(if grid.is_blocked(c, row) { 0 } else { 254 });
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| fail(dir, Problem::Io(e)))?;
    let image = dir.join(format!("{}.pgm", def.name));
    let yaml = dir.join(format!("{}.yaml", def.name));
    let comment = format!("CREATOR: lasertag map export {resolution} m/pix");
    let pgm = image::encode_pgm(grid.cols, grid.rows, &samples, &comment);
    std::fs::write(&image, pgm).map_err(|e| fail(&image, Problem::Io(e)))?;
    // The image's corner is the arena's (-resolution, -resolution), turned by the yaw.
    let (s, c) = origin[2].sin_cos();
    let corner = [
        origin[0] - resolution * (c - s),
        origin[1] - resolution * (s + c),
    ];
    let tidy = |v: f64| (v * 1e9).round() / 1e9 + 0.0;
    let text = format!(
        "image: {}.pgm\nmode: trinary\nresolution: {resolution}\norigin: [{}, {}, {}]\n\
         negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
        def.name,
        tidy(corner[0]),
        tidy(corner[1]),
        tidy(origin[2]),
    );
    std::fs::write(&yaml, text).map_err(|e| fail(&yaml, Problem::Io(e)))?;
    Ok(Exported {
        yaml,
        image,
        pixels: [grid.cols, grid.rows],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meta(mode: Mode, negate: bool) -> Meta {
        Meta {
            image: PathBuf::from("m.pgm"),
            resolution: 0.05,
            origin: [0.0; 3],
            negate,
            occupied_thresh: 0.65,
            free_thresh: 0.196,
            mode,
        }
    }

    #[test]
    fn trinary_thresholds_follow_map_server() {
        let m = meta(Mode::Trinary, false);
        // p = (255 - v) / 255: 0 → 1.0, 254 → 0.004, 205 → 0.196 (not below free_thresh).
        assert_eq!(cell_value(&[0], false, &m), 100);
        assert_eq!(cell_value(&[254], false, &m), 0);
        assert_eq!(cell_value(&[255], false, &m), 0);
        assert_eq!(cell_value(&[205], false, &m), -1);
        assert_eq!(cell_value(&[206], false, &m), 0);
        // p = 0.65 exactly is not above occupied_thresh: 255 - 0.65 × 255 = 89.25.
        assert_eq!(cell_value(&[89], false, &m), 100);
        assert_eq!(cell_value(&[90], false, &m), -1);
        // Colour is averaged; in trinary mode alpha is averaged in too.
        assert_eq!(cell_value(&[255, 255, 255], false, &m), 0);
        assert_eq!(cell_value(&[255, 255, 255, 255], true, &m), 0);
        assert_eq!(cell_value(&[0, 0, 0, 255], true, &m), 100);
        // Transparent white: (3 × 255 + 0) / 4 = 191.25, p = 0.25, unknown.
        assert_eq!(cell_value(&[255, 255, 255, 0], true, &m), -1);
    }

    #[test]
    fn negate_turns_white_into_wall() {
        let m = meta(Mode::Trinary, true);
        assert_eq!(cell_value(&[0], false, &m), 0);
        assert_eq!(cell_value(&[255], false, &m), 100);
        assert_eq!(cell_value(&[50], false, &m), -1); // p = 50 / 255 = 0.196
    }

    #[test]
    fn scale_shades_between_thresholds_and_raw_passes_values() {
        let s = meta(Mode::Scale, false);
        assert_eq!(cell_value(&[0], false, &s), 100);
        assert_eq!(cell_value(&[254], false, &s), 0);
        // p = 128 / 255 = 0.502: 1 + 98 × (0.502 - 0.196) / (0.65 - 0.196) = 67.04 → 67.
        assert_eq!(cell_value(&[127], false, &s), 67);
        // Alpha is not averaged in scale mode; a transparent shade is unknown.
        assert_eq!(cell_value(&[127, 127, 127, 255], true, &s), 67);
        assert_eq!(cell_value(&[127, 127, 127, 0], true, &s), -1);
        assert_eq!(cell_value(&[0, 0, 0, 0], true, &s), 100);
        let t = meta(Mode::Trinary, false);
        assert_eq!(cell_value(&[127], false, &t), -1);

        let r = meta(Mode::Raw, false);
        assert_eq!(cell_value(&[0], false, &r), 0);
        assert_eq!(cell_value(&[100], false, &r), 100);
        assert_eq!(cell_value(&[255], false, &r), -1);
        assert_eq!(cell_value(&[0], false, &meta(Mode::Raw, true)), -1);
    }

    #[test]
    fn occupancy_rows_start_at_the_bottom() {
        let img = Image {
            width: 2,
            height: 2,
            channels: 1,
            samples: vec![0, 0, 254, 254],
        };
        assert_eq!(
            occupancy(&img, &meta(Mode::Trinary, false)),
            vec![0, 0, 100, 100]
        );
    }

    #[test]
    fn yaml_fields_are_checked_and_named() {
        let base = "image: m.pgm\nresolution: 0.05\norigin: [-1.0, 2, 0.5]\nnegate: 0\n\
                    occupied_thresh: 0.65\nfree_thresh: 0.196\n";
        let at = Path::new("maps/lab.yaml");
        let m = parse_meta(base, at).unwrap();
        assert_eq!(m.image, PathBuf::from("maps/m.pgm"));
        assert_eq!(
            (m.origin, m.mode, m.negate),
            ([-1.0, 2.0, 0.5], Mode::Trinary, false)
        );
        let with = |extra: &str| format!("{base}{extra}");
        assert_eq!(
            parse_meta(&with("mode: scale\n"), at).unwrap().mode,
            Mode::Scale
        );
        assert_eq!(
            parse_meta(&with("mode: raw\n"), at).unwrap().mode,
            Mode::Raw
        );
        assert!(
            parse_meta(&base.replace("negate: 0", "negate: true"), at)
                .unwrap()
                .negate
        );
        let abs = base.replace("m.pgm", "/data/m.png");
        assert_eq!(
            parse_meta(&abs, at).unwrap().image,
            PathBuf::from("/data/m.png")
        );
        let cases = [
            (
                with("mode: fancy\n"),
                "mode: \"fancy\" is not trinary, scale or raw",
            ),
            (base.replace("0.05", "-1"), "resolution: -1 must be"),
            (base.replace("0.05", "abc"), "resolution: invalid type"),
            (
                base.replace("[-1.0, 2, 0.5]", "[1, 2]"),
                "origin: needs 3 finite numbers",
            ),
            (
                base.replace("0.65", "1.5"),
                "occupied_thresh: 1.5 must be a probability",
            ),
            (base.replace("negate: 0\n", ""), "missing field `negate`"),
            (
                base.replace("negate: 0", "negate: maybe"),
                "negate: invalid type",
            ),
            (
                base.replace("image: m.pgm", "image: ''"),
                "image: names no file",
            ),
            ("resolution: [".to_string(), "line 1"),
        ];
        for (text, want) in cases {
            let e = parse_meta(&text, at).unwrap_err().to_string();
            assert!(e.contains(want), "{e:?} lacks {want:?}");
        }
    }
}
