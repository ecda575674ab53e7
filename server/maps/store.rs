//! The maps a server knows ([`MapStore`]) and how a folder of map files is read: our JSON
//! maps as they are, ROS and MovingAI maps converted on load (`import`), so that a lab's own
//! maps can be dropped into the folder beside ours.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::access::{ClientKey, Owner};
use crate::maps::format::{FileKind, ImportError, Problem};
use crate::maps::import::{self, ImportOptions};
use crate::maps::json::{MapError, parse};
use lasertag_core::sim::arena::{Arena, MapDef};

/// A map known to the server: its definition and the arena built from it (shared by matches).
#[derive(Debug, Clone)]
pub struct StoredMap {
    pub arena: Arc<Arena>,
    /// Who uploaded it; the default (no token) for shipped maps, which nobody removes.
    pub owner: Owner,
    /// Bytes it was priced at when admitted (0 for shipped maps, which are always there).
    pub memory: u64,
}

/// Every map the server knows, by name (sorted, so listings are stable).
#[derive(Debug, Default)]
pub struct MapStore {
    maps: BTreeMap<String, StoredMap>,
}

/// A map file in the maps directory that could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error("{file}: {source}")]
    Io {
        file: String,
        source: std::io::Error,
    },
    #[error("{file}: {source}")]
    Invalid { file: String, source: MapError },
    #[error("{file}: the map is named {name:?}; a map file must be named <name>.json")]
    NameMismatch { file: String, name: String },
    /// A ROS or MovingAI map that could not be converted (the error names the file).
    #[error(transparent)]
    Import(#[from] ImportError),
    #[error("{file}: a map named {name:?} was already loaded from {first}")]
    Duplicate {
        file: String,
        name: String,
        first: String,
    },
}

/// A map read from one file, with the frame it came in (for an export to restore).
#[derive(Debug, Clone)]
pub struct LoadedMap {
    pub def: MapDef,
    /// Where the arena's (0, 0) lies in the source's frame, and the source's yaw: a ROS
    /// map's origin moved by what the import cropped; zero for our own JSON maps.
    pub origin: [f64; 3],
}

/// Reads one map file of any supported kind with `options` (JSON maps take none). A JSON
/// map must be named after its file; an imported one is named from its file.
pub fn load_file(path: &Path, options: &ImportOptions) -> Result<LoadedMap, LoadError> {
    let file = path.display().to_string();
    match FileKind::of(path) {
        Some(FileKind::Json) => {
            let text = std::fs::read_to_string(path).map_err(|source| LoadError::Io {
                file: file.clone(),
                source,
            })?;
            let def = parse(&text).map_err(|source| LoadError::Invalid {
                file: file.clone(),
                source,
            })?;
            if path.file_stem().and_then(|s| s.to_str()) != Some(def.name.as_str()) {
                return Err(LoadError::NameMismatch {
                    file,
                    name: def.name,
                });
            }
            Ok(LoadedMap {
                def,
                origin: [0.0; 3],
            })
        }
        Some(FileKind::Ros | FileKind::MovingAi) => {
            let imported = import::import_file(path, options)?;
            Ok(LoadedMap {
                def: imported.def,
                origin: imported.origin,
            })
        }
        None => Err(LoadError::Import(ImportError {
            file,
            problem: Problem::Content(
                "not a map file: expected .json (ours), .yaml (ROS map_server) or .map \
                 (MovingAI)"
                    .into(),
            ),
        })),
    }
}

/// The map files of `dir` (every `.json`, `.yaml` and `.map`), sorted by path.
pub fn map_files(dir: &Path) -> Result<Vec<PathBuf>, LoadError> {
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .map_err(|source| LoadError::Io {
            file: dir.display().to_string(),
            source,
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && FileKind::of(p).is_some())
        .collect();
    paths.sort();
    Ok(paths)
}

/// The file in `dir` that a map named `name` is loaded from: `<name>.json`, or a ROS or
/// MovingAI file whose name becomes `name` once made a map name.
pub fn find_map_file(dir: &Path, name: &str) -> Result<Option<PathBuf>, LoadError> {
    Ok(map_files(dir)?.into_iter().find(|p| {
        let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
        match FileKind::of(p) {
            Some(FileKind::Json) => stem == name,
            _ => import::map_name(stem) == name,
        }
    }))
}

impl MapStore {
    /// Loads every map file in `dir`: our `*.json`, and ROS (`*.yaml`) and MovingAI (`*.map`)
    /// maps converted on load with the default [`ImportOptions`]. Any invalid file is an
    /// error, and so is a second file giving a name already loaded: shipping a broken map
    /// should fail loudly at start-up, not when someone picks it.
    pub fn load_dir(dir: &Path) -> Result<MapStore, LoadError> {
        let mut store = MapStore::default();
        let mut first: BTreeMap<String, String> = BTreeMap::new();
        for path in map_files(dir)? {
            let loaded = load_file(&path, &ImportOptions::default())?;
            let file = path.display().to_string();
            let name = loaded.def.name.clone();
            if let Some(earlier) = first.get(&name) {
                return Err(LoadError::Duplicate {
                    file,
                    name,
                    first: earlier.clone(),
                });
            }
            first.insert(name, file);
            store.insert(loaded.def);
        }
        Ok(store)
    }

    /// Adds a map, building its arena. Returns false (and changes nothing) when the name is taken.
    pub fn insert(&mut self, def: MapDef) -> bool {
        if self.maps.contains_key(&def.name) {
            return false; // do not build an arena only to throw it away
        }
        self.insert_arena(Arc::new(Arena::new(def)))
    }

    /// Adds an already-built arena. Returns false (and changes nothing) when the name is taken.
    pub fn insert_arena(&mut self, arena: Arc<Arena>) -> bool {
        self.insert_owned(arena, Owner::default(), 0)
    }

    /// Adds an uploaded map with its owner. Returns false (and changes nothing) when the name
    /// is taken.
    pub fn insert_owned(&mut self, arena: Arc<Arena>, owner: Owner, memory: u64) -> bool {
        if self.maps.contains_key(&arena.def.name) {
            return false;
        }
        self.maps.insert(
            arena.def.name.clone(),
            StoredMap {
                arena,
                owner,
                memory,
            },
        );
        true
    }

    /// Forgets a map (matches playing on it keep their arena).
    pub fn remove(&mut self, name: &str) -> Option<StoredMap> {
        self.maps.remove(name)
    }

    /// Bytes the uploaded maps (all, or `client`'s) were priced at, together.
    pub fn uploaded_memory(&self, client: Option<ClientKey>) -> u64 {
        let of = |m: &&StoredMap| client.is_none_or(|c| m.owner.client == Some(c));
        self.maps.values().filter(of).map(|m| m.memory).sum()
    }

    /// Maps uploaded by `client` held now.
    pub fn uploaded_by(&self, client: ClientKey) -> usize {
        self.maps
            .values()
            .filter(|m| m.owner.client == Some(client))
            .count()
    }

    pub fn contains(&self, name: &str) -> bool {
        self.maps.contains_key(name)
    }

    pub fn get(&self, name: &str) -> Option<&StoredMap> {
        self.maps.get(name)
    }

    pub fn iter(&self) -> impl Iterator<Item = &StoredMap> {
        self.maps.values()
    }

    pub fn len(&self) -> usize {
        self.maps.len()
    }

    pub fn is_empty(&self) -> bool {
        self.maps.is_empty()
    }
}
