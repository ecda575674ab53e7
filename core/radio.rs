//! The team radio: what robots tell each other, and a seeded channel that delays and drops it.
//!
//! Every tick each robot broadcasts one [`Message`]: its pose estimate, what it sensed (the
//! owned form of a [`tracker::Sighting`](crate::tracker::Sighting)), how many opponents its
//! tag device has hit so far, and its plans ([`Status`]: goal, claim, route, whether it
//! pursues or makes way). Each teammate receives it `latency_ticks` later, unless the channel
//! drops it, with probability `loss`, independently per receiver. [`Radio`] is that channel:
//! a queue ordered by delivery tick with its own ChaCha stream, so a match stays a pure
//! function of its seed.
//!
//! How the team uses it (`planner::Team`): with a *perfect* radio (no latency, no loss) the
//! team keeps one shared tracker and its planners read each other's state directly — shared
//! memory is what a perfect radio amounts to, and it is the centralised behaviour, exactly.
//! Otherwise each robot keeps its own tracker, fed by its own sensing plus the sightings it
//! receives, and plans from its own tracker and the last [`Message`] it heard from each
//! teammate.

use std::collections::VecDeque;
use std::sync::Arc;

use nalgebra::Point2;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use crate::sim::Pose;
use crate::sim::sensors::Detection;
use crate::tracker::Sighting;

/// Longest latency a match may ask for (5 s).
pub const MAX_LATENCY_TICKS: u32 = 100;

crate::settings! {
    /// The team radio a match runs with (`radio` in the API). Perfect by default: with a
    /// latency or a loss each robot keeps its own tracker, fed by what it senses and what it
    /// receives.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Settings as "radio" {
        /// Ticks between a robot's broadcast and its teammates' receiving it.
        pub latency_ticks: u32 = 0, range(0, MAX_LATENCY_TICKS);
        /// Probability that one teammate misses one message, independently per receiver.
        pub loss: f32 = 0.0, range(0.0, 1.0);
    }
    internal {
        /// Messages carry the sender's sightings. Off, robots hear teammates' poses and plans
        /// but not what they see (no shared hypotheses): for the reacquire experiment.
        pub share_sightings: bool = true;
        /// Run the per-robot machinery (one tracker per robot, the channel) even when the radio
        /// is perfect. Its result must equal the shared path's; tests and experiments use this.
        pub per_robot: bool = false;
    }
}

impl Settings {
    /// Everything arrives at once: teammates may as well share memory.
    pub fn perfect(&self) -> bool {
        self.latency_ticks == 0 && self.loss == 0.0 && self.share_sightings
    }

    /// Whether each robot keeps its own tracker.
    pub fn uses_channel(&self) -> bool {
        self.per_robot || !self.perfect()
    }
}

/// The owned form of a [`Sighting`]: it outlives the tick it was sensed in.
#[derive(Debug, Clone, PartialEq)]
pub struct OwnedSighting {
    pub pose: Pose,
    pub scan: Vec<f32>,
    pub detections: Vec<Detection>,
    pub tagged: bool,
}

impl OwnedSighting {
    pub fn from_sighting(s: &Sighting) -> OwnedSighting {
        OwnedSighting {
            pose: s.pose,
            scan: s.scan.to_vec(),
            detections: s.detections.to_vec(),
            tagged: s.tagged,
        }
    }

    /// The sighting as a tracker takes it, `age_ticks` after it was sensed.
    pub fn as_sighting(&self, age_ticks: u32) -> Sighting<'_> {
        Sighting {
            pose: self.pose,
            scan: &self.scan,
            detections: &self.detections,
            tagged: self.tagged,
            age_ticks,
        }
    }
}

/// A robot's plans as its teammates hear them (as of its last decision).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Status {
    /// Where it is going, if anywhere.
    pub goal: Option<Pose>,
    /// The candidate pose (an index into the map's view table) whose view it will observe —
    /// the `coordinated` planner's claim; `None` for other planners.
    pub claim: Option<usize>,
    /// It is pursuing an opponent it sees.
    pub pursuing: bool,
    /// What is left of its path (its position first); empty when it has arrived.
    pub route: Vec<Point2<f32>>,
    /// It is stepping off a teammate's path.
    pub making_way: bool,
    /// It is stuck behind this teammate (which has the higher index) and asks it to step
    /// aside: the robot that gives way moves itself, nobody moves another.
    pub yield_request: Option<usize>,
}

/// One robot's broadcast of one tick.
#[derive(Debug, Clone, PartialEq)]
pub struct Message {
    pub from: usize,
    pub sent: u64,
    /// The sender's estimate of its pose.
    pub pose: Pose,
    pub frozen: bool,
    /// What it sensed this tick, if it sensed (and the radio shares sightings).
    pub sighting: Option<OwnedSighting>,
    /// Opponents its tag device has hit since the start: a count rather than a flag, so a
    /// receiver that missed the message of a hit still learns of it from the next one.
    pub hits: u32,
    pub status: Status,
}

/// The channel: messages in flight, in order of delivery.
#[derive(Debug, Clone)]
pub struct Radio {
    pub settings: Settings,
    rng: ChaCha8Rng,
    /// (delivery tick, receiver, message). Delivery ticks never decrease along the queue:
    /// every message has the same latency and is sent in tick order.
    queue: VecDeque<(u64, usize, Arc<Message>)>,
}

impl Radio {
    pub fn new(settings: Settings, rng: ChaCha8Rng) -> Radio {
        Radio {
            settings,
            rng,
            queue: VecDeque::new(),
        }
    }

    /// Broadcasts `message` to the other `robots - 1` robots. One draw per receiver, always
    /// (even with no loss), so that the stream's use does not depend on the settings.
    pub fn send(&mut self, message: Message, robots: usize) {
        let at = message.sent + self.settings.latency_ticks as u64;
        let message = Arc::new(message);
        for to in (0..robots).filter(|&to| to != message.from) {
            let lost = self.rng.random::<f32>() < self.settings.loss;
            if !lost {
                self.queue.push_back((at, to, message.clone()));
            }
        }
    }

    /// Every message due by `tick`, as (receiver, message), in the order they were sent
    /// (by tick, then sender).
    pub fn deliver(&mut self, tick: u64) -> Vec<(usize, Arc<Message>)> {
        let mut out = Vec::new();
        while self.queue.front().is_some_and(|(at, ..)| *at <= tick) {
            if let Some((_, to, m)) = self.queue.pop_front() {
                out.push((to, m));
            }
        }
        out
    }

    /// Messages in flight (for tests).
    pub fn in_flight(&self) -> usize {
        self.queue.len()
    }
}

crate::checkpoint::plain_struct!(OwnedSighting {
    pose,
    scan,
    detections,
    tagged
});
crate::checkpoint::plain_struct!(Status {
    goal,
    claim,
    pursuing,
    route,
    making_way,
    yield_request,
});
crate::checkpoint::plain_struct!(Message {
    from,
    sent,
    pose,
    frozen,
    sighting,
    hits,
    status,
});
crate::checkpoint::restore_struct!(Radio {
    plain: [rng, queue],
    nested: [],
    derived: [settings],
});

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn message(from: usize, sent: u64) -> Message {
        Message {
            from,
            sent,
            pose: Pose::new(1.0, 2.0, 0.0),
            frozen: false,
            sighting: None,
            hits: 0,
            status: Status::default(),
        }
    }

    fn radio(latency_ticks: u32, loss: f32) -> Radio {
        Radio::new(
            Settings {
                latency_ticks,
                loss,
                ..Settings::default()
            },
            ChaCha8Rng::seed_from_u64(3),
        )
    }

    #[test]
    fn messages_arrive_after_the_latency_at_every_other_robot() {
        let mut r = radio(5, 0.0);
        r.send(message(1, 10), 3);
        for t in 10..15 {
            assert!(r.deliver(t).is_empty(), "tick {t}: too early");
        }
        let got = r.deliver(15);
        let to: Vec<usize> = got.iter().map(|(to, _)| *to).collect();
        assert_eq!(to, vec![0, 2], "everyone but the sender, once");
        assert_eq!(r.in_flight(), 0);
    }

    #[test]
    fn loss_drops_about_its_share_independently_per_receiver() {
        let mut r = radio(0, 0.2);
        let mut got = [0usize; 4];
        for t in 0..5_000 {
            r.send(message(0, t), 4);
            for (to, _) in r.deliver(t) {
                got[to] += 1;
            }
        }
        assert_eq!(got[0], 0);
        for n in &got[1..] {
            let share = *n as f64 / 5_000.0;
            assert!((share - 0.8).abs() < 0.03, "received {share}");
        }
        // Independent per receiver: not all three always get the same messages.
        assert!(got[1] != got[2] || got[2] != got[3]);
    }

    #[test]
    fn the_same_seed_drops_the_same_messages() {
        let run = || {
            let mut r = radio(2, 0.5);
            (0..200)
                .flat_map(|t| {
                    r.send(message((t % 3) as usize, t), 3);
                    r.deliver(t)
                        .into_iter()
                        .map(|(to, m)| (to, m.from, m.sent))
                        .collect::<Vec<_>>()
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(run(), run());
    }

    #[test]
    fn settings_are_validated_naming_the_field() {
        use crate::settings::{Group, Value};
        let mut s = Settings::default();
        s.set("latency_ticks", Value::Integer(100)).unwrap();
        s.set("loss", Value::Number(1.0)).unwrap();
        let e = s.set("latency_ticks", Value::Integer(101)).unwrap_err();
        assert_eq!(e.field, "latency_ticks", "{e}");
        for loss in [-0.1, 1.5, f64::NAN] {
            let e = s.set("loss", Value::Number(loss)).unwrap_err();
            assert_eq!(e.clone().within("radio").field, "radio.loss", "{e}");
        }
        assert!(Settings::default().perfect());
        assert!(!Settings::default().uses_channel());
    }
}
