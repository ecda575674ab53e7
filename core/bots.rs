//! Opponent bots: `idle`, `wander` and `evade`.
//!
//! Bots are part of the environment, like the walls, so they may read the true positions of
//! the robots they can see. They walk their paths holonomically ([`Motion::Toward`]) and never
//! fire: the paper's opponent only runs and hides (people and API opponents do fire).

use nalgebra::Point2;
use rand::RngExt;

use crate::nav::{DistanceField, PathFollower};
use crate::sim::arena::Arena;
use crate::sim::{Motion, Pose};

/// How far a bot notices robots (metres, in line of sight, any direction).
pub const BOT_SIGHT: f32 = 10.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BotKind {
    Idle,
    Wander,
    Evade,
}

/// A bot's memory between ticks.
#[derive(Debug, Clone)]
pub struct Bot {
    pub kind: BotKind,
    path: PathFollower,
    /// Tick until which a wandering bot pauses at its goal.
    pause_until: u64,
    /// Next tick an evading bot may re-plan its escape.
    next_flee: u64,
    fleeing: bool,
    /// Where the bot was `STUCK_TICKS` ago, to notice it is blocked.
    progress: (Point2<f32>, u64),
}

const STUCK_TICKS: u64 = 60;

impl Bot {
    pub fn new(kind: BotKind) -> Bot {
        Bot {
            kind,
            path: PathFollower::default(),
            pause_until: 0,
            next_flee: 0,
            fleeing: false,
            progress: (Point2::origin(), 0),
        }
    }

    /// The bot's motion this tick. `robots` are the centres of robots currently in the arena.
    pub fn decide(
        &mut self,
        arena: &Arena,
        me: Pose,
        robots: &[Point2<f32>],
        tick: u64,
        rng: &mut impl RngExt,
    ) -> Motion {
        if self.kind == BotKind::Idle {
            return Motion::Stop;
        }
        if tick >= self.progress.1 + STUCK_TICKS {
            if (me.pos - self.progress.0).norm() < 0.2 && !self.path.finished() {
                self.path = PathFollower::default(); // blocked (by an agent): choose again
            }
            self.progress = (me.pos, tick);
        }
        if self.kind == BotKind::Evade {
            let threats: Vec<Point2<f32>> = robots
                .iter()
                .filter(|r| (*r - me.pos).norm() <= BOT_SIGHT && arena.line_of_sight(me.pos, **r))
                .copied()
                .collect();
            if !threats.is_empty() && tick >= self.next_flee {
                self.next_flee = tick + 20;
                if let Some(path) = flee_path(arena, me.pos, &threats, rng) {
                    self.path = PathFollower::new(path);
                    self.fleeing = true;
                }
            }
        }
        if let Some(target) = self.path.target(me.pos) {
            return Motion::Toward(target);
        }
        if self.fleeing {
            // Reached cover: catch breath before wandering on.
            self.fleeing = false;
            self.pause_until = tick + rng.random_range(20..60);
        }
        if self.pause_until == 0 {
            self.pause_until = tick + rng.random_range(0..40);
        }
        if tick < self.pause_until {
            return Motion::Stop;
        }
        self.pause_until = 0;
        if let Some(path) = wander_path(arena, me.pos, rng) {
            self.path = PathFollower::new(path);
        }
        Motion::Stop
    }
}

/// A path to a random reachable cell, preferring ones 3 m or more away.
fn wander_path(
    arena: &Arena,
    from: Point2<f32>,
    rng: &mut impl RngExt,
) -> Option<Vec<Point2<f32>>> {
    let grid = &arena.grid;
    let field = DistanceField::from_point(grid, from)?;
    let mut fallback = None;
    for _ in 0..200 {
        let cell = rng.random_range(0..grid.len());
        if !field.reachable(cell) {
            continue;
        }
        if field.dist[cell] >= 3.0 {
            return field.path_to(grid, from, cell);
        }
        fallback.get_or_insert(cell);
    }
    fallback.and_then(|cell| field.path_to(grid, from, cell))
}

/// How far a fleeing bot looks for a place to run to (metres of travel).
const FLEE_REACH: f32 = 15.0;

/// A path to the best of a sample of reachable cells: far from the threats, out of their sight,
/// and not too far to run.
fn flee_path(
    arena: &Arena,
    from: Point2<f32>,
    threats: &[Point2<f32>],
    rng: &mut impl RngExt,
) -> Option<Vec<Point2<f32>>> {
    let grid = &arena.grid;
    // Only cells within the reach are ever chosen: the field need not go further.
    let field = DistanceField::from_point_within(grid, from, FLEE_REACH)?;
    let mut best: Option<(f32, usize)> = None;
    let mut tries = 0;
    let mut found = 0;
    while found < 60 && tries < 2_000 {
        tries += 1;
        let cell = rng.random_range(0..grid.len());
        if !field.reachable(cell) || field.dist[cell] > FLEE_REACH {
            continue;
        }
        found += 1;
        let p = grid.centre(cell);
        let nearest = threats
            .iter()
            .map(|t| (t - p).norm())
            .fold(f32::INFINITY, f32::min);
        let hidden = threats.iter().all(|t| !arena.line_of_sight(*t, p));
        let score = nearest + if hidden { 4.0 } else { 0.0 } - 0.2 * field.dist[cell];
        if best.is_none_or(|(s, _)| score > s) {
            best = Some((score, cell));
        }
    }
    best.and_then(|(_, cell)| field.path_to(grid, from, cell))
}

impl crate::checkpoint::Plain for BotKind {
    fn save(&self, w: &mut crate::checkpoint::Writer) {
        (*self as u8).save(w);
    }
    fn load(r: &mut crate::checkpoint::Reader) -> Result<Self, crate::checkpoint::CheckpointError> {
        match u8::load(r)? {
            0 => Ok(BotKind::Idle),
            1 => Ok(BotKind::Wander),
            2 => Ok(BotKind::Evade),
            _ => Err(crate::checkpoint::CheckpointError::BadValue("a bot kind")),
        }
    }
}
crate::checkpoint::plain_struct!(Bot {
    kind,
    path,
    pause_until,
    next_flee,
    fleeing,
    progress,
});
