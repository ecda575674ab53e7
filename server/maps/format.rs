//! What every imported map format shares: the kinds of map file, the bounds on what is
//! read, and what can be wrong with a file ([`Problem`], and [`ImportError`] naming the
//! file). Every error names the file, and the field or line where it can; every size is
//! bounded before anything is allocated for it.

use std::io::Read;
use std::path::Path;

use crate::maps::json::MapError;

/// The kinds of map file a folder may hold, by extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FileKind {
    /// Ours (`docs/map-format.md`).
    Json,
    /// A ROS map_server YAML file and the image it names.
    Ros,
    /// A MovingAI benchmark grid.
    MovingAi,
}

impl FileKind {
    /// The kind a file's extension says, if it is a map file at all.
    pub fn of(path: &Path) -> Option<FileKind> {
        match path.extension()?.to_str()? {
            "json" => Some(FileKind::Json),
            "yaml" => Some(FileKind::Ros),
            "map" => Some(FileKind::MovingAi),
            _ => None,
        }
    }
}

/// Most bytes read from one imported file (a YAML, an image or a MovingAI grid): a plain
/// (ASCII) PGM of the largest grid takes up to 4 bytes a cell.
pub const MAX_FILE_BYTES: u64 = 4 * MAX_CELLS as u64 + 4096;

/// Most cells (pixels) a grid may have: 4096 × 4096, the size of the maps gmapping writes
/// by default (4000 × 4000), so real SLAM maps fit. The importer holds a few bytes a cell.
pub const MAX_CELLS: usize = 4096 * 4096;

/// What is wrong with an imported file; [`ImportError`] adds which file.
#[derive(Debug, thiserror::Error)]
pub enum Problem {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("line {line}: {message}")]
    Line { line: usize, message: String },
    #[error("{field}: {message}")]
    Field { field: String, message: String },
    #[error("{0}")]
    Content(String),
    /// The converted map broke a rule of our format (the validator's error).
    #[error("{0}")]
    Invalid(#[from] MapError),
}

impl Problem {
    pub fn line(line: usize, message: impl Into<String>) -> Problem {
        Problem::Line {
            line,
            message: message.into(),
        }
    }

    pub fn field(field: impl Into<String>, message: impl Into<String>) -> Problem {
        Problem::Field {
            field: field.into(),
            message: message.into(),
        }
    }

    /// This problem, found in `file`.
    pub fn in_file(self, file: &Path) -> ImportError {
        ImportError {
            file: file.display().to_string(),
            problem: self,
        }
    }
}

/// A map file that could not be imported: the file, then what is wrong with it.
#[derive(Debug, thiserror::Error)]
#[error("{file}: {problem}")]
pub struct ImportError {
    pub file: String,
    pub problem: Problem,
}

/// Reads a whole file of at most [`MAX_FILE_BYTES`].
pub fn read_bounded(path: &Path) -> Result<Vec<u8>, ImportError> {
    let file = std::fs::File::open(path).map_err(|e| Problem::Io(e).in_file(path))?;
    let mut bytes = Vec::new();
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| Problem::Io(e).in_file(path))?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(Problem::Content(format!(
            "larger than {MAX_FILE_BYTES} bytes, the limit for an imported file"
        ))
        .in_file(path));
    }
    Ok(bytes)
}
