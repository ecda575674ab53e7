//! `lasertag experiment merge`: the parts of a sharded study back into the files one run of
//! it writes. The parts must make one whole study: the same experiment, the same parameters
//! and the same number of shards, every shard once. Each part's records are read back bit
//! for bit ([`crate::record`]) and put in the study's order, and the experiment's own
//! [`Study::write`] makes the files. A whole run goes through [`join`] too, with its one
//! shard in memory ([`crate::execute::execute`]), so the files are the single run's byte for
//! byte.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::error::{LabError, MergeError};
use crate::part::{self, Part};
use crate::record;
use crate::study::Study;

/// The parts among `paths`: files as given, and every `*.part` file of each directory (in
/// name order, so a merge reads the same parts in the same order wherever it runs).
pub fn read_parts(paths: &[PathBuf]) -> Result<Vec<Part>, LabError> {
    let mut files = Vec::new();
    for p in paths {
        if p.is_dir() {
            let entries = std::fs::read_dir(p).map_err(|source| LabError::File {
                action: "listing",
                path: p.clone(),
                source,
            })?;
            let mut found: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| {
                    f.is_file() && f.extension().is_some_and(|x| x == crate::shard::EXTENSION)
                })
                .collect();
            found.sort();
            files.extend(found);
        } else {
            files.push(p.clone());
        }
    }
    if files.is_empty() {
        return Err(MergeError::NoParts {
            paths: paths.to_vec(),
        }
        .into());
    }
    files.iter().map(|f| part::read(f)).collect()
}

/// Checks that `parts` make one whole study; returns its experiment's name.
pub fn check(parts: &[Part]) -> Result<&str, MergeError> {
    let Some(first) = parts.first() else {
        return Err(MergeError::NoParts { paths: vec![] });
    };
    let h = &first.header;
    let mut seen: BTreeMap<usize, &Path> = BTreeMap::new();
    for p in parts {
        let o = &p.header;
        if o.experiment != h.experiment {
            return Err(MergeError::Experiment {
                first: first.path.clone(),
                first_name: h.experiment.clone(),
                other: p.path.clone(),
                other_name: o.experiment.clone(),
            });
        }
        if o.shard.count != h.shard.count {
            return Err(MergeError::Count {
                first: first.path.clone(),
                first_count: h.shard.count,
                other: p.path.clone(),
                other_count: o.shard.count,
            });
        }
        if let Some((key, a, b)) = h.params.difference(&o.params) {
            return Err(MergeError::Params {
                first: first.path.clone(),
                other: p.path.clone(),
                key: key.to_string(),
                first_value: a.map(str::to_string),
                other_value: b.map(str::to_string),
            });
        }
        if o.study_runs != h.study_runs {
            // Equal parameters make equal studies; a difference here is a damaged file.
            return Err(MergeError::Study {
                path: p.path.clone(),
                message: format!(
                    "{} runs in the study, {} says {}",
                    o.study_runs,
                    first.path.display(),
                    h.study_runs
                ),
            });
        }
        if let Some(earlier) = seen.insert(o.shard.index, &p.path) {
            return Err(MergeError::Duplicate {
                shard: o.shard,
                first: earlier.to_owned(),
                other: p.path.clone(),
            });
        }
    }
    let missing: Vec<usize> = (0..h.shard.count)
        .filter(|i| !seen.contains_key(i))
        .collect();
    if !missing.is_empty() {
        return Err(MergeError::Missing {
            count: h.shard.count,
            missing,
        });
    }
    Ok(&h.experiment)
}

/// Joins checked `parts` of study `S` and writes its files into `out`.
pub fn join<S: Study>(parts: &[Part], out: &Path) -> Result<S::Report, LabError> {
    let Some(first) = parts.first() else {
        return Err(MergeError::NoParts { paths: vec![] }.into());
    };
    let study = S::from_params(&first.header.params).map_err(|message| MergeError::Study {
        path: first.path.clone(),
        message,
    })?;
    let total = study.runs();
    if total != first.header.study_runs {
        return Err(MergeError::Study {
            path: first.path.clone(),
            message: format!(
                "its parameters make a study of {total} runs, the part says {}",
                first.header.study_runs
            ),
        }
        .into());
    }
    let mut runs: Vec<Option<S::Run>> = (0..total).map(|_| None).collect();
    for p in parts {
        for (j, line, text) in &p.runs {
            let r = record::from_line(text).map_err(|message| LabError::Part {
                path: p.path.clone(),
                line: *line,
                message: format!("run {j}: {message}"),
            })?;
            if let Some(slot) = runs.get_mut(*j) {
                *slot = Some(r);
            }
        }
    }
    // `check` and `part::read` saw every shard, and each with all of its runs.
    let runs = runs
        .into_iter()
        .enumerate()
        .map(|(j, r)| {
            r.ok_or_else(|| MergeError::Study {
                path: first.path.clone(),
                message: format!("run {j} is in no part"),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    crate::error::create_dir_all(out)?;
    study.write(runs, out)
}
