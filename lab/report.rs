//! What each experiment command prints once its files are written: the table of its
//! results and the files it wrote.

use std::path::Path;

/// What an experiment command prints once its files are written.
pub enum Report {
    Capture(String),
    Difficulty(String),
    Teammate(String),
    Reacquire(Vec<crate::reacquire::Summary>),
    Localisation(Vec<crate::localisation::Curve>),
    Uncertainty(String),
    Filters(crate::filters::FiltersResult),
}

/// Prints a study's tables and the files it wrote into `out`.
pub fn print(report: &Report, out: &Path) {
    match report {
        Report::Capture(table) => {
            print!("{table}");
            println!(
                "ratio: median capture time / baseline's; p: two-sided Mann–Whitney U against baseline;\n\
                 GOSPA: the belief against the truth until the tag (c = 2 m, p = 2), mean over runs of each run's mean\n\
                 wrote {0}/capture.csv, {0}/capture_summary.csv, {0}/capture_gospa{{,_time}}.csv, {0}/capture_<map>_<bot>.svg and {0}/capture_gospa_<map>_<bot>.svg",
                out.display()
            );
        }
        Report::Difficulty(table) => {
            print!("{table}");
            println!(
                "win rate: matches the robots won (95% Wilson interval); median tag: of the matches they won\n\
                 wrote {0}/difficulty.csv, {0}/difficulty_summary.csv and {0}/difficulty_<map>_<bot>.svg",
                out.display()
            );
        }
        Report::Teammate(table) => {
            print!("{table}");
            println!(
                "captured: runs that tagged within the limit; median and mean count the others at the limit;\n\
                 ratio: median / two coordinated robots' median; p: two-sided Mann–Whitney U against them\n\
                 wrote {0}/teammate.csv, {0}/teammate_summary.csv and {0}/teammate_<map>_<bot>.svg",
                out.display()
            );
        }
        Report::Reacquire(summaries) => {
            println!(
                "condition   shared  predicted  found    mean ± std (s)  median (s)  teammate saw"
            );
            for s in summaries {
                println!(
                    "{:<11} {:<7} {:<10} {:>3}/{:<3} {:>7.2} ± {:<5.2} {:>10.2} {:>12.0}%",
                    s.condition.name,
                    s.condition.shared,
                    s.condition.predicted,
                    s.found,
                    s.runs,
                    s.mean_s,
                    s.std_s,
                    s.median_s,
                    100.0 * s.teammate_saw
                );
            }
            println!(
                "wrote {0}/reacquire.csv, {0}/reacquire_summary.csv and {0}/reacquire.svg",
                out.display()
            );
        }
        Report::Localisation(curves) => {
            println!("map        variant        mean error (m)  worst (m)");
            for c in curves {
                println!(
                    "{:<10} {:<14} {:>14.4} {:>10.4}",
                    c.map,
                    c.variant.name(),
                    c.mean,
                    c.worst
                );
            }
            println!(
                "wrote {0}/localisation.csv, {0}/localisation_summary.csv and {0}/localisation_<map>.svg",
                out.display()
            );
        }
        Report::Uncertainty(table) => {
            print!("{table}");
            println!(
                "wrote {0}/uncertainty_{{hunt,capture}}{{,_summary}}.csv, {0}/uncertainty_lost.svg and {0}/uncertainty_error_<map>.svg",
                out.display()
            );
        }
        Report::Filters(r) => {
            let parts = |g: &crate::tracking::Parts, ci: f64| {
                format!(
                    "GOSPA {:.2} ± {ci:.2} m (localisation {:.2} m, missed {:.2}, false {:.2})",
                    g.gospa, g.localisation, g.missed, g.false_targets
                )
            };
            println!(
                "with merging: mean active filters peaks at {:.2}, ends at {:.2}; {}\n\
                 without merging: peaks at {:.2}, ends at {:.2}; {} ({} s of play)\n\
                 GOSPA: the belief against the truth (c = 2 m, p = 2), mean over runs of each run's mean ± the half-width of its 95% CI",
                r.with_merge_max_mean,
                r.with_merge_final_mean,
                parts(&r.with_merge_gospa, r.with_merge_gospa_ci95),
                r.without_merge_max_mean,
                r.without_merge_final_mean,
                parts(&r.without_merge_gospa, r.without_merge_gospa_ci95),
                r.seconds,
            );
            println!(
                "wrote {0}/filters.csv, {0}/filters.svg, {0}/filters_gospa{{,_runs}}.csv and {0}/filters_gospa.svg",
                out.display()
            );
        }
    }
}
