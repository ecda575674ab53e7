//! The task that owns one match's [`World`].
//!
//! Besides answering requests and ticking, the task publishes a [`Frame`] after every tick
//! (a manual match nobody watches: when its state is asked for; see `publish_stepped`) and
//! after anything else that changes what viewers see, on a `watch` channel, and keeps
//! the people who play: their tokens, which connection is theirs, and how long a dropped
//! player has to come back (a freed slot a person took from a bot goes back to the bot).
//!
//! The people at the match and their inputs are in `seats.rs`; robots driven from outside
//! (orders, observations, environment steps) in `robots.rs`; what goes to the history (the
//! store and replays) in `history.rs`.
//!
//! What the task takes is a [`Request`]; a read or a finished step lends the reader a
//! [`Reading`], a view of the task that follows the reader's `Sight`. Both live here because
//! a `Reading` borrows the very task that makes it.
//!
//! Long file: one match task's loop, its messages, the readings it lends and its clean-up
//! rules share the task's state.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

use tokio::sync::{mpsc, oneshot, watch};

mod history;
mod people;
mod seats;
mod step;
use seats::Player;
use tokio::time::MissedTickBehavior;
use tracing::Instrument;

use crate::access::{ClientKey, Owner, SecretHash};
use std::borrow::Cow;

use crate::access::random_id;
use crate::game::admission;
use crate::game::delay::{HeldBack, HeldBelief};
use crate::game::error::MatchError;
use crate::game::hub::{Hub, Seat};
use crate::game::record::Recording;
use crate::game::view::Sight;
use crate::game::view::{
    BELIEF_EVERY, Clock, Frame, Joined, MatchMeta, SeatView, SeatViews, Stats, Summary, Team,
};
use crate::metrics::{Metrics, Refusal, TickHistograms};
use lasertag_core::sim::AgentId;
use lasertag_core::sim::TICK_HZ;
use lasertag_core::world::{Control, FinishReason, HumanInput, InputError, StepMark, WorldInput};
use lasertag_core::world::{Event, RobotObservation, RobotOrderError};
use lasertag_core::world::{MatchConfig, MatchStatus, World};

/// Ticks over which overruns are counted, and how many of them may overrun before the match
/// is ended (`overloaded`): ten seconds of real time at 20 Hz, half of it over budget, is
/// no passing hiccup but a match the server cannot carry without starving the others.
const OVERRUN_WINDOW: usize = 200;
const OVERRUN_LIMIT: usize = 100;

/// Ticks a manual step runs before it publishes a frame and lets other requests in, and the
/// time after which it lets them in sooner (it shares the runtime with the requests; see
/// `spawn_match`).
const STEP_CHUNK: u64 = 250;
const STEP_SLICE: Duration = Duration::from_millis(2);
/// Tick compute times kept for the stats percentiles.
const TICK_WINDOW: usize = 4096;
/// How often the task looks for players whose connection has gone.
const HOUSEKEEPING: Duration = Duration::from_millis(100);

struct PendingStep {
    remaining: u64,
    /// Ticks run since the last frame (one is published every `STEP_CHUNK`).
    unpublished: u64,
    /// The events logged before the step began (its answer reads those after).
    since: u64,
    answer: Answer,
}

/// What a match's task does with the match once it has done what was asked: reads it (the
/// caller's conversion, run on the task) or tells why it refused.
pub type Answer = Box<dyn FnOnce(Result<&mut Reading<'_>, MatchError>) + Send>;

/// What a handler may ask of a match task.
pub enum Request {
    /// Read the match as a reader with `sight` may see it.
    Read { sight: Sight, answer: Answer },
    /// One change from outside (an opponent's or a robot's order), applied at once.
    Apply {
        input: WorldInput,
        reply: oneshot::Sender<Result<(), MatchError>>,
    },
    /// A step of a manual-clock match: every input of `inputs` (all or none), then `ticks`
    /// ticks; the answer reads the match live once the last has run. `what` names the
    /// request in refusals (`step`, `act`).
    Step {
        inputs: Vec<WorldInput>,
        ticks: u64,
        what: &'static str,
        answer: Answer,
    },
    Join {
        name: crate::names::JoinName,
        team: Team,
        /// Who asks (for the rule of one unplayed hold per client).
        client: Option<ClientKey>,
        reply: oneshot::Sender<Result<Joined, MatchError>>,
    },
    /// A WebSocket connection wants to play the slot `token` belongs to.
    Connect {
        token: String,
        reply: oneshot::Sender<Result<Seat, MatchError>>,
    },
    /// A seated connection's keys (ignored unless `generation` is the slot's current one):
    /// numbered ones are queued and applied one per tick; others hold until the next.
    Input {
        seat: usize,
        generation: u64,
        input: HumanInput,
        seq: Option<u64>,
    },
    /// End the match for this reason (deleted, or the server is shutting down) and its task.
    Stop(FinishReason),
    /// End the task, not the match: its record goes to the store, whole, and the next
    /// server to start on that store resumes it (`game::resume`).
    Suspend,
}

impl Request {
    /// Whether answering it may change what listings show (seats, orders, steps).
    pub(crate) fn changes_listing(&self) -> bool {
        !matches!(self, Request::Input { .. } | Request::Read { .. })
    }

    /// Whether it counts as a client's activity (keys do not: a connected player is
    /// counted already).
    pub(crate) fn is_activity(&self) -> bool {
        !matches!(self, Request::Input { .. })
    }

    /// Whether it changes the match (what keeps a manual match alive).
    pub(crate) fn is_change(&self) -> bool {
        matches!(self, Request::Apply { .. } | Request::Step { .. })
    }
}

impl std::fmt::Debug for Request {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Request::Read { sight, .. } => f.debug_struct("Read").field("sight", sight).finish(),
            Request::Apply { input, .. } => f.debug_struct("Apply").field("input", input).finish(),
            Request::Step { ticks, what, .. } => f
                .debug_struct("Step")
                .field("what", what)
                .field("ticks", ticks)
                .finish(),
            Request::Join { name, .. } => f
                .debug_struct("Join")
                .field("name", &name.name.as_str())
                .finish(),
            Request::Connect { .. } => f.write_str("Connect"),
            Request::Input { seat, seq, .. } => f
                .debug_struct("Input")
                .field("seat", seat)
                .field("seq", seq)
                .finish(),
            Request::Stop(reason) => f.debug_tuple("Stop").field(reason).finish(),
            Request::Suspend => f.write_str("Suspend"),
        }
    }
}

/// A match as a reader with some [`Sight`] may see it (see the module docs).
pub struct Reading<'a> {
    task: &'a mut MatchTask,
    sight: Sight,
    /// The events logged before the step this answers (for a plain read: all of them).
    since: u64,
}

impl<'a> Reading<'a> {
    fn new(task: &'a mut MatchTask, sight: Sight, since: u64) -> Reading<'a> {
        Reading { task, sight, since }
    }

    /// What is held back from this reader: nothing for the owner, nor once the match is
    /// over (then nothing is left to hide).
    fn held(&self) -> Option<&HeldBack> {
        match self.sight {
            Sight::Live => None,
            Sight::Public if self.task.world.status == MatchStatus::Finished => None,
            Sight::Public => self.task.held.as_ref(),
        }
    }

    pub fn meta(&self) -> &MatchMeta {
        &self.task.meta
    }

    pub fn config(&self) -> &MatchConfig {
        &self.task.config
    }

    /// The match as listings show it, now (nothing in it is held back).
    pub fn summary(&self) -> Summary {
        Summary::of(&self.task.world, &self.task.meta, &self.task.config)
    }

    /// How the task keeps up.
    pub fn stats(&self) -> Stats {
        self.task.stats()
    }

    /// The newest frame this reader may see: the world as it is now for a live reader
    /// (whatever changes what a frame shows publishes one), the one shown to spectators for
    /// the public.
    pub fn frame(&mut self) -> Arc<Frame> {
        if let Some(held) = self.held() {
            return held.shown().clone();
        }
        self.task.refresh_frame();
        self.task.frames.borrow().clone()
    }

    /// Robot `robot`'s belief as this reader may see it, or the team's merged one when
    /// `None`.
    pub fn belief(&self, robot: Option<usize>) -> Result<Cow<'_, HeldBelief>, MatchError> {
        let belief = match self.held() {
            Some(held) => held.belief(robot).map(Cow::Borrowed),
            None => HeldBelief::of(&self.task.world, robot).map(Cow::Owned),
        };
        belief.ok_or_else(|| {
            MatchError::NoRobot(format!(
                "robot: no robot r{} in this match (it has {})",
                robot.unwrap_or_default(),
                self.task.world.robots.len()
            ))
        })
    }

    /// The tick of the belief [`Self::belief`] would give, without copying it.
    pub fn belief_tick(&self, robot: Option<usize>) -> Result<u64, MatchError> {
        let tick = match self.held() {
            Some(held) => held.belief(robot).map(|b| b.tick),
            None => robot
                .is_none_or(|r| r < self.task.world.robots.len())
                .then_some(self.task.world.tick),
        };
        tick.ok_or_else(|| {
            MatchError::NoRobot(format!(
                "robot: no robot r{} in this match (it has {})",
                robot.unwrap_or_default(),
                self.task.world.robots.len()
            ))
        })
    }

    /// The events after `since` that this reader may see, oldest first.
    pub fn events(&self, since: u64) -> &[Event] {
        let shown = self.held().map_or(u64::MAX, HeldBack::shown_seq);
        let events = self.task.world.events_since(since);
        let end = events.partition_point(|e| e.seq <= shown);
        &events[..end]
    }

    /// The events logged since the step this answers began (none for a plain read).
    pub fn stepped_events(&self) -> &[Event] {
        self.task.world.events_since(self.since)
    }

    /// The world as it is now, to a reader who may see it live.
    pub fn live(&self) -> Option<&World> {
        (self.sight == Sight::Live).then_some(&self.task.world)
    }

    /// What robot `robot` knows now. It is no frame's: whether a reader may have it while
    /// people play is the caller's rule (its owner only, until the match ends).
    pub fn observation(&self, robot: usize) -> Result<RobotObservation<'_>, MatchError> {
        self.task.world.observation(robot).ok_or_else(|| {
            MatchError::Input(InputError::Robot(RobotOrderError::UnknownRobot(
                AgentId::Robot(robot).to_string(),
            )))
        })
    }

    /// Whether the match has ended.
    pub fn finished(&self) -> bool {
        self.task.world.status == MatchStatus::Finished
    }
}

/// Where a match stands with the store.
#[derive(Debug)]
pub(super) struct StoreProgress {
    /// The store has the match's start.
    pub(super) begun: bool,
    /// The match's end went to the store: nothing more of it does (a match another server
    /// began and this one adopted no longer takes writes from it once finished, and any
    /// write then would be refused and logged).
    pub(super) ended: bool,
    pub(super) last_flush: Instant,
    /// The tick of the newest checkpoint the store has (or was sent), if any.
    pub(super) last_checkpoint: Option<u64>,
    /// The most bytes one of its checkpoints may take (its price).
    pub(super) checkpoint_bytes: u64,
}

/// What a match task needs from the shell besides its world.
pub struct TaskSettings {
    /// How long a dropped player may take to come back before the slot is freed.
    pub reconnect_grace: Duration,
    /// How long a finished match stays before its task ends (and `on_exit` unregisters it).
    pub finished_grace: Duration,
    /// How long a match with human slots may go without any client before it is ended.
    pub abandoned_after: Duration,
    /// How long a manual-clock match may go unchanged (no step, no command) before it is
    /// ended: nothing else ever ends one.
    pub idle_manual_after: Duration,
    /// People who may hold a slot at once.
    pub max_players: usize,
    /// How long a slot joined but never played (no input from a connection) is held.
    pub join_hold: Duration,
    /// Such slots one client may hold at once.
    pub max_holds: usize,
    /// The seats of every client over all matches, and how many one may hold.
    pub seats: Arc<crate::game::hub::SeatLedger>,
    pub max_seats: usize,
    /// Whether one client may hold seats on both sides of this match.
    pub both_sides: bool,
    /// A tick that takes longer overruns (see [`OVERRUN_WINDOW`]).
    pub tick_overrun: Duration,
    /// The path search one request's robot orders may take (`Config::max_command_work`).
    pub max_command_work: u64,
    pub metrics: Metrics,
    /// Where the match goes for replay once it has finished.
    pub history: Arc<crate::game::replay::History>,
    /// Who owns the match (stored, hashed, to resume it).
    pub owner: Arc<Owner>,
    /// The trained policy that drives the team (`MatchConfig::policy`), set up for it.
    pub policy: Option<lasertag_policy::TeamPolicy>,
    /// Called once when the task ends by itself (cleaned up, abandoned): unregisters it.
    pub on_exit: Box<dyn FnOnce() + Send>,
}

/// A person's seat in a resumed match, as the store kept it.
#[derive(Debug, Clone)]
pub struct ResumedSeat {
    pub seat: usize,
    pub player_id: String,
    pub name: String,
    pub token: SecretHash,
    pub client: Option<ClientKey>,
}

/// What a match rebuilt from its record (`game::resume`) brings to its task besides its
/// world.
#[derive(Debug)]
pub struct Resumed {
    /// Its record, all of it in the store already.
    pub recording: Recording,
    /// The recorded inputs from the world's tick on, and the tick the match had reached:
    /// the task runs these ticks at once, publishing each, so that a delayed view has its
    /// delay's worth of frames to show (and nobody sees the truth live).
    pub catch_up: Vec<(u64, WorldInput)>,
    pub until: u64,
    pub seats: Vec<ResumedSeat>,
    /// Who has played it, by name.
    pub people: Vec<crate::store::codec::StoredPerson>,
    pub started_at: std::time::SystemTime,
    /// The tick of the checkpoint it was rebuilt from, if any.
    pub checkpoint_tick: Option<u64>,
}

impl std::fmt::Debug for TaskSettings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TaskSettings")
            .field("reconnect_grace", &self.reconnect_grace)
            .field("finished_grace", &self.finished_grace)
            .field("abandoned_after", &self.abandoned_after)
            .field("idle_manual_after", &self.idle_manual_after)
            .field("max_players", &self.max_players)
            .finish_non_exhaustive()
    }
}

/// Spawns the task for `world` and returns the channel to it and the viewers' hub. The task
/// ends when the match is stopped or every handle is dropped.
pub fn spawn_match(
    world: World,
    meta: MatchMeta,
    settings: TaskSettings,
) -> (mpsc::Sender<Request>, Hub) {
    spawn(world, meta, settings, None)
}

/// Spawns the task of a match rebuilt from its record: it catches up to where the match had
/// got (see [`Resumed`]) before it answers anything.
pub fn spawn_resumed(
    world: World,
    meta: MatchMeta,
    settings: TaskSettings,
    resumed: Resumed,
) -> (mpsc::Sender<Request>, Hub) {
    spawn(world, meta, settings, Some(resumed))
}

fn spawn(
    world: World,
    meta: MatchMeta,
    settings: TaskSettings,
    resumed: Option<Resumed>,
) -> (mpsc::Sender<Request>, Hub) {
    let (tx, rx) = mpsc::channel(256);
    let first = Arc::new(Frame::build(&world, &Default::default(), 0, 0, true));
    let (frames_tx, frames) = watch::channel(first.clone());
    let (held, spectate) = match meta.spectator_delay_ticks {
        0 => (None, frames.clone()),
        delay => {
            let (held, rx) = HeldBack::new(delay, first, &world);
            (Some(held), rx)
        }
    };
    let config = Arc::new(world.config.clone());
    let (summaries_tx, summary) = watch::channel(Arc::new(Summary::of(&world, &meta, &config)));
    let hub = Hub {
        frames,
        spectate,
        delay_ticks: meta.spectator_delay_ticks,
        physics: Arc::new(world.config.physics.clone()),
        summary,
        arena: world.arena.clone(),
        spectators: Arc::new(AtomicUsize::new(0)),
        watchers: Default::default(),
        moved: Default::default(),
        encoded: Default::default(),
    };
    let span = tracing::info_span!("match", id = %meta.id);
    // A manual-clock match computes only when asked, so it runs on the runtime of the
    // requests that drive it: an `act` is then answered without waking a thread of another
    // runtime (a long step yields every `STEP_SLICE`).
    let handle = match meta.clock {
        Clock::Manual => tokio::runtime::Handle::try_current().ok(),
        Clock::Realtime => None,
    }
    .or_else(|| match_runtime().cloned())
    .unwrap_or_else(tokio::runtime::Handle::current);
    let kind = world.team.kind().name();
    let clock = match meta.clock {
        Clock::Realtime => "realtime",
        Clock::Manual => "manual",
    };
    let histograms = settings.metrics.tick_histograms(kind, clock);
    let now = Instant::now();
    let spills = settings.history.store().is_some();
    let lease = settings
        .history
        .store()
        .map(|s| (s.lease().clone(), s.lease().term()));
    let moved = hub.moved.clone();
    let (recording, started_at, catch_up, seats, people, last_checkpoint) = match resumed {
        Some(r) => (
            r.recording,
            r.started_at,
            Some((r.catch_up, r.until)),
            r.seats,
            people::People::restored(&r.people),
            r.checkpoint_tick,
        ),
        None => (
            Recording::new(spills),
            std::time::SystemTime::now(),
            None,
            Vec::new(),
            people::People::default(),
            None,
        ),
    };
    let heavy_ticks =
        admission::holds_a_worker(&admission::match_on(&world.arena.def, &world.config));
    let mut task = MatchTask {
        recording,
        archived: false,
        store: StoreProgress {
            // A resumed match's start is in the store already.
            begun: catch_up.is_some(),
            ended: false,
            last_flush: now,
            last_checkpoint,
            checkpoint_bytes: admission::checkpoint_bytes(&world.arena.def, &world.config),
        },
        catch_up,
        lease,
        moved,
        started_at,
        players: MatchTask::bodies(&world).iter().map(|_| None).collect(),
        people,
        bodies: MatchTask::bodies(&world),
        finished_at: None,
        last_activity: now,
        last_change: now,
        histograms,
        world,
        config,
        meta,
        settings,
        frames: frames_tx,
        held,
        summaries: summaries_tx,
        spectators: hub.spectators.clone(),
        published_seq: 0,
        robot_tags: 0,
        last_belief_tick: 0,
        frames_published: 1,
        frame_stale: false,
        tick_us: Vec::with_capacity(TICK_WINDOW),
        tick_next: 0,
        late_ticks: 0,
        longest_tick_gap: Duration::ZERO,
        overruns: std::collections::VecDeque::with_capacity(OVERRUN_WINDOW),
        overrun_count: 0,
        heavy_ticks,
    };
    task.reseat(seats);
    task.publish_summary();
    // The store hears of the match at once: a crash in its first second still leaves it.
    task.store_flush(true);
    handle.spawn(task.run(rx).instrument(span));
    (tx, hub)
}

/// Runs `f`, which may search paths for milliseconds (`heavy`), without holding up the
/// other tasks of this runtime's worker: on a multi-threaded runtime the worker hands its
/// queue to another thread first. How much such work runs at all is bounded by
/// `game::work`.
pub(super) fn off_the_workers<R>(heavy: bool, f: impl FnOnce() -> R) -> R {
    let threaded = tokio::runtime::Handle::try_current()
        .is_ok_and(|h| h.runtime_flavor() == tokio::runtime::RuntimeFlavor::MultiThread);
    if heavy && threaded {
        tokio::task::block_in_place(f)
    } else {
        f()
    }
}

/// The runtime real-time match tasks run on: threads of their own, so that a tick is never
/// queued behind the hundreds of connection tasks (serialising and sending snapshots) of the
/// server's runtime. Ticks are short and rare, so these threads are mostly asleep and the OS
/// wakes them promptly. `None` (then the current runtime is used) if it cannot be built.
fn match_runtime() -> Option<&'static tokio::runtime::Handle> {
    static RUNTIME: OnceLock<Option<tokio::runtime::Runtime>> = OnceLock::new();
    RUNTIME
        .get_or_init(|| {
            let threads = std::thread::available_parallelism().map_or(2, |n| n.get().min(4));
            tokio::runtime::Builder::new_multi_thread()
                .worker_threads(threads)
                .thread_name("match")
                .enable_all()
                .build()
                .map_err(|e| tracing::warn!("no separate runtime for matches: {e}"))
                .ok()
        })
        .as_ref()
        .map(|rt| rt.handle())
}

struct MatchTask {
    world: World,
    /// `world.config`, shared with every summary published.
    config: Arc<MatchConfig>,
    /// Every change from outside applied to `world`, for its replay.
    recording: Recording,
    /// Whether the finished match went to the history already.
    archived: bool,
    /// What the store has of the match.
    store: StoreProgress,
    /// A resumed match's ticks to run at once before anything else (see [`Resumed`]).
    catch_up: Option<(Vec<(u64, WorldInput)>, u64)>,
    /// How long this server may run its matches, when its store is shared (`store::Lease`),
    /// and the term this match holds it in.
    lease: Option<(Arc<crate::store::Lease>, u64)>,
    /// Where the match went, when it leaves this server (`Hub::moved`).
    moved: Arc<std::sync::OnceLock<Option<String>>>,
    started_at: std::time::SystemTime,
    /// When the world was first seen finished (for the clean-up grace).
    finished_at: Option<Instant>,
    /// The last time a request came or a client was connected (for abandonment).
    last_activity: Instant,
    /// The last step or command (what keeps a manual match alive).
    last_change: Instant,
    histograms: TickHistograms,
    meta: MatchMeta,
    settings: TaskSettings,
    /// Who holds each seat, and the body each seat plays (see `seats`).
    players: Vec<Option<Player>>,
    /// Everyone who has played, by name: what their result counts for.
    people: people::People,
    bodies: Vec<AgentId>,
    frames: watch::Sender<Arc<Frame>>,
    /// What spectators see, when people play (see `delay`).
    held: Option<HeldBack>,
    /// The match as listings show it, published with each frame so that the lobby never
    /// waits on this task.
    summaries: watch::Sender<Arc<Summary>>,
    spectators: Arc<AtomicUsize>,
    published_seq: u64,
    robot_tags: u32,
    last_belief_tick: u64,
    frames_published: u64,
    /// Whether the world has changed since the last frame (see `publish_stepped`).
    frame_stale: bool,
    /// Ring buffer of tick compute times (µs).
    tick_us: Vec<u32>,
    tick_next: usize,
    late_ticks: u64,
    /// The longest wall-clock interval between two real-time ticks.
    longest_tick_gap: Duration,
    /// Whether each of the last ticks overran, and how many did.
    overruns: std::collections::VecDeque<bool>,
    overrun_count: usize,
    /// Whether a tick of this match is priced past `admission::HEAVY_TICK_MS`: its ticks
    /// then run off the workers, so that the tasks queued behind it on its worker (other
    /// matches' ticks, reads of them) are not held for the whole of a long tick.
    heavy_ticks: bool,
}

impl MatchTask {
    async fn run(mut self, mut rx: mpsc::Receiver<Request>) {
        tracing::info!(map = %self.meta.map, clock = ?self.meta.clock, "match started");
        let realtime = self.meta.clock == Clock::Realtime;
        let period = Duration::from_millis(1000 / TICK_HZ as u64);
        let mut interval = tokio::time::interval(period);
        // A match that overran its tick (a loaded machine) skips the missed ticks rather than
        // bursting to catch up: the world must not fast-forward under the players' feet.
        interval.set_missed_tick_behavior(MissedTickBehavior::Skip);
        let mut housekeeping = tokio::time::interval(HOUSEKEEPING);
        housekeeping.set_missed_tick_behavior(MissedTickBehavior::Skip);
        let mut pending: Option<PendingStep> = None;
        let mut last_tick: Option<Instant> = None;
        if let Some((inputs, until)) = self.catch_up.take() {
            self.catch_up(&inputs, until);
        } else if realtime {
            self.head_start();
        }
        loop {
            self.archive();
            let running = self.world.status == MatchStatus::Running;
            let draining = self.held.as_ref().is_some_and(|h| !h.drained());
            tokio::select! {
                biased;
                req = rx.recv() => {
                    let Some(req) = req else { break };
                    if let Request::Suspend = req {
                        // A finished match has nothing to resume: it only ends.
                        if self.world.status == MatchStatus::Running {
                            self.store_flush(true);
                            tracing::info!(tick = self.world.tick, "match suspended: the store has it to resume");
                        }
                        break;
                    }
                    if self.lease_lapsed() {
                        break;
                    }
                    if let Request::Stop(reason) = req {
                        let _ = self.apply(WorldInput::End(reason));
                        self.publish();
                        // Nothing is left to hide, and the task (and its channels) ends now.
                        if let Some(held) = &mut self.held {
                            held.flush();
                        }
                        self.archive();
                        break;
                    }
                    if req.is_activity() {
                        self.last_activity = Instant::now();
                    }
                    if req.is_change() {
                        self.last_change = Instant::now();
                    }
                    let changes_listing = req.changes_listing();
                    self.answer(req, realtime, &mut pending);
                    // Joins, seats and commands change what the lobby shows.
                    if changes_listing {
                        self.publish_summary();
                    }
                }
                _ = interval.tick(), if realtime && (running || draining) => {
                    if self.lease_lapsed() {
                        break;
                    }
                    if !running {
                        // Finished, but spectators are still that far behind: the last
                        // frames come out at the pace they were made.
                        if let Some(held) = &mut self.held {
                            held.tick_on();
                        }
                        continue;
                    }
                    let now = Instant::now();
                    if let Some(gap) = last_tick.map(|t| now - t) {
                        self.longest_tick_gap = self.longest_tick_gap.max(gap);
                        if gap > period + period / 2 {
                            self.late_ticks += 1;
                            self.settings.metrics.late_ticks.inc();
                        }
                    }
                    last_tick = Some(now);
                    off_the_workers(self.heavy_ticks, || {
                        self.step();
                        self.publish();
                    });
                    self.record(now.elapsed());
                    if self.world.status == MatchStatus::Finished {
                        tracing::info!(tick = self.world.tick, winner = ?self.world.winner, "match finished");
                    }
                }
                _ = std::future::ready(()), if pending.is_some() => {
                    if self.lease_lapsed() {
                        break;
                    }
                    if let Some(mut step) = pending.take() {
                        let n = step.remaining.min(STEP_CHUNK - step.unpublished);
                        let slice = Instant::now();
                        let mut done = 0;
                        while done < n {
                            let t = Instant::now();
                            off_the_workers(self.heavy_ticks, || self.step());
                            self.record(t.elapsed());
                            done += 1;
                            let slice_over = slice.elapsed() >= STEP_SLICE;
                            if self.world.status == MatchStatus::Finished || slice_over {
                                break;
                            }
                        }
                        step.remaining -= done;
                        step.unpublished += done;
                        let over = step.remaining == 0 || self.world.status == MatchStatus::Finished;
                        if over || step.unpublished == STEP_CHUNK {
                            self.publish_stepped();
                            step.unpublished = 0;
                        } else {
                            // A request let in before the next slice sees the world now.
                            self.frame_stale = true;
                        }
                        if over {
                            self.answer_step(step);
                        } else {
                            pending = Some(step);
                            tokio::task::yield_now().await;
                        }
                    }
                }
                _ = housekeeping.tick() => {
                    self.refresh_frame();
                    let why = self.housekeeping();
                    self.archive();
                    self.store_flush(false);
                    self.publish_summary();
                    if let Some(why) = why {
                        self.settings.metrics.matches_removed.with_label_values(&[why]).inc();
                        let on_exit = std::mem::replace(&mut self.settings.on_exit, Box::new(|| {}));
                        on_exit();
                        break;
                    }
                }
            }
        }
        self.archive();
        tracing::info!(tick = self.world.tick, "match ended");
    }

    /// Runs the match's head start (`MatchMeta::head_start_ticks`) at once: each tick as the
    /// clock would run it (published, held back for spectators, recorded), so that the
    /// delayed view already has that much to show. Off the workers: it computes for a few
    /// hundred milliseconds. Its ticks are not timed against the tick budget: they run back
    /// to back on purpose, and a slow one keeps no one waiting (the overrun guard is for ticks
    /// that fall behind the clock).
    fn head_start(&mut self) {
        let ticks = self.meta.head_start_ticks;
        off_the_workers(ticks > 0, || {
            for _ in 0..ticks {
                if self.world.status != MatchStatus::Running {
                    break;
                }
                self.step();
                self.publish();
            }
        });
    }

    /// Whether this server's hold on its matches ran out (`store::Lease`: it could not
    /// reach its shared store for a while, or it was paused): another server may run the
    /// match now, so this one stops it at once, unfinished, and lets its viewers know it
    /// moved; the store keeps refusing its writes (the match's fence moved on).
    fn lease_lapsed(&mut self) -> bool {
        if self.lease.as_ref().is_none_or(|(l, term)| l.holds(*term)) {
            return false;
        }
        tracing::warn!(
            tick = self.world.tick,
            "this server's lease on its matches ran out: the match stops here, another server takes it"
        );
        let _ = self.moved.set(None);
        self.settings
            .metrics
            .matches_removed
            .with_label_values(&["moved"])
            .inc();
        let on_exit = std::mem::replace(&mut self.settings.on_exit, Box::new(|| {}));
        on_exit();
        true
    }

    /// Runs a resumed match from the world's tick to `until` at once, re-applying the
    /// recorded `inputs` (the store has them: nothing is recorded again), publishing each
    /// tick as the clock would, so that a held-back view shows what it showed before the
    /// restart. Off the workers, untimed, as the head start.
    fn catch_up(&mut self, inputs: &[(u64, WorldInput)], until: u64) {
        off_the_workers(true, || {
            let mut next = 0;
            loop {
                while let Some((t, input)) = inputs.get(next)
                    && *t <= self.world.tick
                {
                    if *t == self.world.tick {
                        let _ = self.world.apply(input);
                    }
                    next += 1;
                }
                if self.world.tick >= until || self.world.status != MatchStatus::Running {
                    break;
                }
                self.world.step();
                self.publish();
            }
            self.publish();
        });
        tracing::info!(tick = self.world.tick, "match resumed");
    }

    /// The policy's orders of this tick, if a policy drives the team: applied and recorded
    /// like any robot's command, so replays and resumes never need the model.
    fn feed_policy(&mut self) {
        let Some(policy) = self.settings.policy.as_mut() else {
            return;
        };
        let inputs: Vec<WorldInput> = policy
            .orders(&self.world)
            .into_iter()
            .map(|(robot, order)| WorldInput::Robot { robot, order })
            .collect();
        // A robot walked on from where it stood gets a route: the match's own work, as
        // much as its order can take (one waypoint, once in seconds), not a request's.
        let cells = self.world.arena.grid.len();
        self.world
            .set_route_budget(crate::game::work::route_work(&inputs, cells));
        for input in inputs {
            // Drive orders in range, and routes within that budget, are always taken.
            let _ = self.apply(input);
        }
    }

    /// Applies a change from outside to the world and records it (see `game::record`).
    fn apply(&mut self, input: WorldInput) -> Result<(), InputError> {
        self.world.apply(&input)?;
        self.recording.note(&self.world, input);
        Ok(())
    }

    /// Bounds the path search of the robot orders among `inputs` by what their request
    /// was charged (`game::work`), and says whether there is any.
    fn budget_routes(&mut self, inputs: &[WorldInput]) -> bool {
        let bound = crate::game::work::RequestBound(self.settings.max_command_work);
        let work = bound.work(inputs, self.world.arena.grid.len());
        self.world.set_route_budget(work);
        work > 0
    }

    /// One tick of the world, its team's halves timed into the metrics.
    fn step(&mut self) {
        self.feed_inputs();
        self.feed_policy();
        let seated = self.seated_poses();
        let mut started: Option<Instant> = None;
        let h = &self.histograms;
        self.world.step_marked(&mut |m| {
            let now = Instant::now();
            match m {
                StepMark::Tracker => {}
                StepMark::Planner => {
                    if let Some(t) = started {
                        h.tracker.observe((now - t).as_secs_f64());
                    }
                }
                StepMark::Planned => {
                    if let Some(t) = started {
                        h.planner.observe((now - t).as_secs_f64());
                    }
                }
            }
            started = Some(now);
        });
        self.count_walks(seated);
    }

    fn answer(&mut self, req: Request, realtime: bool, pending: &mut Option<PendingStep>) {
        match req {
            Request::Stop(_) | Request::Suspend => {}
            Request::Read { sight, answer } => {
                // A read sees the counts as they are now (the frame catches up when read).
                self.refresh_meta();
                let since = self.world.events().len() as u64;
                answer(Ok(&mut Reading::new(self, sight, since)));
            }
            Request::Apply { input, reply } => {
                let one = std::slice::from_ref(&input);
                let result = match self.recording.room_for(one) {
                    Err(full) => Err(full.into()),
                    Ok(()) => {
                        let searches = self.budget_routes(one);
                        off_the_workers(searches, || self.apply(input)).map_err(MatchError::Input)
                    }
                };
                let _ = reply.send(result);
            }
            Request::Step {
                inputs,
                ticks,
                what,
                answer,
            } => self.begin_step(inputs, ticks, what, answer, realtime, pending),
            Request::Join {
                name,
                team,
                client,
                reply,
            } => {
                let result = self.join(name, team, client);
                if result.is_ok() {
                    self.publish();
                }
                let _ = reply.send(result);
            }
            Request::Connect { token, reply } => {
                let seat = self.connect(&token);
                if seat.is_ok() {
                    self.publish(); // viewers see the player connected
                }
                let _ = reply.send(seat);
            }
            Request::Input {
                seat,
                generation,
                input,
                seq,
            } => {
                self.queue_input(seat, generation, input, seq);
            }
        }
    }

    /// Builds and publishes the frame of the world as it is now. O(agents + belief points).
    fn publish(&mut self) {
        let mut seats = SeatViews {
            opponents: vec![None; self.world.opponents.len()],
            robots: vec![None; self.world.robots.len()],
        };
        for (p, body) in self.players.iter().zip(&self.bodies) {
            let view = p.as_ref().map(|p| SeatView {
                name: p.name.clone(),
                connected: p.connected(),
                ack: p.applied,
            });
            let place = match body {
                AgentId::Opponent(i) => seats.opponents.get_mut(*i),
                AgentId::Robot(i) => seats.robots.get_mut(*i),
            };
            if let Some(place) = place {
                *place = view;
            }
        }
        let tick = self.world.tick;
        let finished = self.world.status == MatchStatus::Finished;
        let with_belief = tick == 0 || finished || tick >= self.last_belief_tick + BELIEF_EVERY;
        if with_belief {
            self.last_belief_tick = tick;
        }
        let frame = Frame::build(
            &self.world,
            &seats,
            self.published_seq,
            self.robot_tags,
            with_belief,
        );
        self.robot_tags = frame.robot_tags;
        self.published_seq = frame.last_seq;
        self.frames_published += 1;
        self.frame_stale = false;
        let frame = Arc::new(frame);
        // `send_replace` never fails nor waits, whoever (if anyone) is watching.
        self.frames.send_replace(frame.clone());
        if let Some(held) = &mut self.held {
            held.push(frame, &self.world);
            // A manual match has no real time to release its last frames by.
            if finished && self.meta.clock == Clock::Manual {
                held.flush();
            }
        }
        self.publish_summary();
    }

    /// Publishes the match as listings show it (players and spectators counted now).
    fn publish_summary(&mut self) {
        self.refresh_meta();
        self.summaries
            .send_replace(Arc::new(Summary::of(&self.world, &self.meta, &self.config)));
    }

    fn record(&mut self, took: Duration) {
        self.histograms.tick.observe(took.as_secs_f64());
        let overran = took > self.settings.tick_overrun;
        if self.overruns.len() == OVERRUN_WINDOW && self.overruns.pop_front() == Some(true) {
            self.overrun_count -= 1;
        }
        self.overruns.push_back(overran);
        if overran {
            self.overrun_count += 1;
            self.settings.metrics.tick_overruns.inc();
            // The first and then every 20th, so a struggling match does not flood the log.
            if self.overrun_count % 20 == 1 {
                tracing::warn!(
                    tick = self.world.tick,
                    took_ms = took.as_secs_f64() * 1e3,
                    overruns = self.overrun_count,
                    "tick overran its budget"
                );
            }
            if self.overrun_count >= OVERRUN_LIMIT && self.world.status == MatchStatus::Running {
                tracing::warn!(
                    "ending the match: {} of its last {} ticks overran",
                    self.overrun_count,
                    self.overruns.len()
                );
                let _ = self.apply(WorldInput::End(FinishReason::Overloaded));
                self.publish();
            }
        }
        let us = took.as_micros().min(u32::MAX as u128) as u32;
        if self.tick_us.len() < TICK_WINDOW {
            self.tick_us.push(us);
        } else {
            self.tick_us[self.tick_next] = us;
        }
        self.tick_next = (self.tick_next + 1) % TICK_WINDOW;
    }

    fn stats(&self) -> Stats {
        let mut v = self.tick_us.clone();
        v.sort_unstable();
        let pct = |q: f64| -> f64 {
            if v.is_empty() {
                0.0
            } else {
                v[((v.len() - 1) as f64 * q).round() as usize] as f64
            }
        };
        Stats {
            tick: self.world.tick,
            ticks_measured: v.len(),
            tick_us_p50: pct(0.5),
            tick_us_p99: pct(0.99),
            tick_us_max: v.last().copied().unwrap_or(0) as f64,
            tick_us_mean: if v.is_empty() {
                0.0
            } else {
                v.iter().map(|x| *x as f64).sum::<f64>() / v.len() as f64
            },
            late_ticks: self.late_ticks,
            longest_tick_gap_ms: self.longest_tick_gap.as_secs_f64() * 1e3,
            frames_published: self.frames_published,
            spectators: self.spectators.load(Ordering::Relaxed),
            players_connected: self
                .players
                .iter()
                .flatten()
                .filter(|p| p.connected())
                .count(),
        }
    }

    fn refresh_meta(&mut self) {
        self.meta.players = self.players.iter().flatten().count();
        self.meta.spectators = self.spectators.load(Ordering::Relaxed);
        self.meta.free_slots = self.free_seats(Team::Opponents);
        self.meta.free_pursuer_slots = self.free_seats(Team::Robots);
    }

    /// Notices dropped players (they stand still), frees the slots of those gone too long,
    /// and says when the match should go: `finished` (its grace is over) or `abandoned`.
    fn housekeeping(&mut self) -> Option<&'static str> {
        let now = Instant::now();
        if self.world.status == MatchStatus::Finished {
            // The grace starts once spectators have seen the end.
            if self.held.as_ref().is_none_or(HeldBack::drained) {
                let at = *self.finished_at.get_or_insert(now);
                if now - at >= self.settings.finished_grace {
                    tracing::info!("removing the match: finished {:?} ago", now - at);
                    return Some("finished");
                }
            }
        } else if self.meta.clock == Clock::Manual
            && now - self.last_change >= self.settings.idle_manual_after
        {
            tracing::info!(
                "ending the match: a manual match unchanged for {:?}",
                now - self.last_change
            );
            let _ = self.apply(WorldInput::End(FinishReason::Abandoned));
            self.publish();
            return Some("idle");
        } else if self.abandoned(now) {
            tracing::info!(
                "ending the match: abandoned (no client for {:?})",
                now - self.last_activity
            );
            let _ = self.apply(WorldInput::End(FinishReason::Abandoned));
            self.publish();
            if let Some(held) = &mut self.held {
                held.flush();
            }
            return Some("abandoned");
        }
        let mut changed = false;
        // Told once the slot is free and published: a client that hears of the lapse and
        // looks at the lobby finds the slot there.
        let mut kicks = Vec::new();
        for seat in 0..self.players.len() {
            let body = self.bodies[seat];
            let Some(p) = self.players[seat].as_mut() else {
                continue;
            };
            let dropped = p.kick.as_ref().is_some_and(|k| k.is_closed());
            if dropped {
                p.kick = None;
                p.away_since = Some(now);
                tracing::info!(player = %p.name, %body, "player dropped");
            }
            // A slot nobody has played lapses `join_hold` after the join, connected or
            // not; a played one `reconnect_grace` after its player dropped.
            let lapsed = !p.played && now - p.joined_at >= self.settings.join_hold;
            let gone = lapsed
                || p.away_since
                    .is_some_and(|t| now - t >= self.settings.reconnect_grace);
            if dropped {
                self.set_keys(seat, HumanInput::default());
                changed = true;
            }
            if gone && let Some(mut p) = self.players[seat].take() {
                kicks.extend(p.kick.take());
                tracing::info!(player = %p.name, %body, lapsed, "player slot freed");
                self.unseat(seat, p.name.to_string());
                changed = true;
            }
        }
        if changed {
            self.publish();
        }
        for kick in kicks {
            let _ = kick.send("the slot lapsed: it was held without being played");
        }
        None
    }

    /// A match is abandoned when it has seats for people (human-controlled opponents or
    /// pursuer slots) and for
    /// `abandoned_after` nobody has been connected (player or spectator) and no request has
    /// come for it. Matches of bots and API-driven opponents are never abandoned: headless
    /// users may run them unattended until their time limit.
    fn abandoned(&mut self, now: Instant) -> bool {
        // Seats for people: human opponent slots, or robots of the team's pursuer slots.
        let human = self.world.config.pursuer_slots > 0
            || self
                .world
                .opponents
                .iter()
                .any(|o| matches!(o.control, Control::Human(_)));
        if !human {
            return false;
        }
        let someone = self.spectators.load(Ordering::Relaxed) > 0
            || self.players.iter().flatten().any(Player::connected);
        if someone {
            self.last_activity = now;
        }
        now - self.last_activity >= self.settings.abandoned_after
    }
}
