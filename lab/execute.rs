//! Running a study, or one shard of it: its runs on every core with a progress bar, then
//! either its files (a whole study is the merge of its one shard, held in memory) or the
//! shard's part.

use std::path::{Path, PathBuf};

use crate::error::LabError;
use crate::merge;
use crate::part::{self, Header, Part};
use crate::record;
use crate::run_all;
use crate::shard::Shard;
use crate::study::Study;

/// What running a study, or a shard of it, produced.
pub enum Outcome<R> {
    /// The whole study: its files are written and this is its report.
    Files(R),
    /// A shard: its part is written.
    Part(Written),
}

/// A part just written.
pub struct Written {
    pub path: PathBuf,
    pub shard: Shard,
    pub runs: usize,
    pub study_runs: usize,
}

/// Runs `study` (or its `shard`), `run(j)` making run `j`'s record, on every core with a
/// progress bar; writes the files, or the shard's part into `<out>/parts/`.
///
/// The whole study is the merge of its one shard, held in memory: its records are written
/// as text, read back and aggregated by [`merge::join`], as a merge of parts is. So the
/// files of a whole run and of a merge come from the same bytes through the same code.
pub fn execute<S: Study>(
    study: &S,
    shard: Option<Shard>,
    out: &Path,
    run: impl Fn(usize) -> Result<S::Run, LabError> + Sync,
) -> Result<Outcome<S::Report>, LabError> {
    let total = study.runs();
    let (dir, label) = match shard {
        None => (out.to_owned(), S::LABEL.to_string()),
        Some(s) => (out.join("parts"), format!("{} {s}", S::LABEL)),
    };
    // Before the matches, so that an unwritable `--out` fails at once.
    crate::error::create_dir_all(&dir)?;
    let header = Header {
        experiment: S::NAME.to_string(),
        shard: shard.unwrap_or(Shard::ALL),
        study_runs: total,
        params: study.params(),
    };
    let mine: Vec<usize> = header.shard.runs(total).collect();
    let records = run_all(&label, mine.len(), |k| {
        run(mine[k]).map(|r| record::to_line(&r))
    });
    let lines = mine
        .iter()
        .zip(records)
        .map(|(&j, r)| r.map(|line| (j, line)))
        .collect::<Result<Vec<_>, _>>()?;
    let Some(shard) = shard else {
        let whole = Part {
            path: out.to_owned(),
            header,
            runs: lines.into_iter().map(|(j, text)| (j, 0, text)).collect(),
        };
        return merge::join::<S>(std::slice::from_ref(&whole), out).map(Outcome::Files);
    };
    let path = dir.join(shard.file_name(S::NAME));
    part::write(&path, &header, &lines)?;
    Ok(Outcome::Part(Written {
        path,
        shard,
        runs: lines.len(),
        study_runs: total,
    }))
}
