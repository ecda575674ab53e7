//! The binary's `map` commands: `import` a ROS or MovingAI map as one of ours, `export` one
//! of ours as a ROS map. Here rather than in `main.rs` so that tests can run them in-process
//! and `main.rs` stays the serving binary's outline.

use std::path::{Path, PathBuf};

use crate::maps::import::{self, ImportOptions};
use crate::maps::ros::{self, ExportError};
use crate::maps::store::{self, LoadError, LoadedMap};

/// `lasertag map …`.
#[derive(Debug, Clone, clap::Subcommand)]
pub enum MapCommand {
    /// Convert a ROS map_server map (.yaml and its PGM or PNG) or a MovingAI grid (.map) into
    /// one of our maps (docs/map-import.md).
    Import(ImportArgs),
    /// Write one of our maps as a ROS map_server map: <name>.yaml and <name>.pgm.
    Export(ExportArgs),
}

#[derive(Debug, Clone, clap::Args)]
pub struct ImportArgs {
    /// The ROS YAML file or the MovingAI .map file.
    pub file: PathBuf,
    /// Where to write the map [default: maps/<name>.json].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The map's name [default: the file's name, made a-z 0-9 - _].
    #[arg(long)]
    pub name: Option<String>,
    /// Merge K × K cells into one, a wall where any of them is: fewer, larger walls, for a
    /// map too detailed for the 10,000-vertex limit.
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub resolution_scale: usize,
    /// Metres per cell of a MovingAI grid.
    #[arg(long, value_name = "METRES")]
    pub cell_size: Option<f64>,
    /// Keep the grid's whole extent instead of cropping the margins that hold no free cell.
    #[arg(long)]
    pub keep_extent: bool,
    /// Overwrite the output file when it exists.
    #[arg(long)]
    pub force: bool,
}

#[derive(Debug, Clone, clap::Args)]
pub struct ExportArgs {
    /// A map's name (looked up in --maps) or a map file (.json, .yaml or .map).
    pub map: String,
    /// The folder to write <name>.yaml and <name>.pgm into.
    #[arg(long)]
    pub out: PathBuf,
    /// Metres per pixel.
    #[arg(long, default_value_t = 0.05)]
    pub resolution: f64,
    /// Where the arena's (0, 0) lies in the ROS frame, and the frame's yaw [default: the
    /// source's origin for a ROS map, else 0,0,0].
    #[arg(long, value_name = "X,Y,YAW", value_parser = parse_origin, allow_hyphen_values = true)]
    pub origin: Option<[f64; 3]>,
    /// The folder of maps a name is looked up in.
    #[arg(long, env = "LASERTAG_MAPS", default_value = "maps")]
    pub maps: PathBuf,
}

fn parse_origin(text: &str) -> Result<[f64; 3], String> {
    let parts: Vec<f64> = text
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("{text:?}: {e}"))?;
    match parts[..] {
        [x, y, yaw] if parts.iter().all(|v| v.is_finite()) => Ok([x, y, yaw]),
        _ => Err(format!("{text:?}: expected three finite numbers X,Y,YAW")),
    }
}

/// Why a `map` command failed.
#[derive(Debug, thiserror::Error)]
pub enum MapCliError {
    #[error(transparent)]
    Load(#[from] LoadError),
    #[error(transparent)]
    Export(#[from] ExportError),
    #[error("{0}")]
    Usage(String),
    #[error("{file}: {source}")]
    Write {
        file: String,
        source: std::io::Error,
    },
}

/// Runs a `map` command; returns what to print.
pub fn run(command: &MapCommand) -> Result<String, MapCliError> {
    match command {
        MapCommand::Import(args) => import(args),
        MapCommand::Export(args) => export(args),
    }
}

fn import(args: &ImportArgs) -> Result<String, MapCliError> {
    let options = ImportOptions {
        cell_size: args.cell_size,
        coarsen: args.resolution_scale,
        crop: !args.keep_extent,
        name: args.name.clone(),
    };
    let imported = import::import_file(&args.file, &options).map_err(LoadError::from)?;
    let name = &imported.file.name;
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| Path::new("maps").join(format!("{name}.json")));
    if out.file_stem().and_then(|s| s.to_str()) != Some(name.as_str()) {
        return Err(MapCliError::Usage(format!(
            "{}: the map is named {name:?} and a map file must be named {name}.json (or give \
             --name)",
            out.display()
        )));
    }
    if out.exists() && !args.force {
        return Err(MapCliError::Usage(format!(
            "{}: exists; give --force to overwrite it",
            out.display()
        )));
    }
    let write = |source| MapCliError::Write {
        file: out.display().to_string(),
        source,
    };
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(write)?;
    }
    std::fs::write(&out, import::to_json(&imported.file)).map_err(write)?;
    let f = &imported.file;
    let vertices: usize = f.obstacles.iter().map(Vec::len).sum();
    let [ox, oy, yaw] = imported.origin;
    Ok(format!(
        "imported {} as {name:?}: {} m × {} m ({} × {} cells of {} m), {} walls ({vertices} \
         vertices), {} robot spawns, {} opponent spawns, {} landmarks\nwrote {}\nthe arena's \
         (0, 0) is at ({ox}, {oy}) in the source's frame, yaw {yaw}: `lasertag map export \
         {name} --out DIR --origin={ox},{oy},{yaw}` lines an export up with the source\n",
        args.file.display(),
        f.width,
        f.height,
        imported.cells[0],
        imported.cells[1],
        crate::maps::grid::round(imported.cell),
        f.obstacles.len(),
        f.robot_spawns.len(),
        f.opponent_spawns.len(),
        f.landmarks.len(),
        out.display(),
    ))
}

fn export(args: &ExportArgs) -> Result<String, MapCliError> {
    let given = Path::new(&args.map);
    let path = if given.is_file() {
        given.to_path_buf()
    } else {
        store::find_map_file(&args.maps, &args.map)?.ok_or_else(|| {
            MapCliError::Usage(format!(
                "{}: no file, and no map named {:?} in {}",
                args.map,
                args.map,
                args.maps.display()
            ))
        })?
    };
    let LoadedMap { def, origin } = store::load_file(&path, &ImportOptions::default())?;
    let origin = args.origin.unwrap_or(origin);
    let done = ros::export(&def, origin, args.resolution, &args.out)?;
    Ok(format!(
        "exported {} ({}): {} × {} pixels of {} m\nwrote {} and {}\n",
        def.name,
        path.display(),
        done.pixels[0],
        done.pixels[1],
        args.resolution,
        done.yaml.display(),
        done.image.display(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn origins_are_three_numbers() {
        assert_eq!(parse_origin("-10,-5.5,0.1"), Ok([-10.0, -5.5, 0.1]));
        assert!(parse_origin("1,2").is_err());
        assert!(parse_origin("1,2,x").is_err());
        assert!(parse_origin("1,2,inf").is_err());
    }
}
