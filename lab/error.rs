//! What can stop an experiment: bad arguments, missing maps, a scenario the chosen map
//! cannot hold, the files it writes, and parts that do not merge.

use std::path::{Path, PathBuf};

use lasertag_core::settings::FieldError;
use lasertag_core::world::{OrderError, SetupError};

#[derive(Debug, thiserror::Error)]
pub enum LabError {
    /// Flags that are each well-formed but do not make an experiment.
    #[error("{0}")]
    Arguments(String),
    #[error("{flag} {error}")]
    Setting {
        flag: &'static str,
        error: FieldError,
    },
    #[error("loading maps: {0}")]
    Maps(Box<dyn std::error::Error + Send + Sync>),
    #[error("no map {name:?} in {}", dir.display())]
    NoMap { name: String, dir: PathBuf },
    /// The experiment's scripted scenario does not fit the map or did not play out.
    #[error("{0}")]
    Scenario(String),
    #[error(transparent)]
    Setup(#[from] SetupError),
    #[error(transparent)]
    Order(#[from] OrderError),
    /// A shipped policy that does not load, or does not fit the team it should drive.
    #[error("policy:{name}: {error}")]
    Policy {
        name: String,
        error: lasertag_policy::PolicyError,
    },
    #[error("{action} {}: {source}", path.display())]
    File {
        action: &'static str,
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("plotting {}: {message}", path.display())]
    Plot { path: PathBuf, message: String },
    /// A part file that is not one, or is damaged (`line` 0: the file as a whole).
    #[error("{}:{line}: {message}", path.display())]
    Part {
        path: PathBuf,
        line: usize,
        message: String,
    },
    #[error(transparent)]
    Merge(#[from] MergeError),
}

/// Parts that are each well-formed but do not make one study.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    #[error("no part files (*.{ext}) in {}", list(paths), ext = crate::shard::EXTENSION)]
    NoParts { paths: Vec<PathBuf> },
    #[error("{} is a part of experiment `{other_name}`, {} of `{first_name}`: merge one study at a time", other.display(), first.display())]
    Experiment {
        first: PathBuf,
        first_name: String,
        other: PathBuf,
        other_name: String,
    },
    #[error("{} and {} are parts of different studies: parameter `{key}` is {} in the first, {} in the second", first.display(), other.display(), shown(first_value), shown(other_value))]
    Params {
        first: PathBuf,
        other: PathBuf,
        key: String,
        first_value: Option<String>,
        other_value: Option<String>,
    },
    #[error("{} is a shard of {other_count}, {} of {first_count}: parts of different splits of a study", other.display(), first.display())]
    Count {
        first: PathBuf,
        first_count: usize,
        other: PathBuf,
        other_count: usize,
    },
    #[error("shard {shard} twice: {} and {}", first.display(), other.display())]
    Duplicate {
        shard: crate::shard::Shard,
        first: PathBuf,
        other: PathBuf,
    },
    #[error("{} of {count} shards missing: {}; run them (`--shard INDEX/{count}`) and merge again", missing.len(), missing.iter().map(|i| format!("{i}/{count}")).collect::<Vec<_>>().join(", "))]
    Missing { count: usize, missing: Vec<usize> },
    #[error("{}: unknown experiment `{name}`", path.display())]
    Unknown { path: PathBuf, name: String },
    /// Parameters this lasertag cannot make a study of (another version wrote them).
    #[error("{}: {message}", path.display())]
    Study { path: PathBuf, message: String },
}

fn list(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

fn shown(value: &Option<String>) -> String {
    value
        .as_ref()
        .map_or_else(|| "absent".to_string(), |v| format!("{v:?}"))
}

/// `std::fs::create_dir_all`, naming the directory when it fails.
pub fn create_dir_all(path: &Path) -> Result<(), LabError> {
    std::fs::create_dir_all(path).map_err(|source| LabError::File {
        action: "creating",
        path: path.to_owned(),
        source,
    })
}

/// `std::fs::write`, naming the file when it fails.
pub fn write(path: &Path, contents: impl AsRef<[u8]>) -> Result<(), LabError> {
    std::fs::write(path, contents).map_err(|source| LabError::File {
        action: "writing",
        path: path.to_owned(),
        source,
    })
}
