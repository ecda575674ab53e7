//! The robot team's decisions: where each robot goes, how it gets there, when it fires.
//!
//! The team sees the world only through a [`TeamView`] (each robot's own pose estimate, laser
//! scan and anonymous detections) and answers with one [`RobotCommand`] per robot. It never
//! reads ground truth; the world applies the commands on the next tick.
//!
//! - [`baseline`]: the paper's baseline — random reachable destinations, chosen one robot at a
//!   time so teammates spread out, travel time as the only other factor.
//! - [`pursuit`]: shared by every planner — turn to a detected opponent, close in, fire.
//! - [`coordinated`]: the paper's tracker-driven planner — destinations where the team's
//!   belief expects the most opponent hypotheses, negotiated one robot at a time.

pub mod baseline;
pub mod coordinated;
pub mod pursuit;
mod view;

pub use view::{Knowledge, RobotCommand, RobotView, TeamView};

use std::borrow::Cow;
use std::sync::Arc;

use nalgebra::Point2;
use rand_chacha::ChaCha8Rng;

use crate::radio::{Message, OwnedSighting, Radio, Status};

use crate::sim::arena::Arena;
use crate::sim::{Physics, Pose};
use crate::tracker::{LaserModel, Role, Sighting, Tracker, TrackerEvent};

/// The planner a match asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlannerKind {
    Idle,
    Baseline,
    Coordinated,
    /// The coordinated planner's negotiation with each choice a look-ahead over several view
    /// poses ([`coordinated::search`]).
    Search,
    /// Robots driven from outside (a researcher's own brain): the team plans nothing and
    /// each robot follows the orders it is given (see `World::order_robot`).
    Api,
}

impl PlannerKind {
    /// The planner's name as the API and the experiments spell it.
    pub fn name(self) -> &'static str {
        match self {
            PlannerKind::Idle => "idle",
            PlannerKind::Baseline => "baseline",
            PlannerKind::Coordinated => "coordinated",
            PlannerKind::Search => "search",
            PlannerKind::Api => "api",
        }
    }
}

/// The team's brain: the opponent tracker(s), the chosen planner and its memory, and the
/// radio between the robots.
///
/// With a perfect radio (the default) the team is centralised: one tracker fed by every
/// robot's sensing, and planners that read each other's state directly. With a latency or
/// loss (see [`crate::radio`]) each robot keeps its own tracker, fed by its own sensing and
/// the sightings it receives, and plans from that tracker and from what it last heard of its
/// teammates ([`Knowledge`]); the planners' per-robot memories stay in one `Brain`, but a
/// robot's decisions read only its own entry and what it heard.
#[derive(Debug, Clone)]
pub struct Team {
    /// One tracker shared by the team (perfect radio), or one per robot, in robot order.
    pub trackers: Vec<Tracker>,
    pub(crate) brain: Brain,
    /// The channel and what each robot has heard; `None` while the team shares one tracker.
    channel: Option<Box<Channel>>,
}

/// What travels over the radio and what each robot made of it.
#[derive(Debug, Clone)]
struct Channel {
    radio: Radio,
    /// `heard[i][j]`: the last message robot `i` received from robot `j`.
    heard: Vec<Vec<Option<Arc<Message>>>>,
    /// `hits_heard[i][j]`: robot `j`'s hit count as robot `i` last heard it.
    hits_heard: Vec<Vec<u32>>,
    /// Each robot's own hit count.
    hits: Vec<u32>,
    /// `requests[i]`: teammates whose message of this tick asked robot `i` to step aside
    /// (filled by [`Team::track`], read by [`Team::plan`]).
    requests: Vec<Vec<usize>>,
}

#[derive(Debug, Clone)]
pub(crate) enum Brain {
    Idle,
    Api,
    Baseline(Box<baseline::Baseline>),
    Coordinated(Box<coordinated::Coordinated>),
}

impl Brain {
    /// Robot `i`'s plans as it announces them (see [`Status`]).
    fn status(&mut self, i: usize, pose: Pose) -> Status {
        match self {
            Brain::Idle | Brain::Api => Status::default(),
            Brain::Baseline(b) => b.status(i),
            Brain::Coordinated(c) => c.status(i, pose),
        }
    }
}

impl Team {
    /// `rng` feeds the planner; the tracker has its own stream, so that tracker settings do
    /// not change the planner's random choices. The team shares `tracker` (a perfect radio)
    /// until [`Team::with_radio`] says otherwise.
    pub fn new(
        kind: PlannerKind,
        arena: &Arena,
        physics: &Physics,
        coordination: coordinated::Settings,
        robots: usize,
        tracker: Tracker,
        rng: ChaCha8Rng,
    ) -> Team {
        let brain = match kind {
            PlannerKind::Idle => Brain::Idle,
            PlannerKind::Api => Brain::Api,
            PlannerKind::Baseline => {
                Brain::Baseline(Box::new(baseline::Baseline::new(arena, robots, rng)))
            }
            PlannerKind::Coordinated => Brain::Coordinated(Box::new(
                coordinated::Coordinated::new(arena, physics, coordination, robots),
            )),
            PlannerKind::Search => Brain::Coordinated(Box::new(
                coordinated::Coordinated::searching(arena, physics, coordination, robots),
            )),
        };
        Team {
            trackers: vec![tracker],
            brain,
            channel: None,
        }
    }

    /// Puts a radio between the `robots` robots. When it is not perfect (or asks for the
    /// per-robot machinery anyway), every robot gets its own copy of the tracker: the same
    /// particles and the same random stream, so that robots fed the same sightings in the
    /// same order hold the same belief as the shared tracker would.
    pub fn with_radio(mut self, radio: Radio, robots: usize) -> Team {
        if !radio.settings.uses_channel() {
            return self;
        }
        let tracker = self.trackers[0].clone();
        self.trackers = vec![tracker; robots];
        self.channel = Some(Box::new(Channel {
            radio,
            heard: vec![vec![None; robots]; robots],
            hits_heard: vec![vec![0; robots]; robots],
            hits: vec![0; robots],
            requests: vec![Vec::new(); robots],
        }));
        self
    }

    /// The planner this team runs (every kind asked for is built, so also the one asked for).
    pub fn kind(&self) -> PlannerKind {
        match self.brain {
            Brain::Idle => PlannerKind::Idle,
            Brain::Api => PlannerKind::Api,
            Brain::Baseline(_) => PlannerKind::Baseline,
            Brain::Coordinated(ref c) if c.is_searching() => PlannerKind::Search,
            Brain::Coordinated(_) => PlannerKind::Coordinated,
        }
    }

    /// Where robot `i` believes its teammate `j` is: with a perfect radio the teammate's
    /// current estimate (`estimates[j]`, shared memory); otherwise the pose in the last
    /// message `i` heard from `j`, however old, or nothing before the first one arrives.
    pub fn believed_teammate(
        &self,
        i: usize,
        j: usize,
        estimates: &[Point2<f32>],
    ) -> Option<Point2<f32>> {
        match &self.channel {
            None => estimates.get(j).copied(),
            Some(c) => c
                .heard
                .get(i)
                .and_then(|row| row.get(j))
                .and_then(|m| m.as_ref())
                .map(|m| m.pose.pos),
        }
    }

    /// What robot `i` last heard of teammate `j`: its pose estimate and the tick it was sent.
    /// With a perfect radio that is the teammate's current estimate (`estimates[j]`) as of
    /// `tick`; otherwise the last message, or nothing before the first one arrives.
    pub fn teammate_report(
        &self,
        i: usize,
        j: usize,
        estimates: &[Pose],
        tick: u64,
    ) -> Option<(Pose, u64)> {
        match &self.channel {
            None => estimates.get(j).map(|p| (*p, tick)),
            Some(c) => c
                .heard
                .get(i)
                .and_then(|row| row.get(j))
                .and_then(|m| m.as_ref())
                .map(|m| (m.pose, m.sent)),
        }
    }

    /// Where robot `i` heard teammate `j` is going: with a perfect radio the teammate's
    /// current goal (`goal`, shared memory); otherwise the goal in the last message `i`
    /// heard from `j`.
    pub fn teammate_goal(&self, i: usize, j: usize, goal: Option<Pose>) -> Option<Pose> {
        match &self.channel {
            None => goal,
            Some(c) => c
                .heard
                .get(i)
                .and_then(|row| row.get(j))
                .and_then(|m| m.as_ref())
                .and_then(|m| m.status.goal),
        }
    }

    /// Whether each robot keeps its own tracker (an imperfect radio).
    pub fn per_robot(&self) -> bool {
        self.channel.is_some()
    }

    /// Robot `robot`'s belief: its own tracker, or the team's when it is shared. `None` for
    /// a robot the team does not have.
    pub fn belief_of(&self, robot: usize, robots: usize) -> Option<&Tracker> {
        if robot >= robots {
            return None;
        }
        self.trackers.get(robot.min(self.trackers.len() - 1))
    }

    /// The team's merged belief. Shared tracker: its roles. Per-robot trackers: the roles of
    /// the robot that knows of the most tags (the lowest index among equals), so that the
    /// untagged counts still add up to the opponents it knows are left; each untagged role's
    /// cloud is the equal mixture of that role and the roles of the same id in the other
    /// robots' trackers (ids agree while robots split roles on the same sightings, which
    /// they do, later or earlier, unless a message is lost). Its confidence is the
    /// reference robot's.
    pub fn merged_belief(&self) -> Cow<'_, [Role]> {
        if self.trackers.len() == 1 {
            return Cow::Borrowed(&self.trackers[0].roles);
        }
        let Some(reference) = self
            .trackers
            .iter()
            .enumerate()
            .min_by_key(|(i, t)| (t.untagged_count(), *i))
            .map(|(i, _)| i)
        else {
            return Cow::Borrowed(&[]);
        };
        let roles = self.trackers[reference]
            .roles
            .iter()
            .map(|role| {
                if role.tagged {
                    return role.clone();
                }
                let parts: Vec<&Role> = self
                    .trackers
                    .iter()
                    .filter_map(|t| t.roles.iter().find(|r| r.id == role.id && !r.tagged))
                    .collect();
                Role::pooled(role, &parts)
            })
            .collect();
        Cow::Owned(roles)
    }

    /// Starts a full negotiation round on the next tick (searching robots then choose one per
    /// tick), as after a change of
    /// the belief from outside (a test that sets up a belief, a restored match).
    pub fn renegotiate(&mut self) {
        if let Brain::Coordinated(c) = &mut self.brain {
            c.renegotiate();
        }
    }

    /// Updates the tracker(s) with what the robots sensed (and, with a radio, heard), then
    /// plans. Returns the commands and what happened to the roles (of robot 0's tracker when
    /// every robot has its own).
    pub fn decide(
        &mut self,
        arena: &Arena,
        physics: &Physics,
        view: &TeamView,
    ) -> (Vec<RobotCommand>, Vec<TrackerEvent>) {
        let events = self.track(arena, physics, view);
        (self.plan(arena, physics, view), events)
    }

    /// The first half of [`Team::decide`]: the radio's traffic of this tick and the
    /// trackers' updates from what the robots sensed and heard. (Split so the shell can time
    /// the two halves; the pair is exactly `decide`.)
    pub fn track(
        &mut self,
        arena: &Arena,
        physics: &Physics,
        view: &TeamView,
    ) -> Vec<TrackerEvent> {
        let own: Vec<Option<Sighting>> = view
            .robots
            .iter()
            // A robot frozen before it sensed has an empty scan and nothing to say; one hit
            // after sensing still reports what it saw, and whether its own shot hit.
            .map(|r| {
                (!r.scan.is_empty() || r.hit).then_some(Sighting {
                    pose: r.pose,
                    scan: r.scan,
                    detections: r.detections,
                    tagged: r.hit,
                    age_ticks: 0,
                })
            })
            .collect();
        let laser = LaserModel {
            fov: physics.laser_fov,
            range: physics.laser_range,
        };
        let Some(channel) = self.channel.as_deref_mut() else {
            let sightings: Vec<Sighting> = own.iter().flatten().copied().collect();
            return self.trackers[0].update(arena, laser, &sightings);
        };
        let n = view.robots.len();
        // Every robot broadcasts what it sensed and its plans as of its last decision.
        for (i, r) in view.robots.iter().enumerate() {
            channel.hits[i] += r.hit as u32;
            let sighting = own[i]
                .filter(|_| channel.radio.settings.share_sightings)
                .map(|s| OwnedSighting::from_sighting(&s));
            let message = Message {
                from: i,
                sent: view.tick,
                pose: r.pose,
                frozen: r.frozen,
                sighting,
                hits: channel.hits[i],
                status: self.brain.status(i, r.pose),
            };
            channel.radio.send(message, n);
        }
        // A teammate's sighting is as old as the radio made it: the trackers widen it by
        // how far an opponent could have moved since.
        let age = |m: &Message| view.tick.saturating_sub(m.sent).min(u32::MAX as u64) as u32;
        let mut inbox: Vec<Vec<Arc<Message>>> = vec![Vec::new(); n];
        for (to, m) in channel.radio.deliver(view.tick) {
            if let Some(b) = inbox.get_mut(to) {
                b.push(m);
            }
        }
        let mut requests: Vec<Vec<usize>> = vec![Vec::new(); n];
        let mut events = Vec::new();
        for (i, received) in inbox.iter_mut().enumerate() {
            // By sender, each sender's in the order sent: with a perfect radio exactly the
            // order the shared tracker takes the robots' sightings in.
            received.sort_by_key(|m| m.from);
            // A hit whose message was lost still takes an opponent off: known from the next
            // message's count, placed in the sender's tag cone as it is now.
            let mut missed: Vec<(usize, u32, OwnedSighting)> = Vec::new();
            for m in received.iter() {
                let expected = channel.hits_heard[i][m.from]
                    + m.sighting.as_ref().is_some_and(|s| s.tagged) as u32;
                for _ in expected..m.hits {
                    missed.push((
                        m.from,
                        age(m),
                        OwnedSighting {
                            pose: m.pose,
                            scan: Vec::new(),
                            detections: Vec::new(),
                            tagged: true,
                        },
                    ));
                }
                channel.hits_heard[i][m.from] = m.hits;
                if m.status.yield_request == Some(i) {
                    requests[i].push(m.from);
                }
                channel.heard[i][m.from] = Some(m.clone());
            }
            let mut sightings: Vec<Sighting> = Vec::new();
            for k in 0..n {
                if k == i {
                    sightings.extend(own[i]);
                    continue;
                }
                for m in received.iter().filter(|m| m.from == k) {
                    sightings.extend(m.sighting.as_ref().map(|s| s.as_sighting(age(m))));
                }
                sightings.extend(
                    missed
                        .iter()
                        .filter(|(from, _, _)| *from == k)
                        .map(|(_, age, s)| s.as_sighting(*age)),
                );
            }
            let e = self.trackers[i].update(arena, laser, &sightings);
            if i == 0 {
                events = e;
            }
        }
        channel.requests = requests;
        events
    }

    /// The second half of [`Team::decide`]: each robot's command from the updated belief(s)
    /// and what it heard.
    pub fn plan(&mut self, arena: &Arena, physics: &Physics, view: &TeamView) -> Vec<RobotCommand> {
        let Some(channel) = self.channel.as_deref() else {
            let know = Knowledge::shared(&self.trackers[0]);
            return plan(&mut self.brain, arena, physics, &know, view);
        };
        let know = Knowledge {
            trackers: &self.trackers,
            heard: (!channel.radio.settings.perfect()).then_some(&channel.heard[..]),
            requests: &channel.requests,
        };
        plan(&mut self.brain, arena, physics, &know, view)
    }
}

fn plan(
    brain: &mut Brain,
    arena: &Arena,
    physics: &Physics,
    know: &Knowledge,
    view: &TeamView,
) -> Vec<RobotCommand> {
    match brain {
        Brain::Idle | Brain::Api => vec![RobotCommand::default(); view.robots.len()],
        Brain::Baseline(b) => b.decide(arena, physics, know, view),
        Brain::Coordinated(c) => c.decide_with(arena, physics, know, view),
    }
}

crate::checkpoint::restore_struct!(Channel {
    plain: [heard, hits_heard, hits, requests],
    nested: [radio],
    derived: [],
});
crate::checkpoint::restore_struct!(Team {
    plain: [],
    nested: [trackers, brain, channel],
    derived: [],
});

/// The planner is the settings' choice: a checkpoint of another planner is refused.
impl crate::checkpoint::Restore for Brain {
    fn save(&self, w: &mut crate::checkpoint::Writer) {
        use crate::checkpoint::Plain;
        match self {
            Brain::Idle => 0u8.save(w),
            Brain::Api => 1u8.save(w),
            Brain::Baseline(b) => {
                2u8.save(w);
                b.save(w);
            }
            Brain::Coordinated(c) => {
                3u8.save(w);
                c.save(w);
            }
        }
    }
    fn restore(
        &mut self,
        r: &mut crate::checkpoint::Reader,
    ) -> Result<(), crate::checkpoint::CheckpointError> {
        use crate::checkpoint::Plain;
        match (u8::load(r)?, self) {
            (0, Brain::Idle) | (1, Brain::Api) => Ok(()),
            (2, Brain::Baseline(b)) => b.restore(r),
            (3, Brain::Coordinated(c)) => c.restore(r),
            _ => Err(crate::checkpoint::CheckpointError::Mismatch {
                what: "the planner",
            }),
        }
    }
}

#[cfg(test)]
mod tests;
