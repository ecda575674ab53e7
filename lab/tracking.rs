//! Tracking quality in the experiments: GOSPA (`lasertag_core::tracker::gospa`) between the
//! team's belief and the opponents still in the arena, taken every tick of a run and
//! averaged per second and over the run, so the filters and capture experiments can say how
//! close the belief was to the truth, not only how many roles it had or how soon it tagged.
//!
//! Reading the world changes nothing in it: a run with these measurements is the same match
//! as one without.
//!
//! A finished [`Track`] is recorded ([`Record`]) as what the aggregates read: its mean and
//! its seconds.

use crate::record::{Fields, Line, Record};
use lasertag_core::sim::TICK_HZ;
use lasertag_core::tracker::estimate::tracking_quality;
use lasertag_core::tracker::gospa::{Gospa, Params};
use lasertag_core::world::World;

/// GOSPA of the team's (merged) belief against the untagged opponents, default `c` and `p`.
pub fn measure(world: &World) -> Gospa {
    tracking_quality(
        &world.team.merged_belief(),
        &world.untagged_opponents(),
        Params::default(),
    )
}

/// GOSPA and its parts as plain numbers, to be summed and averaged.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Parts {
    /// Metres.
    pub gospa: f64,
    /// Metres.
    pub localisation: f64,
    /// Opponents.
    pub missed: f64,
    /// Estimates.
    pub false_targets: f64,
}

impl Parts {
    fn add(&mut self, o: Parts) {
        self.gospa += o.gospa;
        self.localisation += o.localisation;
        self.missed += o.missed;
        self.false_targets += o.false_targets;
    }

    fn scaled(self, k: f64) -> Parts {
        Parts {
            gospa: self.gospa * k,
            localisation: self.localisation * k,
            missed: self.missed * k,
            false_targets: self.false_targets * k,
        }
    }

    /// The mean of `parts` (zero for none).
    pub fn mean(parts: impl IntoIterator<Item = Parts>) -> Parts {
        let (mut sum, mut n) = (Parts::default(), 0usize);
        for p in parts {
            sum.add(p);
            n += 1;
        }
        sum.scaled(1.0 / n.max(1) as f64)
    }

    /// CSV fields: GOSPA, localisation, missed, false.
    pub fn csv(&self) -> String {
        format!(
            "{:.4},{:.4},{:.4},{:.4}",
            self.gospa, self.localisation, self.missed, self.false_targets
        )
    }
}

impl From<Gospa> for Parts {
    fn from(g: Gospa) -> Parts {
        Parts {
            gospa: g.distance as f64,
            localisation: g.localisation as f64,
            missed: g.missed as f64,
            false_targets: g.false_targets as f64,
        }
    }
}

impl Record for Parts {
    fn write(&self, out: &mut Line) {
        [
            self.gospa,
            self.localisation,
            self.missed,
            self.false_targets,
        ]
        .iter()
        .for_each(|x| x.write(out));
    }
    fn read(input: &mut Fields) -> Result<Parts, String> {
        Ok(Parts {
            gospa: f64::read(input)?,
            localisation: f64::read(input)?,
            missed: f64::read(input)?,
            false_targets: f64::read(input)?,
        })
    }
}

/// CSV header of [`Parts::csv`], each name prefixed.
pub fn csv_header(prefix: &str) -> String {
    ["gospa_m", "localisation_m", "missed", "false"]
        .map(|n| format!("{prefix}{n}"))
        .join(",")
}

/// One run's measurements, tick by tick, kept as per-second means.
#[derive(Debug, Clone, Default)]
pub struct Track {
    /// Mean of each whole second's ticks (second `s` holds ticks `s·TICK_HZ ..`).
    pub seconds: Vec<Parts>,
    /// Mean over every tick measured.
    pub mean: Parts,
    sum: Parts,
    ticks: usize,
    second_sum: Parts,
    second_ticks: usize,
}

impl Track {
    /// Records the measurement of `world` at its current tick.
    pub fn push(&mut self, world: &World) {
        let second = (world.tick / TICK_HZ as u64) as usize;
        while self.seconds.len() < second {
            self.close_second();
        }
        let g = Parts::from(measure(world));
        self.sum.add(g);
        self.ticks += 1;
        self.second_sum.add(g);
        self.second_ticks += 1;
        self.mean = self.sum.scaled(1.0 / self.ticks as f64);
    }

    /// Ends the run: the last, partial second counts as a second of its own.
    pub fn finish(mut self) -> Track {
        if self.second_ticks > 0 {
            self.close_second();
        }
        self
    }

    fn close_second(&mut self) {
        let mean = if self.second_ticks > 0 {
            self.second_sum.scaled(1.0 / self.second_ticks as f64)
        } else {
            // A second with no tick measured (none before the first one): hold the last.
            self.seconds.last().copied().unwrap_or_default()
        };
        self.seconds.push(mean);
        self.second_sum = Parts::default();
        self.second_ticks = 0;
    }
}

/// A finished track: its mean, then its seconds. The running sums are not kept: nothing
/// after [`Track::finish`] reads them. (Every field is named, so that a new one must be
/// recorded here or said not to need it.)
impl Record for Track {
    fn write(&self, out: &mut Line) {
        self.mean.write(out);
        self.seconds.write(out);
    }
    fn read(input: &mut Fields) -> Result<Track, String> {
        let mean = Parts::read(input)?;
        let seconds = Vec::read(input)?;
        Ok(Track {
            seconds,
            mean,
            sum: Parts::default(),
            ticks: 0,
            second_sum: Parts::default(),
            second_ticks: 0,
        })
    }
}

/// Mean over runs of each second. `hold`: a run that has ended counts with its last second
/// (a run that goes on with nothing left to happen); otherwise only runs still going count.
/// Returns each second's mean and how many runs it is over.
pub fn mean_by_second(runs: &[&Track], hold: bool) -> Vec<(Parts, usize)> {
    let len = runs.iter().map(|t| t.seconds.len()).max().unwrap_or(0);
    (0..len)
        .map(|s| {
            let at: Vec<Parts> = runs
                .iter()
                .filter_map(|t| {
                    t.seconds
                        .get(s)
                        .or(if hold { t.seconds.last() } else { None })
                        .copied()
                })
                .collect();
            (Parts::mean(at.iter().copied()), at.len())
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parts(gospa: f64) -> Parts {
        Parts {
            gospa,
            localisation: gospa / 2.0,
            missed: 1.0,
            false_targets: 0.0,
        }
    }

    fn track(seconds: &[f64]) -> Track {
        Track {
            seconds: seconds.iter().map(|&g| parts(g)).collect(),
            ..Track::default()
        }
    }

    /// Held, a finished run counts with its last second; not held, only the runs going.
    #[test]
    fn seconds_average_over_the_runs_going_or_held() {
        let (short, long) = (track(&[1.0]), track(&[3.0, 5.0]));
        let held = mean_by_second(&[&short, &long], true);
        assert_eq!(held, vec![(parts(2.0), 2), (parts(3.0), 2)]);
        let going = mean_by_second(&[&short, &long], false);
        assert_eq!(going, vec![(parts(2.0), 2), (parts(5.0), 1)]);
        assert!(mean_by_second(&[], true).is_empty());
    }

    #[test]
    fn a_finished_track_reads_back_with_what_the_aggregates_read() {
        let mut t = track(&[1.0 / 3.0, 2.5]);
        t.mean = parts(0.1);
        let back: Track = crate::record::from_line(&crate::record::to_line(&t)).unwrap();
        assert_eq!((back.mean, back.seconds), (t.mean, t.seconds));
    }

    #[test]
    fn parts_average_and_print_in_the_header_order() {
        assert_eq!(Parts::mean([parts(1.0), parts(3.0)]), parts(2.0));
        assert_eq!(Parts::mean([]), Parts::default());
        assert_eq!(parts(2.0).csv(), "2.0000,1.0000,1.0000,0.0000");
        assert_eq!(
            csv_header("mean_"),
            "mean_gospa_m,mean_localisation_m,mean_missed,mean_false"
        );
    }
}
