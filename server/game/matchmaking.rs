//! The queue's matchmaking, as pure logic: who plays with whom, and when.
//!
//! People who press *Play with others* wait in a [`Pool`] as tickets, each with a rating on
//! the Glicko scale. As in Lichess's rating pools, each ticket accepts people within a window
//! around its own rating that widens the longer it has waited ([`Window`]); two people may
//! play together when each lies in the other's window. [`Pool::form`], called about once a
//! second, starts the groups that should start now: a full group at once, a smaller one once
//! its oldest member has waited [`Rules::gather`] (a bigger group is better, but not at any
//! wait), and whoever would otherwise wait past [`Rules::max_wait`] with whatever compatible
//! people there are, or alone, bots filling the opponents' side up to [`Rules::min_group`].
//! The robot team is the preset nearest the group's mean rating ([`preset_for`]).
//!
//! No clock, no I/O, no tasks: the caller passes its own time as a [`Duration`] since any
//! origin, and the same calls give the same groups (tickets are kept in the order they
//! joined, and every choice is made in a fixed order). The queue's service
//! (`service`, `http`) owns the clock and the sockets. docs/queue.md has the figures.

use std::time::Duration;

use lasertag_core::difficulty::Difficulty;

/// The rating a name nobody has rated yet has (Glicko-2's start, docs/ratings.md): what the
/// caller passes for a newcomer, and what a rating that is not a number counts as.
pub const NEW_PLAYER_RATING: f64 = 1500.0;

/// How far from its own rating a ticket accepts others: `start` points either side at once,
/// `per_second` more for every second waited, never more than `cap`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    pub start: f64,
    pub per_second: f64,
    pub cap: f64,
}

impl Window {
    /// The half-width of the window after `waited`.
    pub fn after(&self, waited: Duration) -> f64 {
        (self.start + self.per_second * waited.as_secs_f64()).min(self.cap)
    }
}

/// What the queue promises and how it trades a wait against a better match.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rules {
    /// People a match needs on the opponents' side; bots fill the seats people do not.
    pub min_group: usize,
    /// People a match takes at most.
    pub max_group: usize,
    /// Nobody waits longer than this for a match.
    pub max_wait: Duration,
    /// How often the caller calls [`Pool::form`]: a ticket that would pass `max_wait` before
    /// the next call is matched at this one, so that nobody waits past it.
    pub call_every: Duration,
    /// How long a group that could start, but is not full, waits (counted from its oldest
    /// member's joining) for more people to make it bigger.
    pub gather: Duration,
    pub window: Window,
}

impl Default for Rules {
    /// The queue's rules as served: 2 to 5 people, nobody past 30 s, a window of ±100 that
    /// grows 20 points a second up to ±500 (reached after 20 s), groups held up to 6 s to
    /// grow. The simulated crowd's figures for them, and for other choices, are in
    /// docs/queue.md.
    fn default() -> Self {
        Rules {
            min_group: 2,
            max_group: 5,
            max_wait: Duration::from_secs(30),
            call_every: Duration::from_secs(1),
            gather: Duration::from_secs(6),
            window: Window {
                start: 100.0,
                per_second: 20.0,
                cap: 500.0,
            },
        }
    }
}

/// A match the queue starts: the people in it, oldest ticket first.
#[derive(Debug, Clone, PartialEq)]
pub struct Group {
    pub members: Vec<u64>,
    /// The members' mean rating: the level the robot team is chosen for ([`preset_for`]).
    pub mean_rating: f64,
    /// The highest member's rating minus the lowest's.
    pub spread: f64,
    /// Opponents' seats bots fill because fewer than [`Rules::min_group`] people were there.
    pub filled_by_bots: usize,
}

/// One person waiting.
#[derive(Debug, Clone, Copy)]
struct Ticket {
    id: u64,
    rating: f64,
    joined: Duration,
}

/// The tickets waiting, and the rules that match them.
#[derive(Debug, Clone)]
pub struct Pool {
    rules: Rules,
    /// Oldest first (by joining time, then by arrival): every choice walks them in this
    /// order, which is what makes [`Pool::form`] deterministic. At most one ticket an id.
    tickets: Vec<Ticket>,
}

impl Pool {
    /// An empty pool. Rules that cannot hold are brought within reach rather than refused:
    /// `max_group` at least 1, `min_group` between 1 and `max_group`.
    pub fn new(rules: Rules) -> Self {
        let max_group = rules.max_group.max(1);
        let rules = Rules {
            max_group,
            min_group: rules.min_group.clamp(1, max_group),
            ..rules
        };
        Pool {
            rules,
            tickets: Vec::new(),
        }
    }

    pub fn rules(&self) -> &Rules {
        &self.rules
    }

    /// Puts `id` in the queue at `now`. A rating that is not a number counts as a
    /// newcomer's. Returns false, and changes nothing, when `id` is already waiting (its wait
    /// goes on from its first joining).
    pub fn join(&mut self, id: u64, rating: f64, now: Duration) -> bool {
        if self.tickets.iter().any(|t| t.id == id) {
            return false;
        }
        let rating = if rating.is_finite() {
            rating
        } else {
            NEW_PLAYER_RATING
        };
        // After every ticket that joined at `now` or before: a caller whose clock steps back
        // a little still gets a fixed order.
        let at = self.tickets.partition_point(|t| t.joined <= now);
        self.tickets.insert(
            at,
            Ticket {
                id,
                rating,
                joined: now,
            },
        );
        true
    }

    /// Takes `id` out of the queue; false when it was not waiting (already matched, or
    /// never joined).
    pub fn leave(&mut self, id: u64) -> bool {
        let before = self.tickets.len();
        self.tickets.retain(|t| t.id != id);
        self.tickets.len() != before
    }

    /// How many people are waiting.
    pub fn waiting(&self) -> usize {
        self.tickets.len()
    }

    /// How long `id` has waited at `now`; `None` when it is not waiting.
    pub fn waited(&self, id: u64, now: Duration) -> Option<Duration> {
        self.tickets
            .iter()
            .find(|t| t.id == id)
            .map(|t| now.saturating_sub(t.joined))
    }

    /// Forms the groups that should start now and takes their members out of the pool.
    ///
    /// Oldest ticket first, each not yet placed this call anchors a group: the people
    /// compatible with it, closest rating first, each added when it is compatible with every
    /// member so far, up to `max_group`. The group starts when it is full, when it has
    /// `min_group` people and its anchor has waited `gather`, or whatever its size when the
    /// anchor would pass `max_wait` before the next call. A group that does not start yet
    /// keeps its members for its anchor this call, so younger tickets do not break up the
    /// match of one who has waited longer.
    pub fn form(&mut self, now: Duration) -> Vec<Group> {
        let rules = self.rules;
        let waits: Vec<Duration> = self
            .tickets
            .iter()
            .map(|t| now.saturating_sub(t.joined))
            .collect();
        let windows: Vec<f64> = waits.iter().map(|&w| rules.window.after(w)).collect();
        let compatible = |a: usize, b: usize| {
            let apart = (self.tickets[a].rating - self.tickets[b].rating).abs();
            apart <= windows[a] && apart <= windows[b]
        };
        let mut placed = vec![false; self.tickets.len()];
        let mut starting: Vec<Vec<usize>> = Vec::new();
        for anchor in 0..self.tickets.len() {
            if placed[anchor] {
                continue;
            }
            let group = self.gather_around(anchor, &placed, &compatible);
            let waited = waits[anchor];
            let due = waited.saturating_add(rules.call_every) > rules.max_wait;
            let starts = group.len() >= rules.max_group
                || due
                || (group.len() >= rules.min_group && waited >= rules.gather);
            for &member in &group {
                placed[member] = true;
            }
            if starts {
                starting.push(group);
            }
        }
        let groups = starting
            .iter()
            .map(|members| self.group_of(members))
            .collect();
        let mut leaving = vec![false; self.tickets.len()];
        for &member in starting.iter().flatten() {
            leaving[member] = true;
        }
        let mut index = 0;
        self.tickets.retain(|_| {
            index += 1;
            !leaving[index - 1]
        });
        groups
    }

    /// The group `anchor` would play in now: itself, then the free tickets compatible with
    /// it, closest rating first (the older first between equals), each taken when it is
    /// compatible with every member so far. Indices, oldest first.
    fn gather_around(
        &self,
        anchor: usize,
        placed: &[bool],
        compatible: &impl Fn(usize, usize) -> bool,
    ) -> Vec<usize> {
        let rating = self.tickets[anchor].rating;
        let mut candidates: Vec<usize> = (0..self.tickets.len())
            .filter(|&c| c != anchor && !placed[c] && compatible(anchor, c))
            .collect();
        // A stable sort on a list already oldest first: equals keep that order.
        candidates.sort_by(|&a, &b| {
            let apart = |i: usize| (self.tickets[i].rating - rating).abs();
            apart(a).total_cmp(&apart(b))
        });
        let mut group = vec![anchor];
        for c in candidates {
            if group.len() >= self.rules.max_group {
                break;
            }
            if group.iter().all(|&m| compatible(m, c)) {
                group.push(c);
            }
        }
        group.sort_unstable();
        group
    }

    fn group_of(&self, members: &[usize]) -> Group {
        let ratings = members.iter().map(|&m| self.tickets[m].rating);
        let lowest = ratings.clone().fold(f64::INFINITY, f64::min);
        let highest = ratings.clone().fold(f64::NEG_INFINITY, f64::max);
        Group {
            members: members.iter().map(|&m| self.tickets[m].id).collect(),
            mean_rating: ratings.sum::<f64>() / members.len() as f64,
            spread: highest - lowest,
            filled_by_bots: self.rules.min_group.saturating_sub(members.len()),
        }
    }
}

/// The robot preset whose fixed rating (docs/ratings.md) is nearest `rating`, a group's
/// level; between two equally near, the first in [`Difficulty::ALL`] (elite before learned,
/// whose measured ratings are the same).
pub fn preset_for(rating: f64) -> Difficulty {
    let apart = |d: Difficulty| (d.rating().rating - rating).abs();
    Difficulty::ALL
        .into_iter()
        .reduce(|best, d| if apart(d) < apart(best) { d } else { best })
        .unwrap_or(Difficulty::DEFAULT)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(seconds: f64) -> Duration {
        Duration::from_secs_f64(seconds)
    }

    /// Calls `form` once a second from `from` to `to` (inclusive), as the service does,
    /// returning each group with the second it formed.
    fn run(pool: &mut Pool, from: u64, to: u64) -> Vec<(u64, Group)> {
        let mut out = Vec::new();
        for second in from..=to {
            for group in pool.form(s(second as f64)) {
                out.push((second, group));
            }
        }
        out
    }

    #[test]
    fn close_ratings_play_together_once_the_oldest_has_gathered() {
        let mut pool = Pool::new(Rules::default());
        pool.join(1, 1500.0, s(0.0));
        pool.join(2, 1540.0, s(1.0));
        pool.join(3, 1480.0, s(2.0));
        // Formable from the third second, held for more people until the oldest has waited
        // `gather` (6 s).
        assert!(run(&mut pool, 0, 5).is_empty());
        assert_eq!(pool.waiting(), 3);
        let formed = run(&mut pool, 6, 6);
        assert_eq!(formed.len(), 1);
        let group = &formed[0].1;
        assert_eq!(group.members, vec![1, 2, 3]);
        assert_eq!(group.filled_by_bots, 0);
        assert!((group.mean_rating - 1506.666).abs() < 0.01);
        assert_eq!(group.spread, 60.0);
        assert_eq!(pool.waiting(), 0);
    }

    #[test]
    fn a_full_group_starts_at_once() {
        let mut pool = Pool::new(Rules::default());
        for id in 0..7 {
            pool.join(id, 1500.0 + id as f64, s(0.5));
        }
        let formed = pool.form(s(1.0));
        assert_eq!(formed.len(), 1);
        assert_eq!(formed[0].members, vec![0, 1, 2, 3, 4]);
        // The two left over wait for more (nobody has waited `gather` yet).
        assert_eq!(pool.waiting(), 2);
        assert_eq!(pool.waited(5, s(1.0)), Some(s(0.5)));
    }

    #[test]
    fn far_ratings_wait_for_their_windows_to_meet() {
        let mut pool = Pool::new(Rules::default());
        // 300 apart: each window must reach ±300, which takes (300 − 100) / 20 = 10 s.
        pool.join(1, 1300.0, s(0.0));
        pool.join(2, 1600.0, s(0.0));
        let formed = run(&mut pool, 0, 30);
        assert_eq!(formed.len(), 1);
        let (second, group) = &formed[0];
        assert_eq!(*second, 10);
        assert_eq!(group.members, vec![1, 2]);
        assert_eq!(group.filled_by_bots, 0);
    }

    #[test]
    fn nobody_waits_past_max_wait_and_bots_fill_a_lone_player() {
        let mut pool = Pool::new(Rules::default());
        // Beyond the cap of ±500 from each other: they never meet.
        pool.join(1, 1000.0, s(0.4));
        pool.join(2, 2000.0, s(3.7));
        let formed = run(&mut pool, 1, 60);
        assert_eq!(formed.len(), 2);
        for (second, group) in &formed {
            assert_eq!(group.members.len(), 1);
            assert_eq!(group.filled_by_bots, 1);
            assert_eq!(group.spread, 0.0);
            let joined = if group.members == [1] { 0.4 } else { 3.7 };
            let waited = *second as f64 - joined;
            assert!((29.0..=30.0).contains(&waited), "{waited}");
        }
        assert_eq!(pool.waiting(), 0);
    }

    #[test]
    fn at_the_deadline_the_oldest_takes_whoever_is_compatible() {
        let mut pool = Pool::new(Rules {
            gather: s(60.0),
            ..Rules::default()
        });
        pool.join(1, 1500.0, s(0.0));
        pool.join(2, 1520.0, s(10.0));
        // Compatible from the start, but held (a long `gather`) until the oldest is due.
        let formed = run(&mut pool, 0, 40);
        assert_eq!(formed.len(), 1);
        assert_eq!(formed[0].0, 30);
        assert_eq!(formed[0].1.members, vec![1, 2]);
        assert_eq!(formed[0].1.filled_by_bots, 0);
    }

    #[test]
    fn six_who_press_within_three_seconds_all_play_within_max_wait() {
        let mut pool = Pool::new(Rules::default());
        let mut joined = Vec::new();
        let mut formed = Vec::new();
        for second in 0..=40u64 {
            // One every half second from 0 to 2.5 s, the form call between two of them.
            for id in 0..6u64 {
                let at = id as f64 * 0.5;
                if at > second as f64 - 1.0 && at <= second as f64 {
                    pool.join(id, 1450.0 + id as f64 * 20.0, s(at));
                    joined.push(at);
                }
            }
            formed.extend(run(&mut pool, second, second));
        }
        let mut played = 0;
        for (second, group) in &formed {
            for &id in &group.members {
                assert!(*second as f64 - joined[id as usize] <= 30.0);
                played += 1;
            }
        }
        assert_eq!(played, 6);
        // The first five fill a match as soon as they are there; the sixth waits for more
        // and, with nobody coming, plays beside a bot.
        assert_eq!(formed[0].0, 2);
        assert_eq!(formed[0].1.members, vec![0, 1, 2, 3, 4]);
        assert_eq!(formed[1].1.filled_by_bots, 1);
    }

    #[test]
    fn younger_tickets_do_not_break_up_an_older_ones_group() {
        let mut pool = Pool::new(Rules {
            gather: s(2.0),
            ..Rules::default()
        });
        pool.join(1, 1500.0, s(0.0));
        pool.join(2, 1600.0, s(0.0));
        for id in 3..=6 {
            pool.join(id, 1700.0, s(0.0));
        }
        // 2 and 3..=6 (100 apart, windows ±120 at 1 s) would make a full group, but 2 is in
        // 1's, held to grow: the younger ones wait too rather than leave 1 alone.
        assert!(pool.form(s(1.0)).is_empty());
        let formed = pool.form(s(2.0));
        let members: Vec<&[u64]> = formed.iter().map(|g| g.members.as_slice()).collect();
        assert_eq!(members, [&[1, 2][..], &[3, 4, 5, 6][..]]);
    }

    #[test]
    fn no_group_is_bigger_than_max_group() {
        let mut pool = Pool::new(Rules::default());
        for id in 0..23 {
            pool.join(id, 1500.0 + (id % 4) as f64 * 10.0, s(id as f64 * 0.1));
        }
        let formed = run(&mut pool, 0, 31);
        let sizes: Vec<usize> = formed.iter().map(|(_, g)| g.members.len()).collect();
        assert!(sizes.iter().all(|&n| (1..=5).contains(&n)), "{sizes:?}");
        assert_eq!(sizes.iter().sum::<usize>(), 23);
        assert_eq!(sizes.iter().filter(|&&n| n == 5).count(), 4);
    }

    #[test]
    fn everyone_in_a_group_is_in_everyone_elses_window() {
        let mut pool = Pool::new(Rules::default());
        let ratings = [1500.0, 1590.0, 1410.0, 1680.0, 1320.0, 1500.0];
        for (id, &rating) in ratings.iter().enumerate() {
            pool.join(id as u64, rating, s(0.0));
        }
        // At 2 s every window is ±140: 1590 and 1410 both fit 1500, but not each other.
        let formed = pool.form(s(2.0));
        assert!(formed.is_empty());
        let formed = pool.form(s(6.0));
        // ±220 at 6 s: 1410 and 1590 now fit each other too; 1320 and 1680 each fit 1500, but
        // not both 1410 and 1590.
        assert_eq!(formed.len(), 1, "{formed:?}");
        assert_eq!(formed[0].members, vec![0, 1, 2, 5]);
        assert_eq!(formed[0].spread, 180.0);
        assert_eq!(pool.waiting(), 2);
    }

    #[test]
    fn one_who_left_is_never_matched() {
        let mut pool = Pool::new(Rules::default());
        pool.join(1, 1500.0, s(0.0));
        pool.join(2, 1500.0, s(0.0));
        assert!(pool.leave(1));
        assert!(!pool.leave(1));
        assert_eq!(pool.waited(1, s(1.0)), None);
        let formed = run(&mut pool, 0, 30);
        assert_eq!(formed.len(), 1);
        assert_eq!(formed[0].1.members, vec![2]);
        assert_eq!(formed[0].1.filled_by_bots, 1);
    }

    #[test]
    fn joining_twice_keeps_the_first_ticket() {
        let mut pool = Pool::new(Rules::default());
        assert!(pool.join(7, 1500.0, s(1.0)));
        assert!(!pool.join(7, 2200.0, s(5.0)));
        assert_eq!(pool.waiting(), 1);
        assert_eq!(pool.waited(7, s(5.0)), Some(s(4.0)));
        pool.join(8, f64::NAN, s(1.0));
        let formed = pool.form(s(8.0));
        // 7 kept its first rating, and 8 counts as a newcomer at 1500.
        assert_eq!(formed.len(), 1);
        assert_eq!(formed[0].members, vec![7, 8]);
        assert_eq!(formed[0].mean_rating, 1500.0);
    }

    #[test]
    fn the_same_calls_give_the_same_groups() {
        // 40 people joining 0.7 s apart, at ratings 1200 to 1800, `form` once a second.
        let calls = || {
            let mut pool = Pool::new(Rules::default());
            let mut formed = Vec::new();
            for second in 0..=60u64 {
                for id in 0..40u64 {
                    let joins = id as f64 * 0.7;
                    if joins > second as f64 - 1.0 && joins <= second as f64 {
                        let rating = 1200.0 + (id * 37 % 11) as f64 * 60.0;
                        pool.join(id, rating, s(joins));
                    }
                }
                formed.extend(run(&mut pool, second, second));
            }
            formed
        };
        let first = calls();
        assert!(first.len() > 5, "{first:?}");
        let matched: usize = first.iter().map(|(_, g)| g.members.len()).sum();
        assert_eq!(matched, 40);
        assert_eq!(first, calls());
        // Tickets that join at one instant are taken in the order they joined.
        let mut pool = Pool::new(Rules::default());
        for id in [9, 3, 5] {
            pool.join(id, 1500.0, s(2.0));
        }
        assert_eq!(pool.form(s(8.0))[0].members, vec![9, 3, 5]);
    }

    #[test]
    fn the_window_grows_to_its_cap() {
        let window = Rules::default().window;
        assert_eq!(window.after(s(0.0)), 100.0);
        assert_eq!(window.after(s(10.0)), 300.0);
        assert_eq!(window.after(s(25.0)), 500.0);
    }

    #[test]
    fn rules_that_cannot_hold_are_brought_within_reach() {
        let pool = Pool::new(Rules {
            min_group: 9,
            max_group: 0,
            ..Rules::default()
        });
        assert_eq!((pool.rules().min_group, pool.rules().max_group), (1, 1));
    }

    #[test]
    fn the_preset_is_the_nearest_by_rating() {
        assert_eq!(preset_for(1200.0), Difficulty::Recruit);
        assert_eq!(preset_for(1480.0), Difficulty::Recruit);
        // Nearer veteran's 1545 than recruit's 1437.
        assert_eq!(preset_for(1500.0), Difficulty::Veteran);
        assert_eq!(preset_for(1520.0), Difficulty::Veteran);
        assert_eq!(preset_for(1900.0), Difficulty::Veteran);
        assert_eq!(preset_for(2100.0), Difficulty::Elite);
        assert_eq!(preset_for(f64::NAN), Difficulty::Recruit);
    }
}
