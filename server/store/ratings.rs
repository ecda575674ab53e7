//! Ratings of player names: Glicko-2 (Glickman, "Example of the Glicko-2 system"), through
//! the `skillratings` crate, each rated match one game of the person against the robot
//! team's preset, whose rating is fixed from how it did against the built-in bots
//! ([`Difficulty::rating`]). docs/ratings.md says which matches count and why.
//!
//! A match is its own rating period: the rating moves after every match rather than in
//! batches, as players expect of a game; a name's deviation shrinks as it plays and the
//! volatility follows how consistent its results are.

use lasertag_core::difficulty::Difficulty;
use skillratings::Outcomes;
use skillratings::glicko2::{Glicko2Config, Glicko2Rating, glicko2};

/// Most names the ratings table keeps; past it the name rated longest ago goes. Bounds what
/// rated matches can make the history store (a name is ~100 bytes with its index).
pub const MAX_RATED_NAMES: u64 = 100_000;

/// A name's rating.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rating {
    pub rating: f64,
    /// Its uncertainty (Glicko's RD): ±2 deviations hold the name's true strength with
    /// 95% confidence.
    pub deviation: f64,
    /// How erratic the name's results are (Glicko-2's σ).
    pub volatility: f64,
}

impl Rating {
    /// A name's rating before its first rated match: Glicko-2's 1500 ± 350.
    pub fn newcomer() -> Rating {
        Rating::from(Glicko2Rating::new())
    }

    /// What leaderboards rank by: the rating less two deviations, the strength the name
    /// has shown with 97.5% confidence, so that one lucky win over `elite` does not put a
    /// newcomer on top.
    pub fn conservative(&self) -> f64 {
        self.rating - 2.0 * self.deviation
    }
}

impl From<Glicko2Rating> for Rating {
    fn from(g: Glicko2Rating) -> Rating {
        Rating {
            rating: g.rating,
            deviation: g.deviation,
            volatility: g.volatility,
        }
    }
}

impl From<Rating> for Glicko2Rating {
    fn from(r: Rating) -> Glicko2Rating {
        Glicko2Rating {
            rating: r.rating,
            deviation: r.deviation,
            volatility: r.volatility,
        }
    }
}

/// `before` after one rated match against `preset`: `won` when the person's side won with
/// them still in it. The preset's rating does not move.
pub fn after(before: Rating, preset: Difficulty, won: bool) -> Rating {
    let fixed = preset.rating();
    let team = Glicko2Rating {
        rating: fixed.rating,
        deviation: fixed.deviation,
        ..Glicko2Rating::new()
    };
    let outcome = if won { Outcomes::WIN } else { Outcomes::LOSS };
    let (person, _) = glicko2(&before.into(), &team, &outcome, &Glicko2Config::new());
    Rating::from(person)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn winning_raises_losing_lowers_and_harder_presets_move_more() {
        let new = Rating::newcomer();
        assert_eq!((new.rating, new.deviation), (1500.0, 350.0));
        let beat_recruit = after(new, Difficulty::Recruit, true);
        let beat_elite = after(new, Difficulty::Elite, true);
        let lost_recruit = after(new, Difficulty::Recruit, false);
        let lost_elite = after(new, Difficulty::Elite, false);
        assert!(beat_recruit.rating > 1500.0 && lost_recruit.rating < 1500.0);
        // An upset moves a rating further than the expected result.
        assert!(beat_elite.rating - 1500.0 > beat_recruit.rating - 1500.0);
        assert!(1500.0 - lost_elite.rating < 1500.0 - lost_recruit.rating);
        // Every match is evidence: the deviation shrinks.
        assert!(beat_recruit.deviation < 350.0 && lost_elite.deviation < 350.0);
    }

    /// A name that keeps beating recruit and losing to elite settles between them.
    #[test]
    fn a_series_settles_between_the_presets_it_beats_and_loses_to() {
        let mut r = Rating::newcomer();
        for _ in 0..30 {
            r = after(r, Difficulty::Recruit, true);
            r = after(r, Difficulty::Elite, false);
        }
        let (low, high) = (
            Difficulty::Recruit.rating().rating,
            Difficulty::Elite.rating().rating,
        );
        assert!(low < r.rating && r.rating < high, "{r:?}");
        assert!(r.deviation < 120.0, "{r:?}");
        assert!(r.conservative() < r.rating);
    }
}
