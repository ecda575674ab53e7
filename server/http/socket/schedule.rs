//! Which of a connection's compact snapshots carries what (`protocol::compact`): the slow
//! parts (scans, clouds) every [`SLOW_EVERY`] ticks, the belief every
//! [`BELIEF_COMPACT_EVERY`], both on the last snapshot; and each snapshot goes as a delta
//! against the whole one sent before it when that is shorter, on a carrier that loses none.

use axum::body::Bytes;

use crate::protocol::compact::{self, BELIEF_COMPACT_EVERY, SLOW_EVERY};

/// Whether a part last sent with tick `at`'s snapshot goes again with tick `tick`'s, sent
/// every `every` ticks: when it never went, when `every` ticks have passed, when time went
/// back (a tagged player's view goes over to the spectators' later frames), or when forced.
pub fn due(at: Option<u64>, tick: u64, every: u64, force: bool) -> bool {
    force || at.is_none_or(|t| tick >= t + every || tick < t)
}

/// The parts a snapshot carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Parts {
    pub slow: bool,
    pub belief: bool,
}

/// One connection's compact snapshots so far: the ticks whose snapshot last carried the
/// slow parts and the belief, and the last one sent whole (the next delta's base).
#[derive(Debug, Default)]
pub struct Schedule {
    slow_at: Option<u64>,
    belief_at: Option<u64>,
    sent: Option<Bytes>,
    /// Whether snapshots go as deltas (on a carrier that loses none).
    deltas: bool,
}

impl Schedule {
    /// A connection's schedule; `deltas`: whether its snapshots may go as deltas.
    pub fn new(deltas: bool) -> Schedule {
        Schedule {
            deltas,
            ..Schedule::default()
        }
    }

    /// What the snapshot of `tick` carries: each part when it is due, and the belief only
    /// when the connection wants it and the frame has one.
    pub fn parts(&self, tick: u64, finished: bool, belief: bool) -> Parts {
        Parts {
            slow: due(self.slow_at, tick, SLOW_EVERY, finished),
            belief: belief && due(self.belief_at, tick, BELIEF_COMPACT_EVERY, finished),
        }
    }

    /// Records the snapshot of `tick` made with `carried` (a player's own view has no slow
    /// parts), and gives what to send: a delta against the last one, or `whole`.
    pub fn sent(&mut self, tick: u64, carried: Parts, whole: Bytes) -> Bytes {
        let bytes = match self
            .sent
            .as_deref()
            .filter(|_| self.deltas)
            .and_then(|base| compact::delta(base, &whole))
        {
            Some(d) => d.into(),
            None => whole.clone(),
        };
        self.sent = Some(whole);
        if carried.slow {
            self.slow_at = Some(tick);
        }
        if carried.belief {
            self.belief_at = Some(tick);
        }
        bytes
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::compact::{KIND_DELTA, KIND_WHOLE};

    #[test]
    fn parts_come_when_due_and_again_after_time_went_back() {
        let mut s = Schedule::new(true);
        let all = Parts {
            slow: true,
            belief: true,
        };
        assert_eq!(s.parts(10, false, true), all);
        s.sent(10, all, Bytes::from_static(&[KIND_WHOLE, 0, 0, 0, 0, 10]));
        assert_eq!(
            s.parts(11, false, true),
            Parts {
                slow: false,
                belief: false
            }
        );
        let slow = s.parts(10 + SLOW_EVERY, false, true);
        assert_eq!((slow.slow, slow.belief), (true, false));
        assert!(s.parts(10 + BELIEF_COMPACT_EVERY, false, true).belief);
        assert!(!s.parts(10 + BELIEF_COMPACT_EVERY, false, false).belief);
        // Back in time (the spectators' frames, later than the player's), or the end.
        assert_eq!(s.parts(9, false, true), all);
        assert_eq!(s.parts(11, true, true), all);
    }

    #[test]
    fn a_players_own_view_leaves_the_slow_parts_due() {
        let mut s = Schedule::new(true);
        let own = Parts {
            slow: false,
            belief: true,
        };
        s.sent(10, own, Bytes::from_static(&[KIND_WHOLE, 0, 0, 0, 0, 10]));
        assert!(s.parts(11, false, true).slow);
        assert!(!s.parts(11, false, true).belief);
    }

    #[test]
    fn each_snapshot_after_the_first_is_a_delta_when_shorter() {
        let mut s = Schedule::new(true);
        let none = Parts {
            slow: false,
            belief: false,
        };
        let whole = |tick: u8, tail: &[u8]| {
            let mut b = vec![KIND_WHOLE, 0, tick, 0, 0, 0];
            b.extend_from_slice(tail);
            Bytes::from(b)
        };
        let first = whole(1, &[7; 40]);
        assert_eq!(s.sent(1, none, first.clone()), first);
        let next = s.sent(2, none, whole(2, &[7; 40]));
        assert_eq!(next[0], KIND_DELTA);
        assert!(next.len() < first.len());
        // Another length: no delta.
        let other = whole(3, &[7; 41]);
        assert_eq!(s.sent(3, none, other.clone()), other);
        // A carrier that may lose snapshots: each goes whole.
        let mut lossy = Schedule::new(false);
        lossy.sent(1, none, first.clone());
        assert_eq!(lossy.sent(2, none, whole(2, &[7; 40]))[0], KIND_WHOLE);
    }
}
