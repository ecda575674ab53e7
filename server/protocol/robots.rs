//! The shapes of robots driven from outside (`"planner": "api"`): a command for one robot,
//! what one robot knows (its observation), and the environment step that applies every
//! robot's command, advances the match and answers every observation.
//!
//! An observation is built from `World::observation`, which has no access path to the
//! referee's truth; numbers are rounded as in the state (a millimetre, a ten-thousandth of a
//! radian) so that a client parses short JSON. An `act` may ask for its scans packed
//! (`"scans": "hex"`): the same millimetres as little-endian `u16`s in one hexadecimal
//! string per scan, which a client decodes in one call (writing and parsing 181 decimal
//! numbers a robot is most of the answer's cost on both sides).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::{EventDto, Invalid, PoseDto, Status, Winner, bounds, invalid, mm, rad};
use crate::game::{MatchError, Reading};
use crate::schema;
use lasertag_core::sim::{AgentId, Pose};
use lasertag_core::world::{RobotObservation, RobotOrder};

/// Body of `POST /api/matches/{id}/robots/{rid}/command`, and each entry of an `act`'s
/// `commands`: velocities (`forward`, `turn`, `tag`), or `waypoints`, or `stop`.
#[derive(Debug, Clone, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RobotCommand {
    /// Fraction of top speed, -1..=1 (0 when only `turn` is given); holds until the next
    /// command.
    pub forward: Option<f64>,
    /// Fraction of the top turn rate, -1..=1, counter-clockwise positive; holds.
    pub turn: Option<f64>,
    /// `true` fires the tag device once, on the next tick, if it is ready then.
    pub tag: Option<bool>,
    /// Drive through these points in order (around walls, by the built-in path follower,
    /// at most 16) and stop at the last.
    #[schema(schema_with = schema::waypoints)]
    pub waypoints: Option<Vec<[f64; 2]>>,
    /// `true` halts the robot.
    pub stop: Option<bool>,
}

impl RobotCommand {
    /// The core's order; `at` is the JSON path of this command (for errors).
    pub fn order(self, at: &str) -> Result<RobotOrder, Invalid> {
        let field = |f: &str| {
            if at.is_empty() {
                f.to_owned()
            } else {
                format!("{at}.{f}")
            }
        };
        let drive = self.forward.is_some() || self.turn.is_some() || self.tag.is_some();
        match (drive, self.waypoints, self.stop) {
            (true, None, None) => {
                let part = |name: &str, v: Option<f64>| match v {
                    Some(v) if v.is_finite() && (-1.0..=1.0).contains(&v) => Ok(v as f32),
                    Some(v) => Err(invalid(field(name), format!("{v} must be in -1..=1"))),
                    None => Ok(0.0),
                };
                Ok(RobotOrder::Drive {
                    forward: part("forward", self.forward)?,
                    turn: part("turn", self.turn)?,
                    tag: self.tag.unwrap_or(false),
                })
            }
            (false, Some(w), None) => {
                let max = lasertag_core::world::MAX_ROBOT_WAYPOINTS;
                if w.len() > max {
                    return Err(invalid(
                        field("waypoints"),
                        format!("{} points, at most {max}", w.len()),
                    ));
                }
                let mut points = Vec::with_capacity(w.len());
                for (i, p) in w.iter().enumerate() {
                    if !(p[0].is_finite() && p[1].is_finite())
                        || p[0].abs() > schema::MAX_COORDINATE
                        || p[1].abs() > schema::MAX_COORDINATE
                    {
                        return Err(invalid(
                            field(&format!("waypoints[{i}]")),
                            format!("[{}, {}] is not a finite point", p[0], p[1]),
                        ));
                    }
                    points.push(nalgebra::Point2::new(p[0] as f32, p[1] as f32));
                }
                Ok(RobotOrder::Waypoints(points))
            }
            (false, None, Some(true)) => Ok(RobotOrder::Stop),
            (false, None, Some(false)) => Err(invalid(field("stop"), "must be true")),
            _ => Err(invalid(
                if at.is_empty() { "body" } else { at }.to_owned(),
                "give velocities (forward, turn, tag), or waypoints, or stop",
            )),
        }
    }
}

/// A robot id of the API (`r0`, `r1`, …) as an index, or why it names no robot.
pub fn robot_index(rid: &str) -> Option<usize> {
    match rid.parse() {
        Ok(AgentId::Robot(i)) => Some(i),
        _ => None,
    }
}

/// Body of `POST /api/matches/{id}/act`.
#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ActRequest {
    /// A command per robot id (`r0`, …); robots left out keep their last one.
    #[serde(default)]
    pub commands: BTreeMap<String, RobotCommand>,
    /// [`bounds::ACT_TICKS`].
    #[serde(default = "default_ticks", deserialize_with = "schema::int")]
    #[schema(schema_with = bounds::act_ticks_schema)]
    pub ticks: i64,
    /// How the answer writes each observation's `scan`: `numbers` (metres, the default) or
    /// `hex` (see [`Scan::Hex`]).
    #[serde(default)]
    #[schema(inline)]
    pub scans: ScanEncoding,
}

/// How an `act` answer writes the observations' scans.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum ScanEncoding {
    /// Ranges in metres, as numbers (the observation's usual shape).
    #[default]
    Numbers,
    /// Each scan one string: see [`Scan::Hex`].
    Hex,
}

fn default_ticks() -> i64 {
    bounds::ACT_TICKS.default_value() as i64
}

impl ActRequest {
    /// Every command as (robot index, order), checked; the first bad one is the error.
    pub fn orders(self) -> Result<(Vec<(usize, RobotOrder)>, u64), Invalid> {
        let ticks = bounds::ACT_TICKS.integer(Some(self.ticks))?;
        let mut orders = Vec::with_capacity(self.commands.len());
        for (rid, command) in self.commands {
            let at = format!("commands.{rid}");
            let index = robot_index(&rid)
                .ok_or_else(|| invalid(at.clone(), "is not a robot id (r0, r1, …)"))?;
            orders.push((index, command.order(&at)?));
        }
        Ok((orders, ticks as u64))
    }
}

/// What one robot knows (never ground truth).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Observation {
    pub tick: u64,
    /// Laser ranges (m) across the field of view, right to left; empty while frozen. With
    /// `act`'s `"scans": "hex"`, one string (see [`Scan::Hex`]).
    #[schema(schema_with = scan_schema)]
    pub scan: Scan,
    /// Anonymous sightings of opponents, relative to the robot.
    pub detections: Vec<super::DetectionDto>,
    /// Landmarks recognised this tick (their ids are indices into the map's `landmarks`).
    pub landmarks: Vec<LandmarkDto>,
    /// Dead-reckoned pose from the wheel odometry.
    pub odometry: PoseDto,
    /// The robot's own estimate of its pose (its localiser's, or its odometry).
    pub estimate: PoseDto,
    /// Standard deviation of that estimate's position (m).
    pub spread: f64,
    pub frozen: bool,
    /// The tag device would fire on the next tick.
    pub tag_ready: bool,
    /// What the radio delivered of each teammate.
    pub teammates: Vec<TeammateDto>,
    /// The team belief as this robot holds it (never the truth).
    pub belief: BeliefFeaturesDto,
}

/// The team belief as one robot holds it, seen from its own estimate: the research
/// environment's belief features (docs/research.md has the layout table). Values are rounded
/// to a ten-thousandth.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct BeliefFeaturesDto {
    /// The expected share of the untagged opponents in each cell of a coarse egocentric
    /// grid: 8 bearing sectors of 45° counter-clockwise from straight ahead, nearer than
    /// 4 m, then the same 8 farther out. Sums to 1 while any opponent is believed untagged.
    pub grid: Vec<f64>,
    /// The same mass by the way to walk to it: of the belief within 6 m of travel, the
    /// expected share of the untagged opponents in each of the 8 sectors (as the grid's) of
    /// the point 1 m along the shortest path to it. Sums to at most 1.
    pub paths: Vec<f64>,
    /// The 2 untagged roles whose means are nearest, nearest first, each `[present, count /
    /// opponents, ahead / 10 m, left / 10 m, spread / 5 m, confidence, ticks looked at in
    /// vain / 100]` (all 0 for an empty slot).
    pub roles: Vec<Vec<f64>>,
    /// The share of the opponents this robot believes are still untagged.
    pub untagged: f64,
}

/// A scan on the wire.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Scan {
    /// Ranges in metres, rounded to the millimetre.
    Metres(Vec<f64>),
    /// The same ranges in millimetres as little-endian unsigned 16-bit integers (saturating
    /// at 65.535 m), their bytes in hexadecimal, 4 digits a beam (`"3412 mm"` is `"540d"`):
    /// in Python, `numpy.frombuffer(bytes.fromhex(s), "<u2") / 1000.0` gives the numbers'
    /// values, bit for bit.
    Hex(String),
}

impl Scan {
    /// The packed form of the same ranges.
    pub fn pack(&self) -> Scan {
        const DIGITS: &[u8; 16] = b"0123456789abcdef";
        match self {
            Scan::Metres(ranges) => {
                let mut text = Vec::with_capacity(4 * ranges.len());
                for r in ranges {
                    // `r` is a whole number of millimetres already (see `mm`).
                    let [lo, hi] = ((r * 1000.0).round().clamp(0.0, u16::MAX as f64) as u16)
                        .to_le_bytes()
                        .map(usize::from);
                    text.extend_from_slice(&[
                        DIGITS[lo >> 4],
                        DIGITS[lo & 15],
                        DIGITS[hi >> 4],
                        DIGITS[hi & 15],
                    ]);
                }
                // Hex digits are ASCII.
                Scan::Hex(String::from_utf8(text).unwrap_or_default())
            }
            packed => packed.clone(),
        }
    }
}

fn scan_schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
    use utoipa::openapi::schema::{ArrayBuilder, ObjectBuilder, OneOfBuilder, Type};
    OneOfBuilder::new()
        .item(ArrayBuilder::new().items(ObjectBuilder::new().schema_type(Type::Number)))
        .item(
            ObjectBuilder::new()
                .schema_type(Type::String)
                .pattern(Some("^([0-9a-f]{4})*$"))
                .description(Some(
                    "With `\"scans\": \"hex\"`: millimetres as little-endian u16, in hex.",
                )),
        )
        .description(Some("Laser ranges (m), right to left; empty while frozen."))
        .into()
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct LandmarkDto {
    pub id: usize,
    pub range: f64,
    pub bearing: f64,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct TeammateDto {
    pub id: String,
    pub x: f64,
    pub y: f64,
    pub theta: f64,
    /// Ticks since the teammate sent this (0 with a perfect radio).
    pub age_ticks: u64,
    /// Where the teammate announced it is going, `[x, y]`, or null (robots driven by
    /// actions announce no goal).
    pub goal: Option<[f64; 2]>,
}

fn pose(p: Pose) -> PoseDto {
    PoseDto {
        x: mm(p.pos.x),
        y: mm(p.pos.y),
        theta: rad(p.theta),
    }
}

/// The observation's wire shape.
pub fn observation(o: &RobotObservation) -> Observation {
    Observation {
        tick: o.tick,
        scan: Scan::Metres(o.scan.iter().map(|r| mm(*r)).collect()),
        detections: o
            .detections
            .iter()
            .map(|d| super::DetectionDto {
                range: mm(d.range),
                bearing: rad(d.bearing),
            })
            .collect(),
        landmarks: o
            .landmarks
            .iter()
            .map(|l| LandmarkDto {
                id: l.id,
                range: mm(l.range),
                bearing: rad(l.bearing),
            })
            .collect(),
        odometry: pose(o.odometry),
        estimate: pose(o.estimate),
        spread: mm(o.spread),
        frozen: o.frozen,
        tag_ready: o.tag_ready,
        teammates: o
            .teammates
            .iter()
            .map(|t| TeammateDto {
                id: AgentId::Robot(t.robot).to_string(),
                x: mm(t.pose.pos.x),
                y: mm(t.pose.pos.y),
                theta: rad(t.pose.theta),
                age_ticks: t.age_ticks,
                goal: t.goal.map(|g| [mm(g.x), mm(g.y)]),
            })
            .collect(),
        belief: BeliefFeaturesDto {
            grid: o.belief.grid.to_vec(),
            paths: o.belief.paths.to_vec(),
            roles: o.belief.roles.iter().map(|r| r.to_vec()).collect(),
            untagged: o.belief.untagged,
        },
    }
}

/// The answer to `POST /api/matches/{id}/act`.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ActResponse {
    pub tick: u64,
    pub status: Status,
    pub winner: Option<Winner>,
    /// Every robot's observation after the last tick, by robot id.
    pub observations: BTreeMap<String, Observation>,
    /// What happened during these ticks.
    pub events: Vec<EventDto>,
}

/// The answer to an environment step, read live once its last tick has run.
pub fn read_act(r: &mut Reading<'_>) -> Result<ActResponse, MatchError> {
    let Some(w) = r.live() else {
        return Err(MatchError::Gone(r.meta().id.clone()));
    };
    Ok(ActResponse {
        tick: w.tick,
        status: super::status(w.status),
        winner: super::winner(w.winner),
        observations: (0..w.robots.len())
            .filter_map(|i| {
                let o = w.observation(i)?;
                Some((AgentId::Robot(i).to_string(), observation(&o)))
            })
            .collect(),
        events: r.stepped_events().iter().map(super::event).collect(),
    })
}

/// What robot `robot` knows now.
pub fn read_observation(
    robot: usize,
) -> impl FnOnce(&mut Reading<'_>) -> Result<Observation, MatchError> + Send + 'static {
    move |r| Ok(observation(&r.observation(robot)?))
}

impl ActResponse {
    /// Writes every observation's scan as `encoding` asks.
    pub fn encode_scans(&mut self, encoding: ScanEncoding) {
        if encoding == ScanEncoding::Hex {
            for o in self.observations.values_mut() {
                o.scan = o.scan.pack();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn command(json: &str) -> Result<RobotOrder, Invalid> {
        super::super::parse::<RobotCommand>(json.as_bytes())?.order("")
    }

    #[test]
    fn a_command_is_velocities_or_waypoints_or_stop() {
        assert_eq!(
            command(r#"{"forward": 0.5, "tag": true}"#),
            Ok(RobotOrder::Drive {
                forward: 0.5,
                turn: 0.0,
                tag: true
            })
        );
        assert_eq!(command(r#"{"stop": true}"#), Ok(RobotOrder::Stop));
        assert!(matches!(
            command(r#"{"waypoints": [[1, 2]]}"#),
            Ok(RobotOrder::Waypoints(p)) if p.len() == 1
        ));
        let e = command(r#"{"forward": 1.5}"#).unwrap_err();
        assert_eq!(
            (e.field.as_str(), e.message.as_str()),
            ("forward", "1.5 must be in -1..=1")
        );
        let e = command(r#"{"forward": 1, "stop": true}"#).unwrap_err();
        assert_eq!(e.field, "body");
        let e = command(r#"{"speed": 1}"#).unwrap_err();
        assert!(e.message.contains("unknown field `speed`"), "{e:?}");
    }

    #[test]
    fn a_packed_scan_is_the_same_millimetres_in_hex() {
        // 3.412 m is 3412 mm = 0x0d54; 0.001 m is 1 mm; past 65.535 m saturates.
        let packed = Scan::Metres(vec![3.412, 0.001, 70.0, 0.0]).pack();
        assert_eq!(packed, Scan::Hex("540d0100ffff0000".to_owned()));
        assert_eq!(Scan::Metres(vec![]).pack(), Scan::Hex(String::new()));
        let act: ActRequest = super::super::parse(br#"{"scans": "hex"}"#).unwrap();
        assert_eq!(act.scans, ScanEncoding::Hex);
        let bad = super::super::parse::<ActRequest>(br#"{"scans": "base64"}"#).unwrap_err();
        assert_eq!(bad.field, "scans");
    }

    #[test]
    fn an_act_names_the_robot_whose_command_is_wrong() {
        let act: ActRequest = super::super::parse(
            br#"{"commands": {"r0": {"turn": 1}, "r1": {"forward": -3}}, "ticks": 2}"#,
        )
        .unwrap();
        let e = act.orders().unwrap_err();
        assert_eq!(e.field, "commands.r1.forward");
        let act: ActRequest =
            super::super::parse(br#"{"commands": {"o0": {"stop": true}}}"#).unwrap();
        assert_eq!(act.orders().unwrap_err().field, "commands.o0");
        let act: ActRequest = super::super::parse(br#"{}"#).unwrap();
        assert_eq!(act.orders().map(|(o, t)| (o.len(), t)), Ok((0, 1)));
    }
}
