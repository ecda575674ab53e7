//! The physical world of a match: bodies, geometry and sensors, below every decision.
//!
//! Nothing here knows of the robots' beliefs or plans (the tracker, planner and localiser sit
//! on higher floors); `crate::world::World` puts a match together.
//!
//! - `arena`: static geometry (ray casts, line of sight, clearance grid).
//! - `map_rules`: the map format's rules, checked on a map as given (`MapSpec`).
//! - `motion`: kinematics and collision resolution of disc agents.
//! - `sensors`: laser scans and anonymous opponent detections.
//! - `rules`: tagging, freezing, elimination.
//! - `still`: how long an agent has stood in one place.
//! - `views`: what each candidate destination's laser would see (the planner's footprints).

pub mod arena;
pub mod map_rules;
pub mod motion;
pub mod rules;
pub(crate) mod segments;
pub mod sensors;
pub mod still;
pub mod views;

use nalgebra::{Point2, Vector2};
use rand::RngExt;

/// Ticks per simulated second.
pub const TICK_HZ: u32 = 20;
/// Seconds per tick.
pub const DT: f32 = 1.0 / TICK_HZ as f32;
/// Every agent is a disc of this radius (metres).
pub const AGENT_RADIUS: f32 = 0.25;

crate::settings! {
    /// The robots' wheel odometry noise (the match's `odometry` object; game-rules.md: "about
    /// 5% of distance and 2° per metre, configurable"). Each is a standard deviation drawn
    /// every tick on the tick's motion; the robots' localisers model the same noise,
    /// inflated as filters should be.
    #[derive(Debug, Clone, Copy, PartialEq)]
    pub struct Odometry as "odometry" {
        /// Error of the distance driven, as a fraction of it.
        pub distance: f32 = 0.05, range(0.0, 1.0);
        /// Heading error per metre driven, degrees.
        pub heading_deg_per_m: f32 = 2.0, range(0.0, 45.0);
        /// Error of a turn, as a fraction of it.
        pub turn: f32 = 0.02, range(0.0, 1.0);
    }
}

impl Odometry {
    /// The heading error per metre driven in radians, as the noise model uses it.
    pub fn heading_per_metre(&self) -> f32 {
        self.heading_deg_per_m.to_radians()
    }
}

/// The physical parameters of a match (game-rules.md defaults).
#[derive(Debug, Clone, PartialEq)]
pub struct Physics {
    pub robot_speed: f32,
    pub robot_turn_rate: f32,
    pub opponent_speed: f32,
    pub opponent_turn_rate: f32,
    pub laser_beams: usize,
    pub laser_fov: f32,
    pub laser_range: f32,
    pub laser_noise: f32,
    pub detection_range_noise: f32,
    pub detection_bearing_noise: f32,
    pub tag_half_angle: f32,
    pub tag_range: f32,
    pub tag_cooldown_ticks: u64,
    pub freeze_ticks: u64,
    /// Wheel odometry noise per step.
    pub odometry: Odometry,
    /// Landmarks are recognised by identity within this range in line of sight, all round.
    pub landmark_range: f32,
    pub landmark_range_noise: f32,
    pub landmark_bearing_noise: f32,
}

impl Default for Physics {
    fn default() -> Self {
        Physics {
            robot_speed: 1.0,
            robot_turn_rate: 2.0,
            opponent_speed: 1.0,
            opponent_turn_rate: 3.0,
            laser_beams: 181,
            laser_fov: std::f32::consts::PI,
            laser_range: 8.0,
            laser_noise: 0.02,
            detection_range_noise: 0.05,
            detection_bearing_noise: 1f32.to_radians(),
            tag_half_angle: 5f32.to_radians(),
            tag_range: 6.0,
            tag_cooldown_ticks: TICK_HZ as u64,
            freeze_ticks: 10 * TICK_HZ as u64,
            odometry: Odometry::default(),
            // game-rules.md gives the 4 m; the noise is ours: like the opponent detector's.
            landmark_range: 4.0,
            landmark_range_noise: 0.05,
            landmark_bearing_noise: 2f32.to_radians(),
        }
    }
}

/// A position and heading (radians, counter-clockwise from +x).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub pos: Point2<f32>,
    pub theta: f32,
}

impl Pose {
    pub fn new(x: f32, y: f32, theta: f32) -> Pose {
        Pose {
            pos: Point2::new(x, y),
            theta,
        }
    }

    pub fn heading(&self) -> Vector2<f32> {
        Vector2::new(self.theta.cos(), self.theta.sin())
    }

    /// Bearing of `p` relative to this pose's heading, in (-π, π].
    pub fn bearing_to(&self, p: Point2<f32>) -> f32 {
        let d = p - self.pos;
        wrap_angle(d.y.atan2(d.x) - self.theta)
    }
}

/// Wraps an angle into (-π, π].
pub fn wrap_angle(a: f32) -> f32 {
    let tau = std::f32::consts::TAU;
    let mut a = a % tau;
    if a > std::f32::consts::PI {
        a -= tau;
    } else if a <= -std::f32::consts::PI {
        a += tau;
    }
    a
}

/// One draw from N(0, σ²), by the ziggurat method (`rand_distr`'s standard normal): most
/// draws are one 64-bit number and a table look-up, where the Box–Muller transform spends
/// a logarithm, a square root and a cosine on each, and noise is drawn per beam, per
/// particle and per tick.
pub fn gaussian(rng: &mut impl RngExt, sigma: f32) -> f32 {
    if sigma == 0.0 {
        return 0.0;
    }
    let z: f32 = rng.sample(rand_distr::StandardNormal);
    sigma * z
}

/// Which agent: robots and opponents are numbered separately (`r0`, `o0`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum AgentId {
    Robot(usize),
    Opponent(usize),
}

/// A string that is not an agent id. Ids are written one way only: `r` or `o`, then the
/// index in decimal without leading zeros (`r0`, `o12`; never `r01`, `R1` or `r+1`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0:?} is not an agent id (r0, r1, … for robots; o0, o1, … for opponents)")]
pub struct BadAgentId(pub String);

impl AgentId {
    /// The index among its kind.
    pub fn index(self) -> usize {
        match self {
            AgentId::Robot(i) | AgentId::Opponent(i) => i,
        }
    }
}

impl std::str::FromStr for AgentId {
    type Err = BadAgentId;

    fn from_str(s: &str) -> Result<Self, BadAgentId> {
        let bad = || BadAgentId(s.to_owned());
        let (kind, digits): (fn(usize) -> AgentId, &str) = match s.as_bytes().first() {
            Some(b'r') => (AgentId::Robot, &s[1..]),
            Some(b'o') => (AgentId::Opponent, &s[1..]),
            _ => return Err(bad()),
        };
        // One spelling per id: digits only, no leading zero, and short enough that no
        // match could have that many agents (which also keeps the parse from overflowing).
        let canonical = !digits.is_empty()
            && digits.len() <= 6
            && digits.bytes().all(|b| b.is_ascii_digit())
            && (digits == "0" || !digits.starts_with('0'));
        if !canonical {
            return Err(bad());
        }
        digits.parse().map(kind).map_err(|_| bad())
    }
}

impl std::fmt::Display for AgentId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AgentId::Robot(i) => write!(f, "r{i}"),
            AgentId::Opponent(i) => write!(f, "o{i}"),
        }
    }
}

/// What moves an agent this tick. Speeds are fractions of the agent's top speed and turn rate.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Motion {
    #[default]
    Stop,
    /// Differential drive (robots, and people at the keyboard): forward and turn in [-1, 1].
    Drive { forward: f32, turn: f32 },
    /// Walk straight towards a point at top speed, turning the body towards the direction of
    /// travel (API-driven opponents and bots).
    Toward(Point2<f32>),
}

crate::checkpoint::plain_struct!(Pose { pos, theta });

impl crate::checkpoint::Plain for AgentId {
    fn save(&self, w: &mut crate::checkpoint::Writer) {
        let (tag, index) = match *self {
            AgentId::Robot(i) => (0u8, i),
            AgentId::Opponent(i) => (1, i),
        };
        tag.save(w);
        index.save(w);
    }
    fn load(r: &mut crate::checkpoint::Reader) -> Result<Self, crate::checkpoint::CheckpointError> {
        match u8::load(r)? {
            0 => Ok(AgentId::Robot(usize::load(r)?)),
            1 => Ok(AgentId::Opponent(usize::load(r)?)),
            _ => Err(crate::checkpoint::CheckpointError::BadValue("an agent id")),
        }
    }
}

impl crate::checkpoint::Plain for Motion {
    fn save(&self, w: &mut crate::checkpoint::Writer) {
        match *self {
            Motion::Stop => 0u8.save(w),
            Motion::Drive { forward, turn } => {
                1u8.save(w);
                forward.save(w);
                turn.save(w);
            }
            Motion::Toward(p) => {
                2u8.save(w);
                p.save(w);
            }
        }
    }
    fn load(r: &mut crate::checkpoint::Reader) -> Result<Self, crate::checkpoint::CheckpointError> {
        match u8::load(r)? {
            0 => Ok(Motion::Stop),
            1 => Ok(Motion::Drive {
                forward: f32::load(r)?,
                turn: f32::load(r)?,
            }),
            2 => Ok(Motion::Toward(Point2::load(r)?)),
            _ => Err(crate::checkpoint::CheckpointError::BadValue("a motion")),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn agent_ids_have_one_spelling() {
        for (text, id) in [
            ("r0", AgentId::Robot(0)),
            ("r7", AgentId::Robot(7)),
            ("o12", AgentId::Opponent(12)),
        ] {
            assert_eq!(text.parse::<AgentId>(), Ok(id));
            assert_eq!(id.to_string(), text);
        }
        for bad in [
            "", "r", "o", "r01", "o007", "r007", "R1", "x1", "r+1", "r-1", "r1 ", "r1234567", "rr1",
        ] {
            assert!(bad.parse::<AgentId>().is_err(), "{bad:?} parsed");
        }
    }

    #[test]
    fn wrap_angle_stays_in_range() {
        for a in [-10.0f32, -3.2, 0.0, 3.2, 7.0, 100.0] {
            let w = wrap_angle(a);
            assert!(w > -std::f32::consts::PI - 1e-6 && w <= std::f32::consts::PI + 1e-6);
            assert!(((w - a) / std::f32::consts::TAU).fract().abs() < 1e-3 || (w - a).abs() < 1e-4);
        }
    }

    #[test]
    fn gaussian_has_the_right_spread() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let xs: Vec<f32> = (0..20_000).map(|_| gaussian(&mut rng, 2.0)).collect();
        let mean = xs.iter().sum::<f32>() / xs.len() as f32;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / xs.len() as f32;
        assert!(mean.abs() < 0.05, "{mean}");
        assert!((var.sqrt() - 2.0).abs() < 0.05, "{var}");
    }
}
