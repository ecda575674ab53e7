//! How long an agent has stood still: the one definition the capture experiment's parked
//! time and the browser test share, and which the served teams' guard against parking
//! (`lasertag_policy::unpark`) is built to act within.
//!
//! "Still" is about place, not heading: a robot turning on the spot, or rocking back and
//! forth within a hand's breadth, is as parked to the person hiding from it as one that does
//! nothing. A spell starts where the agent is and lasts while it stays within
//! [`STILL_RADIUS_M`] of that point; leaving the disc starts a new spell there.

use nalgebra::Point2;

/// How far an agent may move from where its spell began and still count as standing there:
/// its own radius.
pub const STILL_RADIUS_M: f32 = super::AGENT_RADIUS;

/// One agent's current spell of standing still.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StillSpell {
    anchor: Point2<f32>,
    since_tick: u64,
}

impl StillSpell {
    /// A spell starting at `at` on tick `tick`.
    pub fn new(at: Point2<f32>, tick: u64) -> StillSpell {
        StillSpell {
            anchor: at,
            since_tick: tick,
        }
    }

    /// Moves the spell on to tick `tick`, the agent at `at`: a new spell starts there when it
    /// has left the disc. Returns the ticks the spell has lasted.
    pub fn update(&mut self, at: Point2<f32>, tick: u64) -> u64 {
        if (at - self.anchor).norm() > STILL_RADIUS_M {
            *self = StillSpell::new(at, tick);
        }
        self.ticks(tick)
    }

    /// Ticks from the spell's start to `tick`.
    pub fn ticks(&self, tick: u64) -> u64 {
        tick.saturating_sub(self.since_tick)
    }
}

/// The longest spell of standing still of each of several agents, over the ticks it is fed:
/// a measurement, restarted by [`LongestStill::pause`] over ticks that do not count (a
/// frozen robot cannot move).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LongestStill {
    spells: Vec<Option<StillSpell>>,
    longest_ticks: u64,
}

impl LongestStill {
    /// Agent `agent` at `at` on tick `tick`.
    pub fn push(&mut self, agent: usize, at: Point2<f32>, tick: u64) {
        if self.spells.len() <= agent {
            self.spells.resize(agent + 1, None);
        }
        let spell = self.spells[agent].get_or_insert(StillSpell::new(at, tick));
        let ticks = spell.update(at, tick);
        self.longest_ticks = self.longest_ticks.max(ticks);
    }

    /// Agent `agent` does not count until it is pushed again (its spell starts afresh then).
    pub fn pause(&mut self, agent: usize) {
        if let Some(spell) = self.spells.get_mut(agent) {
            *spell = None;
        }
    }

    /// The longest spell of any agent so far, in ticks.
    pub fn longest_ticks(&self) -> u64 {
        self.longest_ticks
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn turning_or_rocking_on_the_spot_is_standing_still_and_walking_off_is_not() {
        let mut s = StillSpell::new(Point2::new(1.0, 1.0), 10);
        // Rocking within the disc: the spell goes on.
        for (tick, dx) in [(20, 0.2), (30, -0.2), (40, 0.1)] {
            assert_eq!(s.update(Point2::new(1.0 + dx, 1.0), tick), tick - 10);
        }
        // Out of it: a new spell from there.
        assert_eq!(s.update(Point2::new(1.3, 1.0), 50), 0);
        assert_eq!(s.update(Point2::new(1.3, 1.2), 70), 20);
    }

    #[test]
    fn the_longest_spell_is_any_agents_and_a_pause_restarts_one() {
        let mut l = LongestStill::default();
        for tick in 0..=100 {
            // Agent 0 walks; agent 1 stands, but is paused at tick 50.
            l.push(0, Point2::new(tick as f32 * 0.05, 0.0), tick);
            if tick == 50 {
                l.pause(1);
            } else {
                l.push(1, Point2::new(3.0, 3.0), tick);
            }
        }
        assert_eq!(l.longest_ticks(), 49, "ticks 0..49, then 51..100");
    }
}
