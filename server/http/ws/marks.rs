//! How often a player may mark: a mark is drawn on every teammate's screen with a sound, so
//! a flood of them would drown the game (Apex Legends limits its pings the same way).

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// Marks a player may make within [`MARK_WINDOW`].
pub const MAX_MARKS: usize = 3;
/// The sliding window [`MAX_MARKS`] counts over; also how long a page shows a mark.
pub const MARK_WINDOW: Duration = Duration::from_secs(5);

/// The times of a connection's recent marks: a sliding window, so that a fourth mark is
/// refused until the oldest of the last three is five seconds old.
#[derive(Debug, Default)]
pub struct MarkRate {
    recent: VecDeque<Instant>,
}

impl MarkRate {
    /// Whether a mark at `now` is within the limit; counts it if so.
    pub fn admit(&mut self, now: Instant) -> bool {
        while self
            .recent
            .front()
            .is_some_and(|t| now.duration_since(*t) >= MARK_WINDOW)
        {
            self.recent.pop_front();
        }
        if self.recent.len() >= MAX_MARKS {
            return false;
        }
        self.recent.push_back(now);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn three_marks_in_five_seconds_then_one_more_as_the_oldest_expires() {
        let t0 = Instant::now();
        let mut rate = MarkRate::default();
        let at = |ms| t0 + Duration::from_millis(ms);
        assert!(rate.admit(at(0)));
        assert!(rate.admit(at(100)));
        assert!(rate.admit(at(200)));
        assert!(!rate.admit(at(4_999)), "a fourth within 5 s of the first");
        assert!(rate.admit(at(5_000)), "the first has left the window");
        assert!(!rate.admit(at(5_050)));
        assert!(rate.admit(at(5_100)));
    }
}
