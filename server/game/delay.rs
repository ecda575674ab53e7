//! The truth of a match people play, held back from everyone but its owner.
//!
//! A person playing an opponent sees only its own line of sight. Anybody else watching the
//! same match live — a second tab, a friend on a call — would see everything: where each
//! robot is, where it is heading, and where the team believes the people are. So a match
//! people may play shows its truth (the spectator WebSocket, `GET /api/matches/{id}`,
//! `/belief`, `/events`) only `spectator_delay_s` late, long enough that it is history rather
//! than a wallhack. The match task pushes every frame it publishes into a [`HeldBack`] and
//! releases each to spectators once it is that old. Beliefs (whole particle clouds, too big
//! to keep per tick) are kept every [`BELIEF_HOLD_EVERY`] ticks, and the one shown is the
//! newest not newer than the frame shown.
//!
//! What it keeps is bounded by the delay and priced before the match is admitted
//! (`admission::held_back`).

use std::collections::VecDeque;
use std::sync::Arc;

use tokio::sync::watch;

use nalgebra::Point2;

use crate::game::view::{BELIEF_HOLD_EVERY, Frame};
use lasertag_core::tracker::{Confidence, Role};
use lasertag_core::world::{MatchStatus, World};

/// A belief as the tracker held it at one tick, kept compact (the tracker's own `f32`s) so
/// that a match can hold some back: see `game::delay`.
#[derive(Debug, Clone)]
pub struct HeldBelief {
    pub tick: u64,
    pub roles: Vec<HeldRole>,
}

/// One role of a [`HeldBelief`]: the whole particle cloud.
#[derive(Debug, Clone)]
pub struct HeldRole {
    pub id: u64,
    pub count: u32,
    pub tagged: bool,
    pub confidence: f32,
    pub state: Confidence,
    pub particles: Vec<Point2<f32>>,
    pub weights: Vec<f32>,
}

impl HeldBelief {
    /// Each role's cloud thinned to at most `at_most` particles, for a reader who
    /// does not need every one (`?particles=`): systematic resampling by weight (evenly spaced
    /// draws at (i + ½) / n of the cumulative weight, no randomness, so every reader of a tick
    /// gets the same), the drawn particles weighing alike. A role with fewer is left whole.
    pub fn thin(&mut self, at_most: usize) {
        let at_most = at_most.max(1);
        for role in &mut self.roles {
            let n = role.particles.len();
            if n <= at_most {
                continue;
            }
            let total: f64 = role.weights.iter().map(|w| f64::from(*w)).sum();
            let mut particles = Vec::with_capacity(at_most);
            let (mut i, mut cumulative) = (0, 0.0);
            for j in 0..at_most {
                let target = (j as f64 + 0.5) / at_most as f64 * total;
                while i + 1 < n && cumulative + f64::from(role.weights[i]) < target {
                    cumulative += f64::from(role.weights[i]);
                    i += 1;
                }
                particles.push(role.particles[i]);
            }
            role.particles = particles;
            role.weights = vec![1.0 / at_most as f32; at_most];
        }
    }

    /// The team's merged belief in `world` (with a perfect radio, the shared tracker's; see
    /// `Team::merged_belief`).
    pub fn team(world: &World) -> HeldBelief {
        HeldBelief::from_roles(world.tick, &world.team.merged_belief())
    }

    /// Robot `robot`'s own belief in `world`; `None` for a robot the match does not have.
    pub fn robot(world: &World, robot: usize) -> Option<HeldBelief> {
        let tracker = world.team.belief_of(robot, world.robots.len())?;
        Some(HeldBelief::from_roles(world.tick, &tracker.roles))
    }

    /// Robot `robot`'s belief now, or the team's merged one when `None`; `None` for a
    /// robot the match does not have.
    pub fn of(world: &World, robot: Option<usize>) -> Option<HeldBelief> {
        match robot {
            None => Some(HeldBelief::team(world)),
            Some(i) => HeldBelief::robot(world, i),
        }
    }

    fn from_roles(tick: u64, roles: &[Role]) -> HeldBelief {
        HeldBelief {
            tick,
            roles: roles
                .iter()
                .map(|r| HeldRole {
                    id: r.id,
                    count: r.count,
                    tagged: r.tagged,
                    confidence: r.confidence,
                    state: r.confidence_state(),
                    particles: r.particles().to_vec(),
                    weights: r.weights().to_vec(),
                })
                .collect(),
        }
    }

    /// Bytes it keeps.
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + self
                .roles
                .iter()
                .map(|r| std::mem::size_of::<HeldRole>() + r.particles.len() * 12)
                .sum::<usize>()
    }
}

/// How late a match people may play shows its truth unless its creator says otherwise.
pub const SPECTATOR_DELAY_S: f64 = 30.0;

/// The team's belief and each robot's at one tick.
#[derive(Debug)]
struct Beliefs {
    tick: u64,
    team: Arc<HeldBelief>,
    /// Each robot's own; the team's `Arc` again when they share one tracker.
    robots: Vec<Arc<HeldBelief>>,
}

impl Beliefs {
    fn of(world: &World) -> Beliefs {
        let team = Arc::new(HeldBelief::team(world));
        let shared = world.config.radio.perfect();
        let robots = (0..world.robots.len())
            .map(|i| match HeldBelief::robot(world, i) {
                Some(b) if !shared => Arc::new(b),
                _ => team.clone(),
            })
            .collect();
        Beliefs {
            tick: world.tick,
            team,
            robots,
        }
    }

    fn bytes(&self) -> usize {
        let own: usize = self
            .robots
            .iter()
            .filter(|r| !Arc::ptr_eq(r, &self.team))
            .map(|r| r.bytes())
            .sum();
        self.team.bytes() + own
    }
}

/// Frames and beliefs of a match not yet shown, and the ones shown now.
#[derive(Debug)]
pub struct HeldBack {
    delay: u64,
    /// The tick the release clock is at: the world's, and after the match has finished one
    /// more per real-time period, so the last frames come out at the pace they were made.
    now: u64,
    /// Frames not yet shown, oldest first.
    queue: VecDeque<Arc<Frame>>,
    shown: Arc<Frame>,
    /// Oldest first; the first is the one shown.
    beliefs: VecDeque<Beliefs>,
    spectators: watch::Sender<Arc<Frame>>,
}

impl HeldBack {
    /// Starts holding back a match `delay` ticks, from its first frame; spectators watch the
    /// receiver.
    pub fn new(
        delay: u64,
        first: Arc<Frame>,
        world: &World,
    ) -> (HeldBack, watch::Receiver<Arc<Frame>>) {
        let (spectators, rx) = watch::channel(first.clone());
        let held = HeldBack {
            delay,
            now: world.tick,
            queue: VecDeque::new(),
            shown: first,
            beliefs: VecDeque::from([Beliefs::of(world)]),
            spectators,
        };
        (held, rx)
    }

    /// Takes the frame just published for `world` and releases what has become old enough.
    pub fn push(&mut self, frame: Arc<Frame>, world: &World) {
        let last_kept = self.beliefs.back().map_or(0, |b| b.tick);
        let finished = world.status == MatchStatus::Finished;
        if world.tick >= last_kept + BELIEF_HOLD_EVERY || (finished && world.tick > last_kept) {
            self.beliefs.push_back(Beliefs::of(world));
        }
        self.queue.push_back(frame);
        self.now = self.now.max(world.tick);
        self.release();
    }

    /// Moves the release clock one tick on (a finished real-time match, every period).
    pub fn tick_on(&mut self) {
        self.now += 1;
        self.release();
    }

    /// Shows everything now (the match is being removed, or was stepped by hand to its end).
    pub fn flush(&mut self) {
        self.now = u64::MAX;
        self.release();
    }

    /// Whether every frame has been shown.
    pub fn drained(&self) -> bool {
        self.queue.is_empty()
    }

    fn release(&mut self) {
        let mut newest = None;
        while let Some(f) = self.queue.front()
            && f.tick.saturating_add(self.delay) <= self.now
        {
            newest = self.queue.pop_front();
        }
        let Some(frame) = newest else { return };
        self.shown = frame;
        while self.beliefs.len() > 1 && self.beliefs[1].tick <= self.shown.tick {
            self.beliefs.pop_front();
        }
        self.spectators.send_replace(self.shown.clone());
    }

    /// The frame spectators see now.
    pub fn shown(&self) -> &Arc<Frame> {
        &self.shown
    }

    /// The belief shown now: `robot`'s, or the team's; `None` for a robot the match does
    /// not have.
    pub fn belief(&self, robot: Option<usize>) -> Option<&HeldBelief> {
        let b = self.beliefs.front()?;
        match robot {
            None => Some(&b.team),
            Some(i) => b.robots.get(i).map(|r| &**r),
        }
    }

    /// The `seq` of the newest event shown.
    pub fn shown_seq(&self) -> u64 {
        self.shown.last_seq
    }

    /// Bytes it keeps (frames and beliefs), for the admission price's check.
    pub fn bytes(&self) -> usize {
        self.queue.iter().map(|f| f.bytes()).sum::<usize>()
            + self.beliefs.iter().map(Beliefs::bytes).sum::<usize>()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::maps::MapStore;
    use lasertag_core::world::MatchConfig;

    #[test]
    fn frames_come_out_exactly_the_delay_late_and_within_their_price() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let maps = MapStore::load_dir(&root.join("maps")).expect("shipped maps");
        let arena = maps.get("office").expect("office").arena.clone();
        let mut config = MatchConfig {
            robots: 3,
            opponents: 3,
            seed: 5,
            ..MatchConfig::default()
        };
        // A lossy radio: each robot keeps a tracker of its own, and each is held back.
        config.radio.loss = 0.2;
        let delay = 100;
        let price = crate::game::admission::held_back(&config, delay).memory as usize;
        let mut world = World::new(arena, config).expect("world");
        let first = Arc::new(Frame::build(&world, &Default::default(), 0, 0, true));
        let (mut held, rx) = HeldBack::new(delay, first, &world);
        let (mut seq, mut most) = (0, 0);
        for _ in 0..400 {
            world.step();
            let frame = Frame::build(
                &world,
                &Default::default(),
                seq,
                0,
                world.tick.is_multiple_of(4),
            );
            seq = frame.last_seq;
            held.push(Arc::new(frame), &world);
            let shown = rx.borrow().tick;
            assert_eq!(shown, world.tick.saturating_sub(delay));
            let belief = held.belief(Some(2)).expect("robot r2").tick;
            assert!(belief <= shown && belief + BELIEF_HOLD_EVERY > shown);
            assert!(held.belief(Some(3)).is_none());
            most = most.max(held.bytes());
        }
        // The price is a bound, and not a wild one.
        assert!(most <= price, "held {most} bytes, priced {price}");
        assert!(most * 3 > price, "held {most} bytes, priced {price}");
        held.flush();
        assert!(held.drained());
        assert_eq!(rx.borrow().tick, world.tick);
    }
}
