//! The people who have played a match, by name: whether each showed the token of the name's
//! claim (only then does the match count for the name's statistics and rating), and whether
//! each has played. A result needs play: a person whose body walked less than
//! [`PLAYED_METRES`] in the match (who stood still, or left at once) rates nobody, so a
//! rating can be neither farmed by idling through a match nor wrecked by joining and
//! leaving. Leaving after playing counts as a loss, as before.

use crate::store::PlayerResult;
use crate::store::codec::StoredPerson;

/// How far a person's body must walk in a match (metres, summed tick by tick) for their
/// result to rate: three seconds of walking.
pub const PLAYED_METRES: f32 = 3.0;

#[derive(Debug, Default)]
pub(super) struct People {
    list: Vec<Person>,
    /// Whether anything the store keeps changed since [`People::take_changed`].
    changed: bool,
}

#[derive(Debug, Clone)]
struct Person {
    name: String,
    claimed: bool,
    /// Metres walked in this server's run of the match (a resumed match starts again at 0;
    /// `played`, once reached, is kept).
    walked: f32,
    played: bool,
}

impl People {
    pub(super) fn restored(stored: &[StoredPerson]) -> People {
        People {
            list: stored
                .iter()
                .map(|p| Person {
                    name: p.name.clone(),
                    claimed: p.claimed,
                    walked: 0.0,
                    played: p.played,
                })
                .collect(),
            changed: false,
        }
    }

    fn person(&mut self, name: &str) -> &mut Person {
        let at = match self.list.iter().position(|p| p.name == name) {
            Some(at) => at,
            None => {
                self.list.push(Person {
                    name: name.to_string(),
                    claimed: false,
                    walked: 0.0,
                    played: false,
                });
                self.list.len() - 1
            }
        };
        &mut self.list[at]
    }

    /// `name` took a seat; `claimed` when they showed its token.
    pub(super) fn joined(&mut self, name: &str, claimed: bool) {
        let person = self.person(name);
        if claimed && !person.claimed {
            person.claimed = true;
            self.changed = true;
        }
    }

    /// `name`'s body moved `metres` this tick.
    pub(super) fn walked(&mut self, name: &str, metres: f32) {
        let person = self.person(name);
        person.walked += metres;
        if !person.played && person.walked >= PLAYED_METRES {
            person.played = true;
            self.changed = true;
        }
    }

    pub(super) fn take_changed(&mut self) -> bool {
        std::mem::take(&mut self.changed)
    }

    pub(super) fn stored(&self) -> Vec<StoredPerson> {
        self.list
            .iter()
            .map(|p| StoredPerson {
                name: p.name.clone(),
                claimed: p.claimed,
                played: p.played,
            })
            .collect()
    }

    /// The results the history keeps: claimed names only, each rating only if they played.
    pub(super) fn kept(&self, results: Vec<PlayerResult>) -> Vec<PlayerResult> {
        results
            .into_iter()
            .filter_map(|mut r| {
                let person = self.list.iter().find(|p| p.name == r.name)?;
                if !person.claimed {
                    return None;
                }
                r.rated = person.played;
                Some(r)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(name: &str) -> PlayerResult {
        PlayerResult {
            name: name.into(),
            tags: 0,
            survived_ticks: 100,
            won: true,
            rated: false,
        }
    }

    #[test]
    fn only_claimed_names_are_kept_and_only_those_who_played_rate() {
        let mut people = People::default();
        people.joined("ada", true);
        people.joined("bob", false);
        people.joined("cy", true);
        for _ in 0..60 {
            people.walked("ada", 0.1);
            people.walked("bob", 0.1);
        }
        people.walked("cy", 1.0);
        let kept = people.kept(vec![result("ada"), result("bob"), result("cy")]);
        let names: Vec<_> = kept.iter().map(|r| (r.name.as_str(), r.rated)).collect();
        assert_eq!(names, [("ada", true), ("cy", false)]);
    }

    #[test]
    fn what_was_played_survives_a_restart() {
        let mut people = People::default();
        people.joined("ada", true);
        assert!(people.take_changed());
        people.walked("ada", PLAYED_METRES);
        assert!(people.take_changed());
        assert!(!people.take_changed());
        let back = People::restored(&people.stored());
        assert!(back.kept(vec![result("ada")])[0].rated);
    }
}
