//! Which of a connection's compact snapshots carries what (`protocol::compact`): the slow
//! parts (scans, clouds) every [`SLOW_EVERY`] ticks, the belief every
//! [`BELIEF_COMPACT_EVERY`], both on the last snapshot; and which whole snapshot the next
//! goes as a delta against, when that is shorter: on a carrier that loses none the one sent
//! before it, on one that may lose some the newest the client says it holds ([`Acks`]).

use std::collections::VecDeque;

use axum::body::Bytes;

use crate::protocol::compact::{self, Acks, BELIEF_COMPACT_EVERY, SLOW_EVERY};

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

/// Whole snapshots kept as baselines on a carrier that may lose them: 1.2 s of ticks, so a
/// client acknowledging every 8 snapshots (web/socket.js) finds one it holds over a round
/// trip up to ~800 ms, and one more behind than that gets wholes. Each is one connection's
/// own bytes, so this bounds what a connection holds (the page keeps 33).
pub const ACKED_BASES: usize = 24;

/// What a delta may be against.
#[derive(Debug)]
enum Bases {
    /// A carrier that loses nothing and keeps order: the whole snapshot sent last.
    Last(Option<Bytes>),
    /// One that may lose snapshots: the last [`ACKED_BASES`] sent whole, by tick, and the
    /// tick below which none is used. A tick sent a second time (time went back) may hold
    /// another snapshot than the client kept for it, so after one the bases restart above
    /// the newest tick sent so far.
    Acked {
        sent: VecDeque<(u32, Bytes)>,
        newest: Option<u32>,
        from: u32,
    },
}

/// One connection's compact snapshots so far: the ticks whose snapshot last carried the
/// slow parts and the belief, and the baselines of the next delta.
#[derive(Debug)]
pub struct Schedule {
    slow_at: Option<u64>,
    belief_at: Option<u64>,
    bases: Bases,
}

impl Schedule {
    /// A connection's schedule; `lossy`: whether its carrier may lose snapshots (deltas then
    /// only against those the client acknowledged).
    pub fn new(lossy: bool) -> Schedule {
        Schedule {
            slow_at: None,
            belief_at: None,
            bases: if lossy {
                Bases::Acked {
                    sent: VecDeque::with_capacity(ACKED_BASES),
                    newest: None,
                    from: 0,
                }
            } else {
                Bases::Last(None)
            },
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
    /// parts), and gives what to send: a delta against a baseline the client holds (`acks`:
    /// what it last said it holds, on a lossy carrier), or `whole`.
    pub fn sent(&mut self, tick: u64, carried: Parts, whole: Bytes, acks: Option<Acks>) -> Bytes {
        let t = compact::tick_of(&whole).unwrap_or(0);
        let base = match &mut self.bases {
            Bases::Last(last) => last.take(),
            Bases::Acked { sent, newest, from } => {
                if newest.is_some_and(|n| t <= n) {
                    sent.clear();
                    *from = newest.map_or(0, |n| n.saturating_add(1));
                }
                *newest = Some(newest.map_or(t, |n| n.max(t)));
                sent.iter()
                    .rev()
                    .find(|(at, b)| {
                        *at >= *from && b.len() == whole.len() && acks.is_some_and(|a| a.holds(*at))
                    })
                    .map(|(_, b)| b.clone())
            }
        };
        let bytes = base
            .and_then(|b| compact::delta(&b, &whole))
            .map_or_else(|| whole.clone(), Bytes::from);
        match &mut self.bases {
            Bases::Last(last) => *last = Some(whole),
            Bases::Acked { sent, .. } => {
                if sent.len() == ACKED_BASES {
                    sent.pop_front();
                }
                sent.push_back((t, whole));
            }
        }
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
        let mut s = Schedule::new(false);
        let all = Parts {
            slow: true,
            belief: true,
        };
        assert_eq!(s.parts(10, false, true), all);
        s.sent(
            10,
            all,
            Bytes::from_static(&[KIND_WHOLE, 0, 10, 0, 0, 0]),
            None,
        );
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
        let mut s = Schedule::new(false);
        let own = Parts {
            slow: false,
            belief: true,
        };
        s.sent(
            10,
            own,
            Bytes::from_static(&[KIND_WHOLE, 0, 10, 0, 0, 0]),
            None,
        );
        assert!(s.parts(11, false, true).slow);
        assert!(!s.parts(11, false, true).belief);
    }

    #[test]
    fn each_snapshot_after_the_first_is_a_delta_when_shorter() {
        let mut s = Schedule::new(false);
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
        assert_eq!(s.sent(1, none, first.clone(), None), first);
        let next = s.sent(2, none, whole(2, &[7; 40]), None);
        assert_eq!(next[0], KIND_DELTA);
        assert!(next.len() < first.len());
        // Another length: no delta.
        let other = whole(3, &[7; 41]);
        assert_eq!(s.sent(3, none, other.clone(), None), other);
        // A carrier that may lose snapshots: wholes until the client says what it holds,
        // then deltas against the newest of those alone.
        let mut lossy = Schedule::new(true);
        lossy.sent(1, none, first.clone(), None);
        assert_eq!(lossy.sent(2, none, whole(2, &[7; 40]), None)[0], KIND_WHOLE);
        let holds_1 = Some(Acks { newest: 1, bits: 0 });
        let d = lossy.sent(3, none, whole(3, &[7; 40]), holds_1);
        assert_eq!((d[0], compact::baseline_of(&d)), (KIND_DELTA, Some(1)));
        // 3 held, 2 lost: against 3.
        let holds_3 = Some(Acks {
            newest: 3,
            bits: 0b10,
        });
        let d = lossy.sent(4, none, whole(4, &[7; 40]), holds_3);
        assert_eq!(compact::baseline_of(&d), Some(3));
        // Nothing held of what is kept: whole.
        let stale = Some(Acks {
            newest: 40,
            bits: 0,
        });
        assert_eq!(
            lossy.sent(5, none, whole(5, &[7; 40]), stale)[0],
            KIND_WHOLE
        );
    }

    #[test]
    fn over_a_lossy_carrier_no_delta_against_a_tick_sent_twice() {
        let none = Parts {
            slow: false,
            belief: false,
        };
        let whole = |tick: u8, fill: u8| {
            let mut b = vec![KIND_WHOLE, 0, tick, 0, 0, 0];
            b.extend_from_slice(&[fill; 40]);
            Bytes::from(b)
        };
        let mut s = Schedule::new(true);
        s.sent(5, none, whole(5, 1), None);
        s.sent(6, none, whole(6, 1), None);
        // Time goes back: tick 5 again, another snapshot. The client's 5 may be either.
        s.sent(5, none, whole(5, 2), None);
        let holds = Some(Acks {
            newest: 6,
            bits: u32::MAX,
        });
        assert_eq!(s.sent(6, none, whole(6, 2), holds)[0], KIND_WHOLE);
        assert_eq!(s.sent(7, none, whole(7, 2), holds)[0], KIND_WHOLE);
        // Above the newest sent before, deltas again.
        let later = Some(Acks { newest: 7, bits: 0 });
        assert_eq!(s.sent(8, none, whole(8, 2), later)[0], KIND_DELTA);
    }

    #[test]
    fn a_lossy_carrier_keeps_a_bounded_number_of_bases() {
        let none = Parts {
            slow: false,
            belief: false,
        };
        let mut s = Schedule::new(true);
        for t in 0..100u8 {
            let mut b = vec![KIND_WHOLE, 0, t, 0, 0, 0];
            b.extend_from_slice(&[0; 40]);
            s.sent(u64::from(t), none, Bytes::from(b), None);
        }
        let Bases::Acked { sent, .. } = &s.bases else {
            panic!("lossy bases")
        };
        assert_eq!(sent.len(), ACKED_BASES);
    }
}
