//! The agents of a match as the world holds them: robots (truth, estimate, sensors, the
//! command decided last tick) and opponents (truth and who controls them), and the orders
//! an API-driven opponent takes.

use super::*;

#[derive(Debug, Clone)]
pub struct Robot {
    pub pose: Pose,
    /// The robot's own belief about its pose: its localiser's point estimate, or its
    /// odometry when localisation is off. Everything the team decides starts from this.
    pub estimate: Pose,
    /// Standard deviation of the robot's position belief (m): its localiser's, or with
    /// localisation off the dead-reckoning uncertainty, which only grows.
    pub spread: f32,
    /// Dead-reckoned pose from the wheel odometry (starts at the true start pose).
    pub odometry: Pose,
    /// The uncertainty of `odometry` (used for `spread` when there is no localiser).
    pub dead_reckoning: DeadReckoning,
    /// Landmarks recognised this tick.
    pub landmarks: Vec<LandmarkSighting>,
    pub localiser: Option<Box<Localiser>>,
    pub frozen_until: u64,
    pub cooldown_until: u64,
    pub scan: Scan,
    pub command: RobotCommand,
    /// Its last order, when the robots are driven from outside.
    pub api: ApiDrive,
    /// This tick's shot, fired by a person's keys: the tick their screen showed (lag
    /// compensation, as for an opponent's person).
    pub aim_tick: Option<u64>,
    /// A person drives it now (a pursuer slot they took); a free pursuer slot is the team
    /// planner's, as a free bot slot of a match people may take over is its bot's.
    pub seated: bool,
}

/// A route given to an API-driven opponent.
#[derive(Debug, Clone, Default)]
pub struct ApiRoute {
    pub waypoints: VecDeque<Point2<f32>>,
    pub fire: bool,
}

/// A person's latest keys.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct HumanInput {
    pub forward: f32,
    pub turn: f32,
    pub tag: bool,
    /// The tick whose robots the person's screen showed when these keys were pressed: a
    /// shot is judged against the robots where they were then (at most
    /// [`MAX_REWIND_TICKS`](crate::world::MAX_REWIND_TICKS) back).
    pub seen_tick: Option<u64>,
}

#[derive(Debug, Clone)]
pub enum Control {
    Bot(Bot),
    Api(ApiRoute),
    Human(HumanInput),
}

impl Control {
    /// Which kind of controller this is.
    pub fn kind(&self) -> ControlKind {
        match self {
            Control::Bot(_) => ControlKind::Bot,
            Control::Api(_) => ControlKind::Api,
            Control::Human(_) => ControlKind::Human,
        }
    }
}

#[derive(Debug, Clone)]
pub struct Opponent {
    pub pose: Pose,
    pub tagged: bool,
    pub cooldown_until: u64,
    pub control: Control,
    /// The bot a person took this opponent over from, back when they leave.
    pub bench: Option<Bot>,
}

/// An external order for an API-driven opponent.
#[derive(Debug, Clone, PartialEq)]
pub enum OpponentOrder {
    Waypoints(Vec<Point2<f32>>),
    Stop,
    Tag,
}

/// Why an order or input was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OrderError {
    #[error("no opponent {0} in this match")]
    UnknownOpponent(String),
    #[error("opponent {0} is not API-controlled")]
    NotApiControlled(String),
    #[error("opponent {0} has been tagged")]
    Tagged(String),
    #[error("{field}: [{x}, {y}] lies outside the arena")]
    OutsideArena { field: String, x: f32, y: f32 },
}

crate::checkpoint::restore_struct!(Robot {
    plain: [
        pose,
        estimate,
        spread,
        odometry,
        dead_reckoning,
        landmarks,
        frozen_until,
        cooldown_until,
        scan,
        command,
        api,
        aim_tick,
        seated,
    ],
    nested: [localiser],
    derived: [],
});
crate::checkpoint::plain_struct!(ApiRoute { waypoints, fire });
crate::checkpoint::plain_struct!(HumanInput {
    forward,
    turn,
    tag,
    seen_tick
});
crate::checkpoint::plain_struct!(Opponent {
    pose,
    tagged,
    cooldown_until,
    control,
    bench,
});

impl Plain for Control {
    fn save(&self, w: &mut crate::checkpoint::Writer) {
        match self {
            Control::Bot(b) => {
                0u8.save(w);
                b.save(w);
            }
            Control::Api(a) => {
                1u8.save(w);
                a.save(w);
            }
            Control::Human(h) => {
                2u8.save(w);
                h.save(w);
            }
        }
    }
    fn load(r: &mut crate::checkpoint::Reader) -> Result<Self, CheckpointError> {
        match u8::load(r)? {
            0 => Ok(Control::Bot(Bot::load(r)?)),
            1 => Ok(Control::Api(ApiRoute::load(r)?)),
            2 => Ok(Control::Human(HumanInput::load(r)?)),
            _ => Err(CheckpointError::BadValue("an opponent's control")),
        }
    }
}
