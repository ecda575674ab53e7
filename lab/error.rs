//! What can stop an experiment: bad arguments, missing maps, a scenario the chosen map
//! cannot hold, and the files it writes.

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
    #[error("{action} {}: {source}", path.display())]
    File {
        action: &'static str,
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("plotting {}: {message}", path.display())]
    Plot { path: PathBuf, message: String },
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
