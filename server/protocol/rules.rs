//! `GET /api/rules`: the physical and sensor constants every match plays by, and the bounds of
//! the requests, for clients that would otherwise write them down themselves (the page's
//! laser fans, the Python environment's observation vector). Each value is read from its one
//! declaration: the core's [`Physics`] defaults and constants, and [`bounds`].
//!
//! The opponents' motion is the same as the `kinematics` of the WebSocket's `welcome`
//! (a test holds the two together).

use serde::Serialize;
use utoipa::ToSchema;

use super::bounds::{self, Bound};
use lasertag_core::settings::Kind;
use lasertag_core::sim::{AGENT_RADIUS, Physics, TICK_HZ};

/// The core's `f32`s, as the decimals they were written as (no `0.05000000074505806`).
fn exact(v: f32) -> f64 {
    ((v as f64) * 1e6).round() / 1e6
}

/// Radians as degrees, to the same precision (`180`, not `180.00000500895632`).
fn degrees(radians: f32) -> f64 {
    exact(radians.to_degrees())
}

/// The rules of every match. Lengths in metres, times in seconds or ticks, angles in degrees,
/// turn rates in radians per second (as the `welcome`'s `kinematics`).
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct Rules {
    /// Ticks per second of match time.
    pub tick_hz: u32,
    /// Every agent is a disc of this radius.
    pub agent_radius: f64,
    pub robot: Motion,
    pub opponent: Motion,
    pub laser: Laser,
    pub detection: Detection,
    pub tag: Tag,
    /// Ticks a tagged robot stays frozen (it neither moves, senses nor shoots).
    pub freeze_ticks: u64,
    pub landmarks: Landmarks,
    pub bounds: RequestBounds,
}

/// How fast an agent goes at full command (`forward` 1, `turn` 1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, ToSchema)]
pub struct Motion {
    /// Metres per second.
    pub speed: f64,
    /// Radians per second.
    pub turn_rate: f64,
}

/// Each robot's forward laser range finder.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, ToSchema)]
pub struct Laser {
    /// Rays per scan, spread evenly over the field of view, right to left.
    pub beams: u64,
    /// Field of view, degrees, centred on the heading.
    pub fov_deg: f64,
    /// Reach, metres: a beam that hits nothing reads this; the opponent detector sees as far.
    pub range: f64,
    /// Standard deviation of a range, metres.
    pub noise: f64,
}

/// The anonymous opponent detector (sightings along the laser's beams).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, ToSchema)]
pub struct Detection {
    /// Standard deviation of a sighting's range, metres.
    pub range_noise: f64,
    /// Standard deviation of a sighting's bearing, degrees.
    pub bearing_noise_deg: f64,
}

/// The tag device.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, ToSchema)]
pub struct Tag {
    /// A tag hits what is within this many degrees either side of the heading.
    pub half_angle_deg: f64,
    /// How far a tag reaches, metres (in line of sight).
    pub range: f64,
    /// Ticks after a shot before the device fires again.
    pub cooldown_ticks: u64,
}

/// Landmarks, recognised by identity all round.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, ToSchema)]
pub struct Landmarks {
    /// Metres, in line of sight.
    pub range: f64,
    /// Standard deviation of a sighting's range, metres.
    pub range_noise: f64,
    /// Standard deviation of a sighting's bearing, degrees.
    pub bearing_noise_deg: f64,
}

/// The bounded numbers of the requests (docs/api.md, "Bounds").
#[derive(Debug, Clone, Copy, PartialEq, Serialize, ToSchema)]
pub struct RequestBounds {
    /// `robots` of `POST /api/matches`.
    pub robots: BoundDto,
    /// `opponents` of `POST /api/matches`.
    pub opponents: BoundDto,
    /// `time_limit_s` of `POST /api/matches`.
    pub time_limit_s: BoundDto,
    /// `spectator_delay_s` of `POST /api/matches`.
    pub spectator_delay_s: BoundDto,
    /// `ticks` of `act` (the default) and `step` (required there).
    pub ticks: BoundDto,
}

/// One bounded number: `minimum..=maximum` (above `minimum` when `exclusive_minimum`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, ToSchema)]
pub struct BoundDto {
    /// Whether it must be a whole number.
    pub integer: bool,
    pub minimum: f64,
    /// Whether `minimum` itself is refused.
    pub exclusive_minimum: bool,
    pub maximum: f64,
    /// What a request that leaves it out gets.
    pub default: f64,
}

impl From<Bound> for BoundDto {
    fn from(b: Bound) -> BoundDto {
        BoundDto {
            integer: b.kind == Kind::Integer,
            minimum: b.range.min,
            exclusive_minimum: b.range.min_exclusive,
            maximum: b.range.max,
            default: b.default_value(),
        }
    }
}

impl Rules {
    /// The rules of a match with `physics`.
    pub fn of(physics: &Physics) -> Rules {
        Rules {
            tick_hz: TICK_HZ,
            agent_radius: exact(AGENT_RADIUS),
            robot: Motion {
                speed: exact(physics.robot_speed),
                turn_rate: exact(physics.robot_turn_rate),
            },
            opponent: Motion {
                speed: exact(physics.opponent_speed),
                turn_rate: exact(physics.opponent_turn_rate),
            },
            laser: Laser {
                beams: physics.laser_beams as u64,
                fov_deg: degrees(physics.laser_fov),
                range: exact(physics.laser_range),
                noise: exact(physics.laser_noise),
            },
            detection: Detection {
                range_noise: exact(physics.detection_range_noise),
                bearing_noise_deg: degrees(physics.detection_bearing_noise),
            },
            tag: Tag {
                half_angle_deg: degrees(physics.tag_half_angle),
                range: exact(physics.tag_range),
                cooldown_ticks: physics.tag_cooldown_ticks,
            },
            freeze_ticks: physics.freeze_ticks,
            landmarks: Landmarks {
                range: exact(physics.landmark_range),
                range_noise: exact(physics.landmark_range_noise),
                bearing_noise_deg: degrees(physics.landmark_bearing_noise),
            },
            bounds: RequestBounds {
                robots: bounds::ROBOTS.into(),
                opponents: bounds::OPPONENTS.into(),
                time_limit_s: bounds::TIME_LIMIT_S.into(),
                spectator_delay_s: bounds::SPECTATOR_DELAY_S.into(),
                ticks: bounds::ACT_TICKS.into(),
            },
        }
    }
}

impl Default for Rules {
    /// The rules every match plays by (the core's defaults).
    fn default() -> Rules {
        Rules::of(&Physics::default())
    }
}

/// The rules as the Python package ships them (`python/lasertag_env/rules.json`), for use
/// without a server.
pub fn python_copy() -> String {
    let json = serde_json::to_string_pretty(&Rules::default()).unwrap_or_default();
    format!("{json}\n")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::ws::Kinematics;

    #[test]
    fn the_rules_are_the_cores() {
        let r = Rules::default();
        assert_eq!((r.tick_hz, r.laser.beams), (20, 181));
        assert_eq!((r.laser.fov_deg, r.laser.range), (180.0, 8.0));
        assert_eq!((r.tag.half_angle_deg, r.tag.range), (5.0, 6.0));
        assert_eq!(r.tag.cooldown_ticks, 20);
        assert_eq!(r.agent_radius, 0.25);
        assert_eq!(r.bounds.robots.maximum, 8.0);
        assert_eq!(r.bounds.ticks.maximum, 100_000.0);
    }

    #[test]
    fn the_opponents_motion_is_the_welcomes() {
        let physics = Physics::default();
        let (rules, k) = (
            Rules::of(&physics),
            Kinematics::of(&physics, lasertag_core::sim::AgentId::Opponent(0)),
        );
        assert_eq!(
            (rules.opponent.speed, rules.opponent.turn_rate),
            (k.speed, k.turn_rate)
        );
        assert_eq!(rules.agent_radius, k.radius);
        assert_eq!(1.0 / rules.tick_hz as f64, k.dt);
    }

    /// The Python package ships the rules for use without a server (it asks a server for its
    /// own); when the copy differs from the declarations, this test writes the new one
    /// (commit it) and fails.
    #[test]
    fn the_python_packages_copy_is_the_declaration() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("python/lasertag_env/rules.json");
        let want = python_copy();
        if std::fs::read_to_string(&path).unwrap_or_default() != want {
            std::fs::write(&path, &want).expect("python/lasertag_env/rules.json is writable");
            panic!(
                "python/lasertag_env/rules.json was out of date and has been rewritten: commit it"
            );
        }
    }
}
