//! lasertag-lab: the paper's experiments over the core, as commands: many seeded headless
//! matches spread over every core, with a progress bar, written out as CSV files and SVG
//! plots. It knows no JSON and no server: the binary hands it the maps it loaded.
//!
//! - [`filters`]: Fig. 4 — the number of active filters with and without role merging.
//! - [`capture`]: Fig. 5 — capture time of `coordinated` against `baseline`.
//! - [`difficulty`]: how often each difficulty preset's robots win, and how soon.
//! - [`teammate`]: a person-like pursuer on the robot team, with and without the
//!   coordinated planner accounting for it, against two planned robots.
//! - [`localisation`]: the robots' own pose error with and without landmarks.
//! - [`reacquire`]: Coltin et al.'s Table I: time to see an opponent again with
//!   and without a teammate's hypotheses and the tracker's prediction.
//! - [`uncertainty`]: uncertainty-aware motion on and off, for robots that
//!   localise from landmarks alone.
//! - [`tracking`]: how close the belief is to the truth (GOSPA), for `filters` and `capture`.
//! - [`policy`]: a shipped trained policy driving a team (`policy:<name>`), for `capture`
//!   and `difficulty`.
//!
//! Each experiment is a [`study::Study`]: a fixed list of runs, a record of what each
//! measured, and the files made from all the records. That lets a study be split over
//! machines ([`shard`]: `--shard INDEX/COUNT`, each shard writing a [`part`] of records,
//! [`record`] their lossless text) and joined again ([`merge`]) into the very files one
//! machine writes; [`execute`] runs a study or a shard of it.

pub mod capture;
pub mod cli;
pub mod difficulty;
pub mod error;
pub mod execute;
pub mod filters;
pub mod localisation;
pub mod merge;
pub mod part;
pub mod plot;
pub mod policy;
pub mod reacquire;
pub mod record;
pub mod report;
pub mod shard;
pub mod study;
pub mod teammate;
pub mod tracking;
pub mod uncertainty;

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use indicatif::{ProgressBar, ProgressStyle};

/// Runs `job(i)` for `i` in `0..n` on every core, showing progress; results in index order.
/// Each job is a whole deterministic match, so the order of execution does not matter.
pub fn run_all<T: Send>(label: &str, n: usize, job: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let bar = ProgressBar::new(n as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg:>24} [{bar:40}] {pos}/{len} runs, {elapsed} (eta {eta})",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    bar.set_message(label.to_string());
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<T>>> = Mutex::new((0..n).map(|_| None).collect());
    let threads = std::thread::available_parallelism()
        .map_or(1, |p| p.get())
        .min(n.max(1));
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    if i >= n {
                        break;
                    }
                    let r = job(i);
                    results.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(r);
                    bar.inc(1);
                }
            });
        }
    });
    bar.finish();
    results
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .map(|r| r.expect("every job ran"))
        .collect()
}
