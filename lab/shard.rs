//! `--shard INDEX/COUNT`: one machine's share of a study. The index is 0-based, as
//! Kubernetes' `JOB_COMPLETION_INDEX` and a Slurm array declared `--array=0-(COUNT-1)` give it:
//! shard `i` of `n` runs every run `j` of the study (in the study's fixed order) with
//! `j % n == i`. Interleaving, rather than cutting the list into blocks, gives every shard a
//! share of every setting, so shards take about as long as each other even though settings
//! differ in cost.

use std::fmt;
use std::str::FromStr;

/// The part files' extension, which `merge` looks for in a directory.
pub const EXTENSION: &str = "part";

/// The flag every experiment command takes, declared once and flattened into each.
#[derive(Debug, Clone, Copy, Default, clap::Args)]
pub struct ShardArgs {
    /// Run only shard INDEX of COUNT (0-based: 0/4 … 3/4) and write its part to
    /// `<out>/parts/`; `lasertag experiment merge` joins the parts into the files one run
    /// writes.
    #[arg(long, value_name = "INDEX/COUNT")]
    pub shard: Option<Shard>,
}

/// Shard `index` of `count`, `index < count`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

/// Why a `--shard` value was refused (clap shows the value before the reason).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ShardError {
    #[error("expected INDEX/COUNT, two whole numbers such as 0/4")]
    Syntax,
    #[error("the count must be at least 1")]
    NoShards,
    #[error("the index is 0-based, so shards of {count} are 0/{count} to {last}/{count}", last = count - 1)]
    PastTheEnd { count: usize },
}

impl FromStr for Shard {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Shard, ShardError> {
        let syntax = || ShardError::Syntax;
        let (i, n) = s.split_once('/').ok_or_else(syntax)?;
        // Digits only: `usize::from_str` would take a sign, and `1/+4` is a typo, not a shard.
        let number = |t: &str| {
            if t.is_empty() || !t.bytes().all(|b| b.is_ascii_digit()) {
                return Err(syntax());
            }
            t.parse::<usize>().map_err(|_| syntax())
        };
        let (index, count) = (number(i)?, number(n)?);
        if count == 0 {
            return Err(ShardError::NoShards);
        }
        if index >= count {
            return Err(ShardError::PastTheEnd { count });
        }
        Ok(Shard { index, count })
    }
}

impl fmt::Display for Shard {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl Shard {
    /// The whole study as one shard.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// The runs of a study of `total` runs that this shard runs, in order.
    pub fn runs(self, total: usize) -> impl Iterator<Item = usize> {
        (self.index..total).step_by(self.count)
    }

    /// How many runs of a study of `total` this shard runs.
    pub fn len(self, total: usize) -> usize {
        total.saturating_sub(self.index).div_ceil(self.count)
    }

    /// Whether run `j` is this shard's.
    pub fn owns(self, j: usize) -> bool {
        j % self.count == self.index
    }

    /// The part file's name: `capture.shard-0-of-4.part`.
    pub fn file_name(self, experiment: &str) -> String {
        format!(
            "{experiment}.shard-{}-of-{}.{}",
            self.index, self.count, EXTENSION
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_0_based_and_refuse_the_rest_by_name() {
        assert_eq!("0/4".parse(), Ok(Shard { index: 0, count: 4 }));
        assert_eq!("3/4".parse(), Ok(Shard { index: 3, count: 4 }));
        assert_eq!("0/1".parse(), Ok(Shard::ALL));
        assert_eq!("0/0".parse::<Shard>(), Err(ShardError::NoShards));
        let past = "4/4".parse::<Shard>().unwrap_err();
        assert_eq!(
            past.to_string(),
            "the index is 0-based, so shards of 4 are 0/4 to 3/4"
        );
        for garbage in [
            "", "4", "a/4", "1/b", "1/4/2", "-1/4", "+1/4", " 1/4", "1/", "/4",
        ] {
            assert_eq!(
                garbage.parse::<Shard>(),
                Err(ShardError::Syntax),
                "{garbage:?}"
            );
        }
        assert_eq!(Shard { index: 2, count: 5 }.to_string(), "2/5");
    }

    /// Every run belongs to exactly one shard, and `len` counts what `runs` yields.
    #[test]
    fn the_shards_of_a_study_cover_each_run_once() {
        for total in [0, 1, 7, 8, 9, 800] {
            for count in [1, 2, 3, 4, 8, 1000] {
                let mut seen = vec![0; total];
                for index in 0..count {
                    let s = Shard { index, count };
                    let runs: Vec<usize> = s.runs(total).collect();
                    assert_eq!(runs.len(), s.len(total));
                    assert!(runs.iter().all(|&j| s.owns(j)));
                    runs.iter().for_each(|&j| seen[j] += 1);
                }
                assert!(seen.iter().all(|&n| n == 1), "{total} runs, {count} shards");
            }
        }
        assert_eq!(
            Shard { index: 1, count: 4 }.file_name("capture"),
            "capture.shard-1-of-4.part"
        );
    }
}
