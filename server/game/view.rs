//! What a match shows of itself, in the game's own terms: one shared [`Frame`] of ground
//! truth after every tick, the [`Summary`] listings read, its [`MatchMeta`] and [`Stats`]. `protocol` turns these into the wire's
//! shapes; nothing here knows JSON.
//!
//! The task builds a frame once per tick (O(agents + particles shown), never O(clients)) and
//! publishes it on a `watch` channel: the latest frame wins, so a slow viewer skips stale
//! frames instead of slowing the tick. Each WebSocket connection filters a frame for its
//! viewer (a player sees what its opponent has in line of sight) and serialises it; what
//! every spectator gets is serialised once per frame and shared through [`Frame::encoded`].
//!
//! The belief is thinned for display here: each role's cloud is resampled (systematic
//! resampling, no randomness) down to a few hundred points in all, quantised to centimetres,
//! and rebuilt only every [`BELIEF_EVERY`] ticks.
//!
//! Every frame also measures the team's belief against the truth ([`TrackingFrame`], GOSPA). It
//! is computed here, where the truth is shown anyway, and never in the core's tick: it reads
//! the world and changes nothing in the match.
//!
//! Long file: a frame and who may see what of it (a player's line of sight, and the events
//! that follow the same rule, [`event_seen`]) belong in one place, so that one rule holds.

use std::any::Any;
use std::sync::{Arc, OnceLock};

use nalgebra::Point2;

use lasertag_core::localise::Localiser;
use lasertag_core::planner::PlannerKind;
use lasertag_core::sim::arena::Arena;
use lasertag_core::sim::sensors::Detection;
use lasertag_core::sim::{AGENT_RADIUS, AgentId, Pose};
use lasertag_core::tracker::estimate::tracking_quality;
use lasertag_core::tracker::gospa::{Gospa, Params};
use lasertag_core::tracker::{Confidence, Role};
use lasertag_core::world::{ControlKind, Event, EventKind, MatchConfig};
use lasertag_core::world::{MatchStatus, Side, World};

/// Ticks between two belief updates sent to viewers (5 Hz at 20 Hz ticks).
pub const BELIEF_EVERY: u64 = 4;
/// Ticks between two beliefs a match people play keeps to show late (2 s at 20 Hz; see
/// `game::delay`): its delayed `/belief` moves in steps of this size.
pub const BELIEF_HOLD_EVERY: u64 = 40;
/// Points of the belief shown in all, shared among the untagged roles.
pub const BELIEF_BUDGET: usize = 480;
/// No role is shown with fewer points than this (unless it has fewer particles).
pub const BELIEF_MIN_PER_ROLE: usize = 48;

#[derive(Debug, Clone)]
pub struct RobotFrame {
    pub pose: Pose,
    pub frozen: bool,
    pub goal: Option<Pose>,
    /// This tick's laser ranges (metres), empty while frozen.
    pub scan: Vec<f32>,
    /// This tick's anonymous sightings.
    pub detections: Vec<Detection>,
    /// The opponents behind them (the referee's truth, which the robots never read): what
    /// a person driving this robot is shown.
    pub seen: Vec<usize>,
    /// The robot's own belief about its pose, and that belief's spread (m).
    pub estimate: Pose,
    pub spread: f32,
    /// A thinned sample of its localisation particles, in centimetres (empty when it does
    /// not localise).
    pub cloud: Vec<[i32; 2]>,
    /// The person driving it, when it is a pursuer seat somebody holds.
    pub player: Option<Arc<str>>,
    /// Whether that person is connected right now.
    pub connected: bool,
    /// The `seq` of that person's last numbered input applied.
    pub ack: u64,
}

/// Localisation particles shown per robot. Every spectator snapshot carries them, so they
/// count against the 8 KB a snapshot with the belief may take: 40 per robot took the
/// largest of those to 8.2 KB in the load test (`examples/loadtest/`), and a converged
/// cloud is a few centimetres across, where 24 dots show it as well.
pub const CLOUD_POINTS: usize = 24;

/// Every k-th particle, so that about [`CLOUD_POINTS`] are shown (deterministic: resampled
/// particles carry equal weight, so a stride is a fair sample).
fn thin_cloud(localiser: &Localiser) -> Vec<[i32; 2]> {
    let particles = localiser.particles();
    let stride = particles.len().div_ceil(CLOUD_POINTS).max(1);
    particles
        .iter()
        .step_by(stride)
        // Particles move only at measurement updates; drawn where they would be now.
        .map(|p| localiser.carried(*p))
        .map(|p| {
            [
                (p.pos.x * 100.0).round() as i32,
                (p.pos.y * 100.0).round() as i32,
            ]
        })
        .collect()
}

#[derive(Debug, Clone)]
pub struct OpponentFrame {
    pub pose: Pose,
    pub tagged: bool,
    pub control: ControlKind,
    /// The person playing it, if any.
    pub player: Option<Arc<str>>,
    /// Whether that person is connected right now.
    pub connected: bool,
    /// The `seq` of that person's last numbered input applied.
    pub ack: u64,
}

/// A person at an opponent slot or a robot's seat, as frames show it.
#[derive(Debug, Clone)]
pub struct SeatView {
    pub name: Arc<str>,
    pub connected: bool,
    /// The `seq` of the last numbered input applied.
    pub ack: u64,
}

/// Who sits where: one entry per opponent slot and per robot (`None`: nobody, or no seat).
#[derive(Debug, Clone, Default)]
pub struct SeatViews {
    pub opponents: Vec<Option<SeatView>>,
    pub robots: Vec<Option<SeatView>>,
}

impl SeatViews {
    fn of(seats: &[Option<SeatView>], i: usize) -> (Option<Arc<str>>, bool, u64) {
        match seats.get(i) {
            Some(Some(s)) => (Some(s.name.clone()), s.connected, s.ack),
            _ => (None, false, 0),
        }
    }
}

/// One role of the belief, thinned for display.
#[derive(Debug, Clone, PartialEq)]
pub struct RoleView {
    pub id: u64,
    pub count: u32,
    pub tagged: bool,
    /// The team's trust in the cloud and what it makes of it (see `tracker::Confidence`).
    pub confidence: f32,
    pub state: Confidence,
    /// Particles the tracker holds for this role.
    pub particles: usize,
    /// Weighted mean of the cloud (metres).
    pub mean: [f32; 2],
    /// Points shown, in centimetres.
    pub points: Vec<[i32; 2]>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct BeliefView {
    pub tick: u64,
    pub roles: Vec<RoleView>,
}

/// How close the team's (merged) belief is to the truth at one tick: GOSPA between its
/// untagged roles' point estimates and the opponents still in the arena, with the cut-off
/// and order it was computed with (see `tracker::gospa` and docs/tracker.md).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackingFrame {
    pub gospa: Gospa,
    pub params: Params,
}

impl TrackingFrame {
    /// The measurement for `roles` (the team's merged belief) in `world`.
    pub fn of(world: &World, roles: &[Role]) -> TrackingFrame {
        let params = Params::default();
        TrackingFrame {
            gospa: tracking_quality(roles, &world.untagged_opponents(), params),
            params,
        }
    }
}

/// Everything about one tick that any viewer may be shown.
#[derive(Debug)]
pub struct Frame {
    pub tick: u64,
    pub time_s: f64,
    pub time_limit_s: f64,
    pub status: MatchStatus,
    pub winner: Option<Side>,
    pub robots: Vec<RobotFrame>,
    pub opponents: Vec<OpponentFrame>,
    /// Present on belief ticks (every [`BELIEF_EVERY`] ticks and on the last one).
    pub belief: Option<Arc<BeliefView>>,
    /// On belief ticks, with an imperfect radio (each robot its own tracker): the belief of
    /// each robot a person drives, by robot (`None` for the others). What that person is
    /// shown: their robot's knowledge, with what the radio has delivered of the team's, not
    /// the team's pooled one.
    pub robot_beliefs: Vec<Option<Arc<BeliefView>>>,
    /// The belief measured against the truth, every tick.
    pub tracking: TrackingFrame,
    /// Events logged since the previous frame, oldest first.
    pub events: Vec<Event>,
    /// The `seq` of the last event before this frame's (0 for none).
    pub since_seq: u64,
    /// The `seq` of the newest event so far.
    pub last_seq: u64,
    /// Tags of robots by opponents so far (the opponents' score), counted from the
    /// events of every frame so far.
    pub robot_tags: u32,
    /// The `finished` event, once the match has ended.
    pub finished: Option<Event>,
    /// Serialised forms shared by every spectator of this frame.
    pub encoded: Encoded,
}

/// The encodings of one frame that its viewers share, made by the first viewer that needs
/// them: the sockets keep their own cache type here (`protocol::ws::WireCache`), which the
/// game does not know.
#[derive(Debug, Default)]
pub struct Encoded(OnceLock<Box<dyn Any + Send + Sync>>);

impl Encoded {
    /// The cache of type `T`, made on first use; `None` if another type got here first.
    pub fn get<T: Any + Send + Sync + Default>(&self) -> Option<&T> {
        self.0.get_or_init(|| Box::new(T::default())).downcast_ref()
    }
}

impl Frame {
    /// The frame of a world that has not changed since `since_seq`.
    pub fn build(
        world: &World,
        seats: &SeatViews,
        since_seq: u64,
        robot_tags: u32,
        with_belief: bool,
    ) -> Frame {
        let new_events = world.events_since(since_seq);
        let robot_tags = robot_tags
            + new_events
                .iter()
                .filter(|e| matches!(e.kind, EventKind::RobotTagged { .. }))
                .count() as u32;
        let events: Vec<Event> = new_events.to_vec();
        let last_seq = events.last().map_or(since_seq, |e| e.seq);
        let roles = world.team.merged_belief();
        Frame {
            tick: world.tick,
            time_s: world.time_s(),
            time_limit_s: world.config.time_limit_ticks as f64 / lasertag_core::sim::TICK_HZ as f64,
            status: world.status,
            winner: world.winner,
            robots: world
                .robots
                .iter()
                .enumerate()
                .map(|(i, r)| {
                    let (player, connected, ack) = SeatViews::of(&seats.robots, i);
                    RobotFrame {
                        pose: r.pose,
                        frozen: world.robot_frozen(i),
                        goal: r.command.goal,
                        scan: r.scan.ranges.clone(),
                        detections: r.scan.detections.clone(),
                        seen: r.scan.seen.clone(),
                        estimate: r.estimate,
                        spread: r.spread,
                        cloud: r
                            .localiser
                            .as_ref()
                            .map_or_else(Vec::new, |l| thin_cloud(l)),
                        player,
                        connected,
                        ack,
                    }
                })
                .collect(),
            opponents: world
                .opponents
                .iter()
                .enumerate()
                .map(|(i, o)| {
                    let (player, connected, ack) = SeatViews::of(&seats.opponents, i);
                    OpponentFrame {
                        pose: o.pose,
                        tagged: o.tagged,
                        control: o.control.kind(),
                        player,
                        connected,
                        ack,
                    }
                })
                .collect(),
            belief: with_belief.then(|| Arc::new(belief_view_of(world.tick, &roles))),
            robot_beliefs: if with_belief && world.team.per_robot() {
                (0..world.robots.len())
                    .map(|r| {
                        let seated = seats.robots.get(r).is_some_and(Option::is_some);
                        let own = world.team.belief_of(r, world.robots.len());
                        own.filter(|_| seated)
                            .map(|t| Arc::new(belief_view_of(world.tick, &t.roles)))
                    })
                    .collect()
            } else {
                Vec::new()
            },
            tracking: TrackingFrame::of(world, &roles),
            events,
            since_seq,
            last_seq,
            robot_tags,
            finished: (world.status == MatchStatus::Finished)
                .then(|| {
                    world
                        .events()
                        .iter()
                        .rev()
                        .find(|e| matches!(e.kind, EventKind::Finished { .. }))
                        .cloned()
                })
                .flatten(),
            encoded: Encoded::default(),
        }
    }
}

impl Frame {
    /// The belief this frame shows `you` in place of the team's pooled one: a person's own
    /// robot's, when each robot keeps its own.
    pub fn own_belief(&self, you: AgentId) -> Option<&BeliefView> {
        match you {
            AgentId::Robot(r) => self.robot_beliefs.get(r)?.as_deref(),
            AgentId::Opponent(_) => None,
        }
    }

    /// Bytes it keeps (what a match holding frames back is priced by), its serialised
    /// forms aside: they are made only once a frame is shown.
    pub fn bytes(&self) -> usize {
        let robots: usize = self
            .robots
            .iter()
            .map(|r| {
                std::mem::size_of::<RobotFrame>()
                    + r.scan.capacity() * 4
                    + r.detections.capacity() * std::mem::size_of::<Detection>()
                    + r.cloud.capacity() * 8
            })
            .sum();
        let view = |b: &BeliefView| {
            b.roles
                .iter()
                .map(|r| std::mem::size_of::<RoleView>() + r.points.capacity() * 8)
                .sum::<usize>()
        };
        let belief = self.belief.as_deref().map_or(0, view)
            + self
                .robot_beliefs
                .iter()
                .flatten()
                .map(|b| view(b))
                .sum::<usize>();
        std::mem::size_of::<Frame>()
            + robots
            + self.opponents.capacity() * std::mem::size_of::<OpponentFrame>()
            + belief
            + self.events.capacity() * std::mem::size_of::<Event>()
    }
}

/// Which agents the person playing `you` can see, computed from ground truth on the server,
/// and how well.
///
/// An opponent sees along its own line of sight: walls occlude, and so do the other agents'
/// bodies (discs of [`AGENT_RADIUS`], as the robots' laser meets them): another agent is in
/// sight when the line to its centre clears the walls and one of three lines to it (its
/// centre, and either side of it) clears every body in between. A tagged opponent has left
/// the arena: it watches on through its teammates' eyes (what any opponent still in the
/// arena sees, and where it was tagged), as a dead player spectates teammates in
/// Counter-Strike: live, and never more than its side could see ([`Visible::teammates`]).
///
/// A person on the robot team sees every robot (their own team) and the opponents their
/// robot's laser saw this tick, exactly as the core cast it (walls and bodies stop beams;
/// nothing while it is frozen, its laser off). The team's detector is anonymous: it tells
/// where something is, not who or which way it faces, so neither is sent
/// ([`Visible::anonymous`]); the team's belief tells them the rest.
pub fn visible_to(frame: &Frame, arena: &Arena, you: AgentId) -> Option<Visible> {
    match you {
        AgentId::Opponent(slot) => {
            let me = frame.opponents.get(slot)?;
            if !me.tagged {
                return Some(opponent_sight(frame, arena, slot));
            }
            let mut union = Visible {
                robots: vec![false; frame.robots.len()],
                opponents: vec![false; frame.opponents.len()],
                anonymous: false,
                teammates: true,
            };
            union.opponents[slot] = true;
            let alive =
                (frame.opponents.iter().enumerate()).filter(|(i, o)| *i != slot && !o.tagged);
            for (mate, _) in alive {
                let sight = opponent_sight(frame, arena, mate);
                for (u, s) in union.robots.iter_mut().zip(&sight.robots) {
                    *u |= s;
                }
                for (u, s) in union.opponents.iter_mut().zip(&sight.opponents) {
                    *u |= s;
                }
            }
            Some(union)
        }
        AgentId::Robot(r) => {
            let me = frame.robots.get(r)?;
            Some(Visible {
                robots: vec![true; frame.robots.len()],
                opponents: (frame.opponents.iter().enumerate())
                    .map(|(i, o)| !me.frozen && !o.tagged && me.seen.contains(&i))
                    .collect(),
                anonymous: true,
                teammates: false,
            })
        }
    }
}

/// What the untagged opponent in `slot` sees (see [`visible_to`]).
fn opponent_sight(frame: &Frame, arena: &Arena, slot: usize) -> Visible {
    let eye = frame.opponents[slot].pose.pos;
    // Every body in the arena but the viewer's: the robots (frozen ones too) and the
    // untagged opponents.
    let bodies: Vec<(AgentId, Point2<f32>)> = (frame.robots.iter().enumerate())
        .map(|(i, r)| (AgentId::Robot(i), r.pose.pos))
        .chain(
            (frame.opponents.iter().enumerate())
                .filter(|(i, o)| *i != slot && !o.tagged)
                .map(|(i, o)| (AgentId::Opponent(i), o.pose.pos)),
        )
        .collect();
    let sees = |who: AgentId, p: Point2<f32>| {
        arena.line_of_sight(eye, p)
            && in_sight_past_bodies(eye, p, bodies.iter().filter(|b| b.0 != who))
    };
    Visible {
        robots: (frame.robots.iter().enumerate())
            .map(|(i, r)| sees(AgentId::Robot(i), r.pose.pos))
            .collect(),
        opponents: (frame.opponents.iter().enumerate())
            .map(|(i, o)| i == slot || (!o.tagged && sees(AgentId::Opponent(i), o.pose.pos)))
            .collect(),
        anonymous: false,
        teammates: false,
    }
}

/// Whether a body at `target` shows from `eye` past `bodies` (centres of discs of
/// [`AGENT_RADIUS`]): one of the lines to its centre and to either side of it (at 0.8 of
/// its radius) passes no body before it.
fn in_sight_past_bodies<'a>(
    eye: Point2<f32>,
    target: Point2<f32>,
    bodies: impl Iterator<Item = &'a (AgentId, Point2<f32>)> + Clone,
) -> bool {
    let to = target - eye;
    let len = to.norm();
    if len < 1e-6 {
        return true;
    }
    let side = nalgebra::Vector2::new(-to.y, to.x) * (0.8 * AGENT_RADIUS / len);
    [target, target + side, target - side]
        .into_iter()
        .any(|aim| {
            bodies
                .clone()
                .all(|(_, c)| !blocks(eye, aim, *c, len - AGENT_RADIUS))
        })
}

/// Whether a disc of [`AGENT_RADIUS`] at `centre` crosses the line from `eye` towards `aim`
/// within `reach` of `eye`.
fn blocks(eye: Point2<f32>, aim: Point2<f32>, centre: Point2<f32>, reach: f32) -> bool {
    let d = aim - eye;
    let len = d.norm();
    if len < 1e-6 {
        return false;
    }
    let d = d / len;
    let v = centre - eye;
    let along = v.dot(&d);
    let across2 = v.norm_squared() - along * along;
    let r2 = AGENT_RADIUS * AGENT_RADIUS;
    if across2 > r2 {
        return false;
    }
    // The line enters the disc at `along - half`: in front of the eye and before the target.
    let enters = along - (r2 - across2).sqrt();
    enters < reach && along + (r2 - across2).sqrt() > 0.0
}

/// The result of [`visible_to`], one flag per agent.
#[derive(Debug, Clone, PartialEq)]
pub struct Visible {
    pub robots: Vec<bool>,
    pub opponents: Vec<bool>,
    /// The opponents in sight are anonymous sightings (a person on the robot team): shown
    /// without who they are or their heading, and in an order that says nothing of it.
    pub anonymous: bool,
    /// The viewer has been tagged and sees through its surviving teammates' eyes.
    pub teammates: bool,
}

impl Visible {
    fn sees(&self, agent: AgentId) -> bool {
        let flags = match agent {
            AgentId::Robot(_) => &self.robots,
            AgentId::Opponent(_) => &self.opponents,
        };
        flags.get(agent.index()).copied().unwrap_or(false)
    }
}

/// Whether the person playing `you` is told of `event` as it happens, `visible` being
/// [`visible_to`] of the frame the event comes with (the rule its snapshots follow).
///
/// An opponent: it took part (its own shot or tag, or it was hit), or every agent the event
/// names is in its view (an opponent a robot's shot tags has just left the arena: the shot
/// counts, as seen when its shooter is). The robots' belief splitting or merging is not
/// something it saw.
///
/// A person on the robot team: whatever the team knows as it happens (its robots' shots and
/// tags, a robot of it hit or frozen, its belief splitting or merging); an opponent's shot
/// that hit no robot only when that opponent is in their robot's view.
///
/// A mark goes live to the marker's side only.
///
/// Seats and the end are public and go live. Everything else reaches the player as late as
/// spectators get it.
pub fn event_seen(event: &Event, visible: &Visible, you: AgentId) -> bool {
    let seen =
        |agents: &[AgentId]| agents.contains(&you) || agents.iter().all(|a| visible.sees(*a));
    let robot = |a: &AgentId| matches!(a, AgentId::Robot(_));
    match (&event.kind, you) {
        (
            EventKind::PlayerJoined { .. }
            | EventKind::PlayerLeft { .. }
            | EventKind::Finished { .. },
            _,
        ) => true,
        (EventKind::RoleSplit { .. } | EventKind::RoleMerge { .. }, AgentId::Robot(_)) => true,
        (EventKind::RoleSplit { .. } | EventKind::RoleMerge { .. }, AgentId::Opponent(_)) => false,
        (EventKind::Shot { by, hit }, AgentId::Robot(_)) => {
            robot(by) || hit.as_ref().is_some_and(robot) || seen(&[*by])
        }
        (EventKind::Tag { .. } | EventKind::RobotTagged { .. }, AgentId::Robot(_)) => true,
        (EventKind::Shot { by, hit: None }, AgentId::Opponent(_)) => seen(&[*by]),
        (EventKind::Shot { by, hit: Some(hit) }, AgentId::Opponent(_)) => match (by, hit) {
            (AgentId::Robot(_), AgentId::Opponent(_)) if *hit != you => seen(&[*by]),
            _ => seen(&[*by, *hit]),
        },
        (EventKind::Tag { by, target }, AgentId::Opponent(_)) => *target == you || seen(&[*by]),
        (EventKind::RobotTagged { by, target }, AgentId::Opponent(_)) => seen(&[*by, *target]),
        // A mark is for the marker's side alone: the other side never learns of it live.
        (EventKind::Mark { by, .. }, _) => robot(by) == robot(&you),
    }
}

/// The team's (merged) belief, thinned for display (see the module docs).
pub fn belief_view(world: &World) -> BeliefView {
    belief_view_of(world.tick, &world.team.merged_belief())
}

/// The thinned view of `roles`, the team's merged belief at `tick`.
fn belief_view_of(tick: u64, roles: &[Role]) -> BeliefView {
    let live = roles.iter().filter(|r| !r.tagged).count().max(1);
    let per_role = (BELIEF_BUDGET / live).max(BELIEF_MIN_PER_ROLE);
    BeliefView {
        tick,
        roles: roles
            .iter()
            .map(|r| {
                let k = if r.tagged { 1 } else { per_role };
                RoleView {
                    id: r.id,
                    count: r.count,
                    tagged: r.tagged,
                    confidence: r.confidence,
                    state: r.confidence_state(),
                    particles: r.particles().len(),
                    mean: weighted_mean(r.particles(), r.weights()),
                    points: thin(r.particles(), r.weights(), k),
                }
            })
            .collect(),
    }
}

fn weighted_mean(points: &[Point2<f32>], weights: &[f32]) -> [f32; 2] {
    let (mut x, mut y, mut w) = (0.0f64, 0.0f64, 0.0f64);
    for (p, wi) in points.iter().zip(weights) {
        let wi = *wi as f64;
        x += p.x as f64 * wi;
        y += p.y as f64 * wi;
        w += wi;
    }
    if w > 0.0 && w.is_finite() {
        [(x / w) as f32, (y / w) as f32]
    } else if let Some(p) = points.first() {
        [p.x, p.y]
    } else {
        [0.0, 0.0]
    }
}

/// At most `k` points that represent the weighted cloud: systematic resampling with a fixed
/// offset (deterministic), duplicates dropped, quantised to centimetres.
pub fn thin(points: &[Point2<f32>], weights: &[f32], k: usize) -> Vec<[i32; 2]> {
    let cm = |p: &Point2<f32>| [(p.x * 100.0).round() as i32, (p.y * 100.0).round() as i32];
    if points.len() <= k {
        return points.iter().map(cm).collect();
    }
    let total: f64 = weights.iter().map(|w| *w as f64).sum();
    if !(total > 0.0 && total.is_finite()) || weights.len() != points.len() {
        // Weights unusable: an even stride over the particles.
        let step = points.len() as f64 / k as f64;
        return (0..k)
            .map(|j| cm(&points[((j as f64 + 0.5) * step) as usize % points.len()]))
            .collect();
    }
    let mut out: Vec<[i32; 2]> = Vec::with_capacity(k);
    let mut last: Option<usize> = None;
    let mut cum = weights[0] as f64 / total;
    let mut i = 0;
    for j in 0..k {
        let u = (j as f64 + 0.5) / k as f64;
        while cum < u && i + 1 < points.len() {
            i += 1;
            cum += weights[i] as f64 / total;
        }
        if last != Some(i) {
            out.push(cm(&points[i]));
            last = Some(i);
        }
    }
    out
}

/// Whether a reader may see a match's truth as it is now, or only as long ago as the match
/// holds it back (see [`delay`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sight {
    /// The owner, the operator, or the server itself.
    Live,
    /// Everybody else.
    Public,
}

/// How a match's clock runs: 20 Hz of real time, or a tick only when asked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Clock {
    Realtime,
    Manual,
}

impl Clock {
    /// As the history stores it.
    pub fn stored(self) -> crate::store::codec::StoredClock {
        match self {
            Clock::Realtime => crate::store::codec::StoredClock::Realtime,
            Clock::Manual => crate::store::codec::StoredClock::Manual,
        }
    }

    /// As the history stored it.
    pub fn of_stored(clock: crate::store::codec::StoredClock) -> Clock {
        match clock {
            crate::store::codec::StoredClock::Realtime => Clock::Realtime,
            crate::store::codec::StoredClock::Manual => Clock::Manual,
        }
    }
}

/// What the shell knows about a match besides its world.
#[derive(Debug, Clone)]
pub struct MatchMeta {
    pub id: String,
    pub map: String,
    pub clock: Clock,
    pub players: usize,
    /// WebSocket spectators connected now.
    pub spectators: usize,
    /// Opponent slots a person can take now.
    pub free_slots: usize,
    /// Robots of the team's pursuer slots a person can take now.
    pub free_pursuer_slots: usize,
    /// Whether people may take over bot opponents (the showcase).
    pub bots_joinable: bool,
    /// How far behind the match its truth is shown to all but its owner (0: live). Set
    /// when people may play it (see `MatchRequest::spectator_delay_ticks`).
    pub spectator_delay_ticks: u64,
    /// Ticks a real-time match runs at once when it starts, faster than real time, before
    /// its clock starts (the showcase: its delay's worth, so that the delayed view moves
    /// from the first second rather than showing the first frame until the delay is over).
    /// Nobody can have joined by then, so nothing live is lost.
    pub head_start_ticks: u64,
    /// The robot team's preset, when the match was created with one
    /// (`lasertag_core::difficulty`).
    pub difficulty: Option<lasertag_core::difficulty::Difficulty>,
    /// Whether it counts for ratings (`CreateMatch::rated`, docs/ratings.md): its owner
    /// reads it as late as everyone else, and its end rates the person who played it
    /// against `difficulty`.
    pub rated: bool,
}

impl MatchMeta {
    /// The meta of the stored match `id` on `map` (a replay, a resumed match), as its
    /// settings say; nobody is at it yet.
    pub fn stored(
        id: String,
        map: String,
        settings: &crate::store::codec::StoredSettings,
    ) -> MatchMeta {
        MatchMeta {
            id,
            map,
            clock: Clock::of_stored(settings.clock),
            players: 0,
            spectators: 0,
            free_slots: 0,
            free_pursuer_slots: 0,
            bots_joinable: settings.bots_joinable,
            spectator_delay_ticks: settings.spectator_delay_ticks,
            head_start_ticks: 0,
            difficulty: settings.difficulty(),
            rated: settings.rated,
        }
    }
}

/// Whether people may play a match: human opponent slots, bot opponents people may take
/// over (`bots_joinable`, the showcase), or seats on the robot team (`pursuer_slots`). Such a match shows its truth `spectator_delay_s`
/// late and keeps its seed secret while it runs: a match is a pure function of its
/// settings, seed and inputs, so a public seed would let anyone rebuild it live.
pub fn people_may_play(config: &MatchConfig, bots_joinable: bool) -> bool {
    bots_joinable || config.opponent_control == ControlKind::Human || config.pursuer_slots > 0
}

/// A match as listings show it, published with every frame so that a listing never waits
/// on the match's task.
#[derive(Debug, Clone)]
pub struct Summary {
    pub meta: MatchMeta,
    pub tick: u64,
    pub time_s: f64,
    pub status: MatchStatus,
    pub winner: Option<Side>,
    pub robots: usize,
    pub opponents: usize,
    pub opponents_left: usize,
    /// The planner the team runs.
    pub planner: PlannerKind,
    /// The match's settings (they do not change while it runs).
    pub config: Arc<MatchConfig>,
}

impl Summary {
    /// The summary of `world` now; `config` is `world.config`, shared.
    pub fn of(world: &World, meta: &MatchMeta, config: &Arc<MatchConfig>) -> Summary {
        Summary {
            meta: meta.clone(),
            tick: world.tick,
            time_s: world.time_s(),
            status: world.status,
            winner: world.winner,
            robots: world.robots.len(),
            opponents: world.opponents.len(),
            opponents_left: world.opponents.iter().filter(|o| !o.tagged).count(),
            planner: world.team.kind(),
            config: config.clone(),
        }
    }

    /// Whether its seed is kept from everybody but its owner and the operator now: while a
    /// match people may play runs (see [`people_may_play`]).
    pub fn seed_secret(&self) -> bool {
        self.status == MatchStatus::Running
            && people_may_play(&self.config, self.meta.bots_joinable)
    }
}

/// How a match's task keeps up (wall-clock measurements of the shell, not part of the
/// deterministic match).
#[derive(Debug, Clone, PartialEq)]
pub struct Stats {
    pub tick: u64,
    /// Ticks the percentiles cover (the most recent ones).
    pub ticks_measured: usize,
    /// Compute time of one tick (the step plus building the published frame), microseconds.
    pub tick_us_p50: f64,
    pub tick_us_p99: f64,
    pub tick_us_max: f64,
    pub tick_us_mean: f64,
    /// Real-time ticks that were late by more than a whole tick period.
    pub late_ticks: u64,
    /// The longest wall-clock interval between two real-time ticks, milliseconds.
    pub longest_tick_gap_ms: f64,
    pub frames_published: u64,
    pub spectators: usize,
    pub players_connected: usize,
}

/// Which side a person asks to play (`POST /api/matches/{id}/players`, `team`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Team {
    /// An opponent slot: the hunted.
    #[default]
    Opponents,
    /// A robot of the team's pursuer slots: a hunter beside the robots.
    Robots,
}

/// A person's place at a match, as `join` gives it: the player, the body they play (an
/// opponent slot or a robot) and the secret its WebSocket connects with.
#[derive(Debug, Clone, PartialEq)]
pub struct Joined {
    pub player_id: String,
    pub body: AgentId,
    pub token: String,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_body_on_the_line_hides_what_is_behind_it_and_one_beside_it_does_not() {
        let eye = Point2::new(0.0, 0.0);
        let target = Point2::new(6.0, 0.0);
        let body = |x: f32, y: f32| (AgentId::Robot(0), Point2::new(x, y));
        let clear =
            |bodies: &[(AgentId, Point2<f32>)]| in_sight_past_bodies(eye, target, bodies.iter());
        assert!(clear(&[]));
        assert!(!clear(&[body(3.0, 0.0)]), "squarely between");
        assert!(clear(&[body(3.0, 0.2)]), "half the target shows past it");
        assert!(clear(&[body(3.0, 0.6)]), "beside the line");
        assert!(clear(&[body(7.0, 0.0)]), "behind the target");
        assert!(clear(&[body(-1.0, 0.0)]), "behind the eye");
        assert!(
            !clear(&[body(3.0, 0.2), body(3.0, -0.2)]),
            "two side by side"
        );
    }

    #[test]
    fn thinning_keeps_the_weighted_shape_and_caps_the_count() {
        // 1000 particles: the heavy half on the left, the light half on the right.
        let points: Vec<Point2<f32>> = (0..1000)
            .map(|i| Point2::new(if i < 500 { 1.0 } else { 9.0 }, i as f32 * 0.001))
            .collect();
        let weights: Vec<f32> = (0..1000)
            .map(|i| if i < 500 { 0.0018 } else { 0.0002 })
            .collect();
        let shown = thin(&points, &weights, 100);
        assert!(shown.len() <= 100 && shown.len() >= 80, "{}", shown.len());
        let left = shown.iter().filter(|p| p[0] == 100).count();
        assert!(left as f32 / shown.len() as f32 > 0.85, "{left}");
        let mean = weighted_mean(&points, &weights)[0];
        assert!((mean - 1.8).abs() < 1e-3, "{mean}");
    }

    #[test]
    fn small_or_unweighted_clouds_pass_through() {
        let points = vec![Point2::new(0.5, 0.25), Point2::new(1.0, 2.0)];
        assert_eq!(thin(&points, &[0.5, 0.5], 10), vec![[50, 25], [100, 200]]);
        let many: Vec<Point2<f32>> = (0..10).map(|i| Point2::new(i as f32, 0.0)).collect();
        assert_eq!(thin(&many, &[0.0; 10], 5).len(), 5);
        assert_eq!(thin(&many, &[f32::NAN; 10], 5).len(), 5);
    }
}
