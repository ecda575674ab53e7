//! A part file: what one shard of a study measured, for `lasertag experiment merge`.
//!
//! Plain text, one item a line, so a person can read what a shard did:
//!
//! ```text
//! # lasertag experiment part: merge with `lasertag experiment merge`
//! lasertag-experiment-part 1
//! experiment capture
//! shard 1/4
//! study-runs 800
//! param runs 100
//! param seed 0
//! …
//! run 1 <the run's record>
//! run 5 <the run's record>
//! …
//! end 200
//! ```
//!
//! The parameters are the study's, all of them (every planner weight, the maps and their
//! fingerprints), so that a merge can refuse parts of different studies. `run j` lines hold
//! the shard's runs in the study's order ([`crate::record`]); `end` counts them, so a part
//! cut short is refused rather than merged. A part is written to a temporary name and
//! renamed into place, so a shard killed mid-write leaves no part, and a retried shard
//! replaces its part whole.

use std::fmt::Display;
use std::path::{Path, PathBuf};

use crate::error::LabError;
use crate::shard::{EXTENSION, Shard};

/// The first line that is not a comment, with the format's version.
const MAGIC: &str = "lasertag-experiment-part";
const VERSION: u32 = 1;

/// A study's parameters, in a fixed order: `key value` pairs, the value text to the end of
/// its line.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Params(Vec<(String, String)>);

impl Params {
    pub fn set(&mut self, key: impl Into<String>, value: impl Display) {
        self.0.push((key.into(), value.to_string()));
    }

    pub fn iter(&self) -> impl Iterator<Item = (&str, &str)> {
        self.0.iter().map(|(k, v)| (k.as_str(), v.as_str()))
    }

    /// The value of `key`.
    pub fn get(&self, key: &str) -> Result<&str, String> {
        self.iter()
            .find(|(k, _)| *k == key)
            .map(|(_, v)| v)
            .ok_or_else(|| format!("parameter `{key}` is missing"))
    }

    /// The value of `key`, parsed.
    pub fn parse<T: std::str::FromStr>(&self, key: &str) -> Result<T, String> {
        let text = self.get(key)?;
        text.parse()
            .map_err(|_| format!("parameter `{key}`: {text:?} does not read as its type"))
    }

    /// The first parameter that differs from `other`'s: its name and both values (`None`
    /// where one of them lacks it).
    pub fn difference<'a>(
        &'a self,
        other: &'a Params,
    ) -> Option<(&'a str, Option<&'a str>, Option<&'a str>)> {
        let value = |p: &'a Params, key: &str| p.iter().find(|(k, _)| *k == key).map(|kv| kv.1);
        self.iter()
            .chain(other.iter())
            .map(|(k, _)| k)
            .find(|k| value(self, k) != value(other, k))
            .map(|k| (k, value(self, k), value(other, k)))
    }
}

/// What a part says about itself before its runs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Header {
    pub experiment: String,
    pub shard: Shard,
    /// Runs in the whole study (every shard's).
    pub study_runs: usize,
    pub params: Params,
}

/// A part as read: its header and its runs' records, still as text (which experiment's
/// record they are is known only from the header).
#[derive(Debug, Clone)]
pub struct Part {
    pub path: PathBuf,
    pub header: Header,
    /// `(run index in the study, line number, the record's text)`, in the study's order.
    pub runs: Vec<(usize, usize, String)>,
}

/// Writes a part: `runs` are `(run index, record line)` in the study's order.
pub fn write(path: &Path, header: &Header, runs: &[(usize, String)]) -> Result<(), LabError> {
    let mut text = format!(
        "# lasertag experiment part: merge with `lasertag experiment merge`\n\
         {MAGIC} {VERSION}\nexperiment {}\nshard {}\nstudy-runs {}\n",
        header.experiment, header.shard, header.study_runs
    );
    for (k, v) in header.params.iter() {
        // A value is the rest of its line; a key ends at the first space.
        if k.contains(char::is_whitespace) || v.contains(['\n', '\r']) {
            return Err(LabError::Part {
                path: path.to_owned(),
                line: 0,
                message: format!("parameter {k:?} = {v:?} does not fit on one line"),
            });
        }
        text.push_str(&format!("param {k} {v}\n"));
    }
    for (j, line) in runs {
        text.push_str(&format!("run {j} {line}\n"));
    }
    text.push_str(&format!("end {}\n", runs.len()));
    let partial = path.with_extension(format!("{EXTENSION}.partial-{}", std::process::id()));
    crate::error::write(&partial, text)?;
    std::fs::rename(&partial, path).map_err(|source| LabError::File {
        action: "renaming into place",
        path: path.to_owned(),
        source,
    })
}

/// Reads and checks a part: its header, and that its runs are exactly its shard's, in order,
/// and all there.
pub fn read(path: &Path) -> Result<Part, LabError> {
    let text = std::fs::read_to_string(path).map_err(|source| LabError::File {
        action: "reading",
        path: path.to_owned(),
        source,
    })?;
    let bad = |line: usize, message: String| LabError::Part {
        path: path.to_owned(),
        line,
        message,
    };
    let mut lines = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l))
        .filter(|(_, l)| !l.starts_with('#') && !l.trim().is_empty());
    let mut expect = |key: &str| {
        let (n, l) = lines
            .next()
            .ok_or_else(|| bad(0, format!("ends before its `{key}` line")))?;
        let value = l
            .strip_prefix(key)
            .and_then(|rest| rest.strip_prefix(' '))
            .ok_or_else(|| bad(n, format!("expected `{key} …`, found {l:?}")))?;
        Ok::<_, LabError>((n, value.to_string()))
    };
    let (n, version) =
        expect(MAGIC).map_err(|_| bad(1, format!("not a part file (no `{MAGIC}` line)")))?;
    if version != VERSION.to_string() {
        return Err(bad(
            n,
            format!("format {version}; this lasertag reads format {VERSION}"),
        ));
    }
    let (_, experiment) = expect("experiment")?;
    let (n, shard) = expect("shard")?;
    let shard: Shard = shard
        .parse()
        .map_err(|e| bad(n, format!("shard {shard:?}: {e}")))?;
    let (n, study_runs) = expect("study-runs")?;
    let study_runs: usize = study_runs
        .parse()
        .map_err(|_| bad(n, format!("study-runs {study_runs:?} is not a count")))?;
    let mut params = Params::default();
    let mut runs = Vec::new();
    let mut expected = shard.runs(study_runs);
    let mut ended = None;
    for (n, l) in lines {
        if ended.is_some() {
            return Err(bad(n, "a line after `end`".into()));
        }
        let (key, rest) = l.split_once(' ').unwrap_or((l, ""));
        match key {
            "param" if runs.is_empty() => {
                let (k, v) = rest.split_once(' ').unwrap_or((rest, ""));
                params.set(k, v);
            }
            "run" => {
                let (j, record) = rest.split_once(' ').unwrap_or((rest, ""));
                let j: usize = j
                    .parse()
                    .map_err(|_| bad(n, format!("run {j:?} is not a run index")))?;
                match expected.next() {
                    Some(want) if want == j => runs.push((j, n, record.to_string())),
                    Some(want) => {
                        return Err(bad(
                            n,
                            format!("run {j} where shard {shard} has run {want} next"),
                        ));
                    }
                    None => {
                        return Err(bad(
                            n,
                            format!("run {j}: shard {shard} of {study_runs} runs has no more"),
                        ));
                    }
                }
            }
            "end" => {
                let count: usize = rest
                    .parse()
                    .map_err(|_| bad(n, format!("end {rest:?} is not a count")))?;
                if count != runs.len() {
                    return Err(bad(
                        n,
                        format!("end says {count} runs, the part holds {}", runs.len()),
                    ));
                }
                ended = Some(n);
            }
            _ => return Err(bad(n, format!("unexpected line {l:?}"))),
        }
    }
    if ended.is_none() {
        return Err(bad(
            text.lines().count(),
            "no `end` line: the part was cut short".into(),
        ));
    }
    if let Some(want) = expected.next() {
        return Err(bad(
            text.lines().count(),
            format!(
                "holds {} of shard {shard}'s {} runs (run {want} is missing)",
                runs.len(),
                shard.len(study_runs)
            ),
        ));
    }
    Ok(Part {
        path: path.to_owned(),
        header: Header {
            experiment,
            shard,
            study_runs,
            params,
        },
        runs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(shard: Shard) -> Header {
        let mut params = Params::default();
        params.set("runs", 5);
        params.set("maps", "office,warehouse");
        Header {
            experiment: "capture".into(),
            shard,
            study_runs: 10,
            params,
        }
    }

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("lasertag-part-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_part_reads_back_as_written() {
        let d = dir("back");
        let shard = Shard { index: 1, count: 3 };
        let runs: Vec<(usize, String)> = shard.runs(10).map(|j| (j, format!("{j}.5 -"))).collect();
        let path = d.join(shard.file_name("capture"));
        write(&path, &header(shard), &runs).unwrap();
        let part = read(&path).unwrap();
        assert_eq!(part.header, header(shard));
        let back: Vec<(usize, String)> = part.runs.into_iter().map(|(j, _, r)| (j, r)).collect();
        assert_eq!(back, runs);
        assert_eq!(
            std::fs::read_dir(&d).unwrap().count(),
            1,
            "no temporary file left"
        );
        let _ = std::fs::remove_dir_all(&d);
    }

    /// A part cut short, holding another shard's run or missing one, is refused by line.
    #[test]
    fn a_damaged_part_is_refused_with_its_line() {
        let d = dir("damaged");
        let shard = Shard { index: 0, count: 2 };
        let path = d.join(shard.file_name("capture"));
        let runs: Vec<(usize, String)> = shard.runs(10).map(|j| (j, "1.0".into())).collect();
        write(&path, &header(shard), &runs).unwrap();
        let good = std::fs::read_to_string(&path).unwrap();
        for (damage, says) in [
            (good.replace("end 5\n", ""), "no `end` line"),
            (
                good.replace("run 4 ", "run 5 "),
                "run 5 where shard 0/2 has run 4 next",
            ),
            (
                good.replace("run 8 1.0\n", "").replace("end 5", "end 4"),
                "run 8 is missing",
            ),
            (
                good.replace("shard 0/2", "shard 2/2"),
                "the index is 0-based",
            ),
            (
                good.replace("lasertag-experiment-part 1", "lasertag-experiment-part 9"),
                "format 9",
            ),
            ("hello\n".to_string(), "not a part file"),
        ] {
            std::fs::write(&path, damage).unwrap();
            let err = read(&path).unwrap_err().to_string();
            assert!(err.contains(says), "{err}");
            assert!(err.starts_with(&path.display().to_string()), "{err}");
        }
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn params_name_their_first_difference() {
        let a = header(Shard::ALL).params;
        let mut b = a.clone();
        assert_eq!(a.difference(&b), None);
        b.0[0].1 = "6".into();
        assert_eq!(a.difference(&b), Some(("runs", Some("5"), Some("6"))));
        let mut c = a.clone();
        c.set("seed", 1);
        assert_eq!(a.difference(&c), Some(("seed", None, Some("1"))));
        assert_eq!(a.parse::<usize>("runs"), Ok(5));
        assert!(a.parse::<usize>("maps").unwrap_err().contains("`maps`"));
        assert!(a.get("seed").unwrap_err().contains("missing"));
    }
}
