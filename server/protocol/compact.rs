//! Compact snapshots: the same content as the JSON `snapshot`, as a binary WebSocket message
//! for clients that ask for it (`?format=compact`, what the game page uses).
//!
//! JSON spends most of a spectator's bytes on digits: 181 scan ranges per robot and 480
//! belief points every 4th tick came to about 74 KiB/s. Here positions are centimetres in a
//! `u16` (maps are at most 500 m), headings a `u16` turn, scan ranges a byte each (1/32 m),
//! and the parts a viewer can do with less often come less often: scans and localisation
//! clouds every [`SLOW_EVERY`] ticks, the belief every [`BELIEF_COMPACT_EVERY`]. The page
//! keeps the last of each until the next arrives. `web/compact.js` is the decoder; the
//! layout is in docs/api.md ("Compact snapshots").
//!
//! All integers little-endian. A message is one snapshot:
//!
//! ```text
//! u8 kind = 1 | u8 flags | u32 tick | u16 time_left (1/10 s) | u32 ack | u8 you (index+1, 0)
//! u8 tags | u16 robot_tags | u8 opponents | u8 opponents_left | u8 robots_frozen
//! u8 robots, each: u8 index | u16 x | u16 y | u16 theta | u8 bits (frozen, goal, extras,
//!     slow, name)
//!     [goal: u16 x, y, theta] [extras: u16 estimate x, y, theta | u16 spread (mm)]
//!     [slow: u8 cloud points, each u16 x, y | u8 beams, each u8 range]
//!     [name: u8 bytes, UTF-8]
//! u8 opponents, each: u8 index | u16 x | u16 y | u16 theta | u8 bits (tagged, control ×2,
//!     name, connected, anonymous) [name: u8 bytes, UTF-8]
//!     (an anonymous sighting, in a person on the robot team's view: index 255, theta 0,
//!     bit 32 set, no control or name: where something is, not who or which way it faces)
//! [belief: u32 tick | u8 cell (cm) | u8 roles, each: u32 id | u8 count | u8 bits (tagged,
//!     state ×2) | u8 confidence (/255) | u32 particles | u16 mean x, y | points as cells]
//! ```
//!
//! A role's points go as cells [`BELIEF_CELL_CM`] wide, about 1.2 bytes each
//! ([`cells`]): as pairs of centimetres they would be most of what a spectator is sent.
//!
//! `flags`: 1 spectator view, 2 belief, 4 slow parts, 8 finished, 16 robots won, 32
//! opponents won, 64 `you` is a robot (a person on the robot team; else an opponent), 128
//! the teammates' view (a tagged player watching through its surviving teammates). A
//! robot's slow part comes when its `slow` bit is set: in a spectator's slow snapshots, and
//! for a person's own robot in their slow snapshots (its scan is their laser's view).
//!
//! A snapshot the same length as the one before it on the connection comes as a delta
//! against it ([`delta`], kind 2) when that is shorter: a WebSocket loses nothing and keeps
//! order, so the snapshot last written is one the client holds when the next arrives; that
//! is its acknowledgement, and no message of its own is needed (Fiedler's "Snapshot
//! Compression" acknowledges explicitly because it runs over UDP).
//!
//! ```text
//! u8 kind = 2 | u8 flags | u32 tick | u32 baseline tick | runs to the end, each:
//!     u8 same (bytes as in the baseline) | u8 n | n bytes (the snapshot's own)
//! ```
//!
//! Bytes after the last run are the baseline's.
//!
//! Over WebTransport snapshots go as datagrams, which may be lost or come out of order, so
//! the client says which it holds: an acknowledgement ([`Acks`]) names the newest tick it
//! holds and, in 32 bits, which of the 32 before it; a delta is against the newest snapshot
//! the server sent that the client last said it holds. A snapshot too large for a datagram
//! goes on the stream, its motion alone first as a datagram of kind 3 ([`KIND_MOTION`]):
//! laid out as kind 1, shown, never a baseline (the whole of that tick follows).

pub mod cells;

use crate::game::view::{BeliefView, Frame, Visible};
use lasertag_core::sim::AgentId;
use lasertag_core::world::{ControlKind, MatchStatus, Side};

/// The index an anonymous sighting of an opponent goes by (`o?`), its bits' 32 set.
pub const ANONYMOUS_INDEX: u8 = u8::MAX;

/// Scans and clouds come with every this many ticks' snapshot (5 Hz).
pub const SLOW_EVERY: u64 = 4;
/// The belief comes with every this many ticks' snapshot (2.5 Hz), when switched on.
pub const BELIEF_COMPACT_EVERY: u64 = 8;
/// The cells a belief's points are rounded to, centimetres: under the 7 cm squares the page
/// draws them as, so a point moves by at most 2 cm, a third of its square.
pub const BELIEF_CELL_CM: u8 = 4;

/// A coordinate in metres as centimetres, clamped to what a `u16` holds.
fn cm(v: f32) -> u16 {
    (v * 100.0).round().clamp(0.0, u16::MAX as f32) as u16
}

/// A heading in radians as a fraction of a turn.
fn turn(theta: f32) -> u16 {
    let t = theta.rem_euclid(std::f32::consts::TAU) / std::f32::consts::TAU;
    ((t * 65_536.0).round() as u32 % 65_536) as u16
}

struct Out(Vec<u8>);

impl Out {
    fn u8(&mut self, v: u8) {
        self.0.push(v);
    }
    fn u16(&mut self, v: u16) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn count(&mut self, n: usize) {
        self.u8(n.min(u8::MAX as usize) as u8);
    }
    /// A point already in centimetres.
    fn point(&mut self, p: [i32; 2]) {
        self.u16(p[0].clamp(0, u16::MAX as i32) as u16);
        self.u16(p[1].clamp(0, u16::MAX as i32) as u16);
    }
    fn pose(&mut self, x: f32, y: f32, theta: f32) {
        self.u16(cm(x));
        self.u16(cm(y));
        self.u16(turn(theta));
    }
}

/// The compact form of `frame` for a viewer: everything (`visible` is `None`), or what the
/// player of `you` sees; with `belief` when given (the frame's own for spectators, the
/// one spectators see for a player), and with the scans and clouds when `slow`
/// (spectators). Each connection decides when those are due ([`SLOW_EVERY`],
/// [`BELIEF_COMPACT_EVERY`]).
pub fn snapshot(
    frame: &Frame,
    you: Option<AgentId>,
    visible: Option<&Visible>,
    belief: Option<&BeliefView>,
    slow: bool,
) -> Vec<u8> {
    let you_robot = match you {
        Some(AgentId::Robot(i)) => Some(i),
        _ => None,
    };
    let spectator = visible.is_none();
    // Scans and clouds: a spectator's of every robot; a person's on the robot team of their
    // own robot (its scan is their view). An opponent's player gets none.
    let own_slow = slow && you_robot.is_some();
    let slow = spectator && slow;
    let mut o = Out(Vec::with_capacity(256));
    let mut flags = 0u8;
    if spectator {
        flags |= 1;
    }
    if visible.is_some_and(|v| v.teammates) {
        flags |= 128;
    }
    if belief.is_some() {
        flags |= 2;
    }
    if slow || own_slow {
        flags |= 4;
    }
    if frame.status == MatchStatus::Finished {
        flags |= 8;
    }
    match frame.winner {
        Some(Side::Robots) => flags |= 16,
        Some(Side::Opponents) => flags |= 32,
        None => {}
    }
    if you_robot.is_some() {
        flags |= 64;
    }
    o.u8(KIND_WHOLE);
    o.u8(flags);
    o.u32(frame.tick.min(u32::MAX as u64) as u32);
    let left = (frame.time_limit_s - frame.time_s).max(0.0) * 10.0;
    o.u16(left.round().min(u16::MAX as f64) as u16);
    let ack = match you {
        Some(AgentId::Opponent(i)) => frame.opponents.get(i).map_or(0, |p| p.ack),
        Some(AgentId::Robot(i)) => frame.robots.get(i).map_or(0, |r| r.ack),
        None => 0,
    };
    o.u32(ack.min(u32::MAX as u64) as u32);
    o.u8(you.map_or(0, |a| (a.index() + 1).min(u8::MAX as usize) as u8));
    o.count(frame.opponents.iter().filter(|p| p.tagged).count());
    o.u16(frame.robot_tags.min(u16::MAX as u32) as u16);
    o.count(frame.opponents.len());
    o.count(frame.opponents.iter().filter(|p| !p.tagged).count());
    o.count(frame.robots.iter().filter(|r| r.frozen).count());
    let robots = shown(&frame.robots, visible.map(|v| &v.robots[..]));
    o.count(robots.len());
    for (i, r) in robots {
        o.u8(i as u8);
        o.pose(r.pose.pos.x, r.pose.pos.y, r.pose.theta);
        let goal = r.goal.filter(|_| spectator);
        let slow = slow || (own_slow && you_robot == Some(i));
        let name = r
            .player
            .as_deref()
            .map(|n| &n.as_bytes()[..n.len().min(64)]);
        o.u8(r.frozen as u8
            | (goal.is_some() as u8) << 1
            | (spectator as u8) << 2
            | (slow as u8) << 3
            | (name.is_some() as u8) << 4);
        if let Some(g) = goal {
            o.pose(g.pos.x, g.pos.y, g.theta);
        }
        if spectator {
            o.pose(r.estimate.pos.x, r.estimate.pos.y, r.estimate.theta);
            o.u16((r.spread * 1000.0).round().clamp(0.0, u16::MAX as f32) as u16);
        }
        if slow {
            o.count(r.cloud.len());
            for p in r.cloud.iter().take(u8::MAX as usize) {
                o.point(*p);
            }
            o.count(r.scan.len());
            for v in r.scan.iter().take(u8::MAX as usize) {
                o.u8((v * 32.0).round().clamp(0.0, 255.0) as u8);
            }
        }
        if let Some(n) = name {
            o.count(n.len());
            o.0.extend_from_slice(n);
        }
    }
    let mut opponents = shown(&frame.opponents, visible.map(|v| &v.opponents[..]));
    let anonymous = visible.is_some_and(|v| v.anonymous);
    if anonymous {
        // In the order of where they are: the slots' order would tell who is who.
        opponents.sort_by(|(_, a), (_, b)| {
            let (a, b) = (a.pose.pos, b.pose.pos);
            a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y))
        });
    }
    o.count(opponents.len());
    for (i, p) in opponents {
        if anonymous {
            // Where something is, not who or which way it faces.
            o.u8(ANONYMOUS_INDEX);
            o.pose(p.pose.pos.x, p.pose.pos.y, 0.0);
            o.u8(p.tagged as u8 | 1 << 5);
            continue;
        }
        o.u8(i as u8);
        o.pose(p.pose.pos.x, p.pose.pos.y, p.pose.theta);
        let control = match p.control {
            ControlKind::Bot => 0u8,
            ControlKind::Api => 1,
            ControlKind::Human => 2,
        };
        let name = p
            .player
            .as_deref()
            .map(|n| &n.as_bytes()[..n.len().min(64)]);
        o.u8(p.tagged as u8
            | control << 1
            | (name.is_some() as u8) << 3
            | (p.connected as u8) << 4);
        if let Some(n) = name {
            o.count(n.len());
            o.0.extend_from_slice(n);
        }
    }
    if let Some(b) = belief {
        encode_belief(&mut o, b);
    }
    o.0
}

/// Kind byte of a whole snapshot and of a delta against the one before it.
pub const KIND_WHOLE: u8 = 1;
pub const KIND_DELTA: u8 = 2;
/// Kind byte of a snapshot's motion sent ahead of its whole (laid out as [`KIND_WHOLE`]):
/// the client shows it and keeps it as no baseline.
pub const KIND_MOTION: u8 = 3;

/// The tick of a compact message (whole, delta or motion), when it has one.
pub fn tick_of(message: &[u8]) -> Option<u32> {
    message
        .get(2..6)
        .map(|t| u32::from_le_bytes([t[0], t[1], t[2], t[3]]))
}

/// The tick of the baseline a delta is against.
pub fn baseline_of(delta: &[u8]) -> Option<u32> {
    tick_of(delta.get(4..)?)
}

/// Which snapshots a client holds, as it last said (over a carrier that may lose them): the
/// newest tick, and bit `i` for tick `newest - 1 - i`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Acks {
    pub newest: u32,
    pub bits: u32,
}

impl Acks {
    /// The length of an acknowledgement: `u32 newest | u32 bits`.
    pub const LEN: usize = 8;

    pub fn holds(&self, tick: u32) -> bool {
        match self.newest.checked_sub(tick) {
            Some(0) => true,
            Some(back @ 1..=32) => self.bits & (1 << (back - 1)) != 0,
            _ => false,
        }
    }

    /// An acknowledgement's bytes, as a client sends them; `None` when malformed.
    pub fn parse(bytes: &[u8]) -> Option<Acks> {
        let b: &[u8; Acks::LEN] = bytes.try_into().ok()?;
        Some(Acks {
            newest: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            bits: u32::from_le_bytes([b[4], b[5], b[6], b[7]]),
        })
    }

    pub fn to_bytes(self) -> [u8; Acks::LEN] {
        let mut b = [0u8; Acks::LEN];
        b[..4].copy_from_slice(&self.newest.to_le_bytes());
        b[4..].copy_from_slice(&self.bits.to_le_bytes());
        b
    }

    /// As an atomic's word (see [`Acks::from_word`]).
    pub fn to_word(self) -> u64 {
        u64::from(self.newest) << 32 | u64::from(self.bits)
    }

    pub fn from_word(word: u64) -> Acks {
        Acks {
            newest: (word >> 32) as u32,
            bits: word as u32,
        }
    }
}

/// `whole` (a whole snapshot) as a motion part sent ahead of it: kind [`KIND_MOTION`].
pub fn as_motion(mut whole: Vec<u8>) -> Vec<u8> {
    if let Some(kind) = whole.first_mut() {
        *kind = KIND_MOTION;
    }
    whole
}

/// `next` as a delta against `base` (both whole snapshots), when they are the same length
/// and the delta is shorter; `None` means send `next` whole.
pub fn delta(base: &[u8], next: &[u8]) -> Option<Vec<u8>> {
    if base.len() != next.len() || next.len() < 6 || base.len() < 6 {
        return None;
    }
    let mut o = Out(Vec::with_capacity(next.len() / 2));
    o.u8(KIND_DELTA);
    o.u8(next[1]);
    o.0.extend_from_slice(&next[2..6]);
    o.0.extend_from_slice(&base[2..6]);
    let n = next.len();
    let mut at = 0;
    loop {
        let start = at;
        while at < n && at - start < u8::MAX as usize && base[at] == next[at] {
            at += 1;
        }
        if at == n {
            break;
        }
        let same = at - start;
        let from = at;
        // A literal runs on over a single unchanged byte between changed ones: one byte
        // copied costs less than the two a new run would.
        while at < n
            && at - from < u8::MAX as usize
            && (base[at] != next[at] || (at + 1 < n && base[at + 1] != next[at + 1]))
        {
            at += 1;
        }
        o.u8(same as u8);
        o.u8((at - from) as u8);
        o.0.extend_from_slice(&next[from..at]);
        if o.0.len() >= n {
            return None;
        }
    }
    Some(o.0)
}

/// Why a delta could not be applied.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum DeltaError {
    #[error("not a delta message")]
    NotDelta,
    #[error("the delta is against tick {wanted}, the last snapshot held is tick {held}")]
    WrongBaseline { wanted: u32, held: u32 },
    #[error("the delta runs past the end of its baseline")]
    Overrun,
}

/// The whole snapshot a delta stands for, given the whole snapshot it is against (what a
/// client does; the page's copy is in `web/compact.js`).
pub fn apply_delta(base: &[u8], delta: &[u8]) -> Result<Vec<u8>, DeltaError> {
    if delta.first() != Some(&KIND_DELTA) || delta.len() < 10 {
        return Err(DeltaError::NotDelta);
    }
    let wanted = baseline_of(delta).ok_or(DeltaError::NotDelta)?;
    let held = tick_of(base).ok_or(DeltaError::Overrun)?;
    if wanted != held {
        return Err(DeltaError::WrongBaseline { wanted, held });
    }
    let mut out = base.to_vec();
    let mut at = 0;
    let mut i = 10;
    while i < delta.len() {
        let (same, n) = match delta.get(i..i + 2) {
            Some(h) => (h[0] as usize, h[1] as usize),
            None => return Err(DeltaError::Overrun),
        };
        i += 2;
        at += same;
        let bytes = delta.get(i..i + n).ok_or(DeltaError::Overrun)?;
        out.get_mut(at..at + n)
            .ok_or(DeltaError::Overrun)?
            .copy_from_slice(bytes);
        at += n;
        i += n;
    }
    Ok(out)
}

/// The agents a viewer is sent, with their indices: all, or those `visible` (at most 255,
/// what a count byte holds).
fn shown<'a, T>(agents: &'a [T], visible: Option<&[bool]>) -> Vec<(usize, &'a T)> {
    agents
        .iter()
        .enumerate()
        .filter(|(i, _)| visible.is_none_or(|v| v.get(*i).copied().unwrap_or(false)))
        .take(u8::MAX as usize)
        .collect()
}

fn encode_belief(o: &mut Out, b: &BeliefView) {
    o.u32(b.tick.min(u32::MAX as u64) as u32);
    o.u8(BELIEF_CELL_CM);
    o.count(b.roles.len());
    for r in b.roles.iter().take(u8::MAX as usize) {
        o.u32(r.id.min(u32::MAX as u64) as u32);
        o.count(r.count as usize);
        let state = match r.state {
            lasertag_core::tracker::Confidence::Valid => 0u8,
            lasertag_core::tracker::Confidence::Suspicious => 1,
            lasertag_core::tracker::Confidence::Invalid => 2,
        };
        o.u8(r.tagged as u8 | state << 1);
        o.u8((r.confidence.clamp(0.0, 1.0) * 255.0).round() as u8);
        o.u32(r.particles.min(u32::MAX as usize) as u32);
        o.u16(cm(r.mean[0]));
        o.u16(cm(r.mean[1]));
        cells::encode(&mut o.0, &r.points, u16::from(BELIEF_CELL_CM));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headings_and_coordinates_round_to_their_units() {
        assert_eq!(turn(0.0), 0);
        assert_eq!(turn(std::f32::consts::PI), 32_768);
        assert_eq!(turn(-std::f32::consts::FRAC_PI_2), 49_152);
        assert_eq!(turn(std::f32::consts::TAU - 1e-7), 0);
        assert_eq!(cm(12.344), 1234);
        assert_eq!(cm(-1.0), 0);
        assert_eq!(cm(1e6), u16::MAX);
    }

    #[test]
    fn acks_name_the_newest_tick_and_the_32_before_it() {
        let a = Acks {
            newest: 100,
            bits: 0b101,
        };
        assert!(a.holds(100) && a.holds(99) && !a.holds(98) && a.holds(97));
        assert!(!a.holds(101) && !a.holds(67));
        let all = Acks {
            newest: 100,
            bits: u32::MAX,
        };
        assert!(all.holds(68) && !all.holds(67));
        let early = Acks {
            newest: 3,
            bits: u32::MAX,
        };
        assert!(early.holds(0) && !early.holds(u32::MAX));
        assert_eq!(Acks::parse(&a.to_bytes()), Some(a));
        assert_eq!(Acks::from_word(a.to_word()), a);
        assert_eq!(Acks::parse(&[1, 2, 3]), None);
        assert_eq!(Acks::parse(&[0; 9]), None);
    }

    fn snapshot_like(tick: u32, tail: &[u8]) -> Vec<u8> {
        let mut v = vec![KIND_WHOLE, 0];
        v.extend_from_slice(&tick.to_le_bytes());
        v.extend_from_slice(tail);
        v
    }

    #[test]
    fn a_delta_gives_back_the_snapshot_it_stands_for() {
        let base = snapshot_like(7, &[9; 600]);
        let mut tail = vec![9u8; 600];
        // Changes alone, in pairs with one byte between, and a long changed stretch.
        tail[3] = 1;
        tail[10] = 2;
        tail[12] = 3;
        for b in &mut tail[300..500] {
            *b = 4;
        }
        tail[599] = 5;
        let next = snapshot_like(8, &tail);
        let d = delta(&base, &next).expect("a delta is shorter");
        assert!(d.len() < next.len() / 2, "{} bytes", d.len());
        assert_eq!(d[0], KIND_DELTA);
        assert_eq!(apply_delta(&base, &d), Ok(next.clone()));
        let other = snapshot_like(6, &[9; 600]);
        assert_eq!(
            apply_delta(&other, &d),
            Err(DeltaError::WrongBaseline { wanted: 7, held: 6 })
        );
        assert_eq!(
            apply_delta(&base, &d[..d.len() - 1]),
            Err(DeltaError::Overrun)
        );
    }

    #[test]
    fn a_beliefs_points_go_as_cells_behind_each_roles_header() {
        use crate::game::view::RoleView;
        let role = |id: u64, points: Vec<[i32; 2]>| RoleView {
            id,
            count: 1,
            tagged: false,
            confidence: 1.0,
            state: lasertag_core::tracker::Confidence::Valid,
            particles: 500,
            mean: [10.0, 5.0],
            points,
        };
        let cloud: Vec<[i32; 2]> = (0..200).map(|i| [990 + i % 20, 480 + i / 5]).collect();
        let b = BeliefView {
            tick: 40,
            roles: vec![role(3, cloud.clone()), role(4, vec![])],
        };
        let mut o = Out(Vec::new());
        encode_belief(&mut o, &b);
        let bytes = o.0;
        assert_eq!(bytes[..6], [40, 0, 0, 0, BELIEF_CELL_CM, 2]);
        // id, count, bits, confidence, particles, mean: 15 bytes, then the cells.
        let header = 6 + 15;
        let cell = u16::from(BELIEF_CELL_CM);
        let (points, len) = cells::decode(&bytes[header..], cell).expect("the first role's");
        assert_eq!(points.len(), cloud.len());
        assert!(
            len < cloud.len() * 2,
            "{len} bytes for {} points",
            cloud.len()
        );
        let second = header + len + 15;
        assert_eq!(bytes[second - 15..second - 11], 4u32.to_le_bytes());
        assert_eq!(cells::decode(&bytes[second..], cell), Ok((vec![], 2)));
        assert_eq!(bytes.len(), second + 2);
    }

    #[test]
    fn snapshots_that_differ_in_length_or_in_everything_go_whole() {
        let base = snapshot_like(1, &[0; 40]);
        assert_eq!(delta(&base, &snapshot_like(2, &[0; 41])), None);
        assert_eq!(delta(&base, &snapshot_like(2, &[1; 40])), None);
        let same = delta(&base, &snapshot_like(1, &[0; 40])).expect("nothing changed");
        assert_eq!(same.len(), 10);
        assert_eq!(apply_delta(&base, &same), Ok(base));
    }
}
