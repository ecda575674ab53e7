//! Every room of a server: made, joined, changed, started, swept; kept in the store on every
//! change; and what guessing codes costs each client.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::{Arc, Mutex};
use std::time::{Instant, SystemTime};

use tokio::sync::watch;

use super::room::{
    LAPSE, MAX_MEMBERS, MINUTES, Party, PartySettings, new_member, normalise_code, random_code,
};
use crate::access::{Bucket, ClientKey};
use crate::config::Config;
use crate::game::view::Team;
use crate::names::JoinName;
use crate::store::codec::PartyRecord;
use crate::store::{KeptParty, Write};
use lasertag_core::difficulty::Difficulty;

/// The seats a started match gave the members: what each member's socket tells its page.
#[derive(Debug, Clone)]
pub struct Started {
    pub match_id: String,
    /// Member id to (seat token, side).
    pub seats: BTreeMap<String, (String, Team)>,
    /// Counts the starts of this room, so that a socket tells each start once.
    pub serial: u64,
}

/// What a room's sockets are shown: the room, who is connected, and the last start.
#[derive(Debug, Clone)]
pub struct RoomView {
    pub party: Party,
    pub connected: BTreeSet<String>,
    pub started: Option<Arc<Started>>,
    /// Set when the room is gone (lapsed): its sockets close.
    pub gone: bool,
}

/// Why a party request was refused, in the party's words.
#[derive(Debug, thiserror::Error)]
pub enum PartyError {
    #[error("no party {0:?}")]
    NoParty(String),
    #[error("party {0} has no member {1:?}")]
    NoMember(String, String),
    #[error("party {0} is full ({MAX_MEMBERS} people)")]
    Full(String),
    #[error("that token is no member's of party {0}")]
    NotMember(String),
    #[error("only the host may {0}")]
    NotHost(&'static str),
    #[error("a member may change only their own {0}")]
    NotYours(&'static str),
    #[error("not ready: {0}")]
    NotReady(String),
    #[error("party {0} is playing; it waits again after its match")]
    Playing(String),
    #[error("the host cannot leave their own party; it lapses once nobody is connected")]
    HostLeaves,
    #[error("party codes looked up in vain too often from this address; try again in {0} s")]
    TooManyMisses(u64),
    #[error("this address hosts {0} parties already")]
    TooManyHosted(usize),
    #[error("the server holds as many parties as it may ({0})")]
    ServerFull(usize),
    #[error("{0}")]
    Invalid(String),
}

/// A change a member asks for (`PATCH …/members/{id}`).
#[derive(Debug, Clone, Default)]
pub struct Change {
    pub ready: Option<bool>,
    pub side: Option<Team>,
    pub map: Option<String>,
    pub difficulty: Option<Difficulty>,
    pub minutes: Option<u32>,
}

pub(super) struct Room {
    pub(super) party: Party,
    view: watch::Sender<RoomView>,
    /// Open sockets per member.
    sockets: BTreeMap<String, usize>,
    /// When somebody was last connected (now, while anybody is).
    seen: Instant,
    host_client: ClientKey,
    starts: u64,
    /// Held while the host's start builds the match, so that a second start waits out
    /// the first and finds the room playing.
    starting: bool,
}

impl Room {
    /// A room nobody is connected to yet, its lapse counted from now.
    fn new(party: Party, host_client: ClientKey) -> Room {
        Room {
            view: watch::Sender::new(RoomView {
                party: party.clone(),
                connected: BTreeSet::new(),
                started: None,
                gone: false,
            }),
            party,
            sockets: BTreeMap::new(),
            seen: Instant::now(),
            host_client,
            starts: 0,
            starting: false,
        }
    }

    fn publish(&self, started: Option<Option<Arc<Started>>>) {
        let connected = self.sockets.keys().cloned().collect();
        self.view.send_modify(|v| {
            v.party = self.party.clone();
            v.connected = connected;
            if let Some(s) = started {
                v.started = s;
            }
        });
    }
}

/// Every room of this server, and what guessing codes costs each client.
pub struct Parties {
    rooms: Mutex<HashMap<String, Room>>,
    misses: Mutex<HashMap<ClientKey, Bucket>>,
    max: usize,
    per_client: usize,
    misses_per_minute: f64,
    /// Where rooms are kept (none without a store: rooms then end with the process).
    history: Option<Arc<crate::game::replay::History>>,
}

impl Default for Parties {
    fn default() -> Parties {
        Parties::new(&Config::default(), None)
    }
}

impl std::fmt::Debug for Parties {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Parties").finish_non_exhaustive()
    }
}

impl Parties {
    pub fn new(config: &Config, history: Option<Arc<crate::game::replay::History>>) -> Parties {
        Parties {
            rooms: Mutex::default(),
            misses: Mutex::default(),
            max: config.max_parties,
            per_client: config.max_parties_per_address,
            misses_per_minute: config.party_misses_per_minute,
            history,
        }
    }

    pub(super) fn rooms(&self) -> std::sync::MutexGuard<'_, HashMap<String, Room>> {
        self.rooms.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Writes `room` to the store (never waits: a full queue loses this write, and the
    /// next change writes the room whole again).
    fn keep(&self, room: &Room) {
        if let Some(store) = self.history.as_ref().and_then(|h| h.store()) {
            let record = room.party.record(SystemTime::now());
            let write = Write::KeepParty(Box::new(KeptParty {
                code: record.code.clone(),
                doc: record.to_doc(),
            }));
            if store.send(write).is_err() {
                tracing::warn!(
                    party = room.party.code,
                    "the store's queue is full: room not kept now"
                );
            }
        }
    }

    /// Charges `client` for naming `code`, which names no room: an error once it has named
    /// too many.
    fn miss(&self, client: ClientKey, code: &str) -> PartyError {
        let mut misses = self.misses.lock().unwrap_or_else(|e| e.into_inner());
        let per_s = self.misses_per_minute / 60.0;
        let bucket = misses
            .entry(client)
            .or_insert_with(|| Bucket::new(self.misses_per_minute, per_s));
        match bucket.take() {
            Ok(()) => PartyError::NoParty(code.to_string()),
            Err(wait) => PartyError::TooManyMisses(wait.as_secs().max(1)),
        }
    }

    /// Refuses `client` while it has no misses left (so that a guesser's hits do not come
    /// for free either).
    fn check_misses(&self, client: ClientKey) -> Result<(), PartyError> {
        let mut misses = self.misses.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(bucket) = misses.get_mut(&client) {
            bucket.refill(Instant::now());
            let wait = bucket.wait_s(1.0);
            if wait > 0.0 {
                return Err(PartyError::TooManyMisses(wait.ceil() as u64));
            }
        }
        Ok(())
    }

    /// Runs `f` on room `code` as `client` names it (a miss is charged).
    fn with_room<T>(
        &self,
        code: &str,
        client: Option<ClientKey>,
        f: impl FnOnce(&mut Room) -> Result<T, PartyError>,
    ) -> Result<T, PartyError> {
        if let Some(c) = client {
            self.check_misses(c)?;
        }
        let found = normalise_code(code);
        let mut rooms = self.rooms();
        match found.as_deref().and_then(|c| rooms.get_mut(c)) {
            Some(room) => f(room),
            None => {
                drop(rooms);
                Err(match client {
                    Some(c) => self.miss(c, code),
                    None => PartyError::NoParty(code.to_string()),
                })
            }
        }
    }

    /// A new room hosted by `name`: (code, member id, member token).
    pub fn create(
        &self,
        name: JoinName,
        client: ClientKey,
        settings: PartySettings,
    ) -> Result<(String, String, String), PartyError> {
        let mut rooms = self.rooms();
        if rooms.len() >= self.max {
            return Err(PartyError::ServerFull(self.max));
        }
        let hosted = rooms.values().filter(|r| r.host_client == client).count();
        if hosted >= self.per_client {
            return Err(PartyError::TooManyHosted(hosted));
        }
        let code = loop {
            let code = random_code();
            if !rooms.contains_key(&code) {
                break code;
            }
        };
        let (member, token) = new_member(name, client, Team::Opponents);
        let party = Party {
            code: code.clone(),
            host: member.id.clone(),
            members: vec![member],
            settings,
            match_id: None,
        };
        let member_id = party.host.clone();
        let room = Room::new(party, client);
        self.keep(&room);
        rooms.insert(code.clone(), room);
        Ok((code, member_id, token))
    }

    /// `name` joins room `code`: (member id, member token).
    pub fn join(
        &self,
        code: &str,
        name: JoinName,
        client: ClientKey,
    ) -> Result<(String, String), PartyError> {
        let joined = self.with_room(code, Some(client), |room| {
            if room.party.members.len() >= MAX_MEMBERS {
                return Err(PartyError::Full(room.party.code.clone()));
            }
            let (member, token) = new_member(name, client, Team::Opponents);
            let id = member.id.clone();
            room.party.members.push(member);
            room.seen = Instant::now();
            room.publish(None);
            self.keep(room);
            Ok((id, token))
        })?;
        Ok(joined)
    }

    /// Room `code` as `client` asks for it.
    pub fn get(&self, code: &str, client: Option<ClientKey>) -> Result<RoomView, PartyError> {
        self.with_room(code, client, |room| Ok(room.view.borrow().clone()))
    }

    /// The member `token` belongs to in room `code`, and the room's changes to watch.
    pub fn subscribe(
        &self,
        code: &str,
        token: &str,
        client: ClientKey,
    ) -> Result<(String, watch::Receiver<RoomView>), PartyError> {
        self.with_room(code, Some(client), |room| {
            let member = member_holding(&room.party, token)?;
            Ok((member, room.view.subscribe()))
        })
    }

    /// A socket of `member` opened (`true`) or closed in room `code`.
    pub fn connected(&self, code: &str, member: &str, open: bool) {
        let _ = self.with_room(code, None, |room| {
            let n = room.sockets.entry(member.to_string()).or_default();
            if open {
                *n += 1;
            } else {
                *n = n.saturating_sub(1);
                if *n == 0 {
                    room.sockets.remove(member);
                }
            }
            room.seen = Instant::now();
            room.publish(None);
            Ok(())
        });
    }

    /// `change` to member `target` of room `code`, asked with `token`: a member changes their
    /// own ready and side; the host also anyone's side and the settings. `check` vets the
    /// settings (a map the server has).
    pub fn change(
        &self,
        code: &str,
        target: &str,
        token: &str,
        client: ClientKey,
        change: Change,
    ) -> Result<RoomView, PartyError> {
        self.with_room(code, Some(client), |room| {
            let party = &mut room.party;
            let by = member_holding(party, token)?;
            let host = by == party.host;
            if party.member(target).is_none() {
                return Err(PartyError::NoMember(party.code.clone(), target.to_string()));
            }
            if change.ready.is_some() && by != target {
                return Err(PartyError::NotYours("ready"));
            }
            if change.side.is_some() && by != target && !host {
                return Err(PartyError::NotYours("side"));
            }
            let settings =
                change.map.is_some() || change.difficulty.is_some() || change.minutes.is_some();
            if settings && !host {
                return Err(PartyError::NotHost("change the settings"));
            }
            if let Some(m) = change.minutes
                && !MINUTES.contains(&m)
            {
                return Err(PartyError::Invalid(format!(
                    "settings.minutes: {m} must be in {}..={}",
                    MINUTES.start(),
                    MINUTES.end()
                )));
            }
            if let Some(m) = party.members.iter_mut().find(|m| m.id == target) {
                if let Some(ready) = change.ready {
                    m.ready = ready;
                }
                if let Some(side) = change.side {
                    m.side = side;
                }
            }
            if let Some(map) = change.map {
                party.settings.map = map;
            }
            if let Some(d) = change.difficulty {
                party.settings.difficulty = d;
            }
            if let Some(m) = change.minutes {
                party.settings.minutes = m;
            }
            room.publish(None);
            self.keep(room);
            Ok(room.view.borrow().clone())
        })
    }

    /// Member `target` leaves room `code` (their own token) or the host removes them.
    pub fn remove(
        &self,
        code: &str,
        target: &str,
        token: &str,
        client: ClientKey,
    ) -> Result<RoomView, PartyError> {
        self.with_room(code, Some(client), |room| {
            let party = &mut room.party;
            let by = member_holding(party, token)?;
            if by != target && by != party.host {
                return Err(PartyError::NotHost("remove a member"));
            }
            if target == party.host {
                return Err(PartyError::HostLeaves);
            }
            let before = party.members.len();
            party.members.retain(|m| m.id != target);
            if party.members.len() == before {
                return Err(PartyError::NoMember(party.code.clone(), target.to_string()));
            }
            room.sockets.remove(target);
            room.publish(None);
            self.keep(room);
            Ok(room.view.borrow().clone())
        })
    }

    /// The host (`token`) starts room `code`: the room as it stands, for the caller to
    /// build the match from, once every member is ready. The room is held (no second start)
    /// until [`Parties::started`] or [`Parties::start_failed`].
    pub fn begin_start(
        &self,
        code: &str,
        token: &str,
        client: ClientKey,
    ) -> Result<Party, PartyError> {
        self.with_room(code, Some(client), |room| {
            let party = &room.party;
            if party.holder(token) != Some(party.host.as_str()) {
                return Err(PartyError::NotHost("start the match"));
            }
            if party.match_id.is_some() || room.starting {
                return Err(PartyError::Playing(party.code.clone()));
            }
            let waiting: Vec<&str> = party
                .members
                .iter()
                .filter(|m| !m.ready)
                .map(|m| m.name.name.as_str())
                .collect();
            if !waiting.is_empty() {
                return Err(PartyError::NotReady(waiting.join(", ")));
            }
            room.starting = true;
            Ok(party.clone())
        })
    }

    /// The start of room `code` failed: it waits as before.
    pub fn start_failed(&self, code: &str) {
        let _ = self.with_room(code, None, |room| {
            room.starting = false;
            Ok(())
        });
    }

    /// Room `code` plays `match_id`, each member in the seat of `seats` (member id to seat
    /// token and side): every member's socket is told theirs.
    pub fn started(&self, code: &str, match_id: &str, seats: BTreeMap<String, (String, Team)>) {
        let _ = self.with_room(code, None, |room| {
            room.starting = false;
            room.starts += 1;
            room.party.match_id = Some(match_id.to_string());
            let started = Arc::new(Started {
                match_id: match_id.to_string(),
                seats,
                serial: room.starts,
            });
            room.publish(Some(Some(started)));
            self.keep(room);
            Ok(())
        });
    }

    /// Rooms whose match is over (as `running` says of a match id) wait again, everyone
    /// not ready, same sides; rooms nobody was connected to for [`LAPSE`] go. Called about
    /// once a second.
    pub fn sweep(&self, now: Instant, running: impl Fn(&str) -> bool) {
        let mut rooms = self.rooms();
        let mut gone = Vec::new();
        for (code, room) in rooms.iter_mut() {
            if !room.sockets.is_empty() {
                room.seen = now;
            }
            if let Some(id) = &room.party.match_id
                && !running(id)
            {
                room.party.match_id = None;
                for m in &mut room.party.members {
                    m.ready = false;
                }
                room.publish(Some(None));
                self.keep(room);
            }
            // A party at play is not abandoned: its people are in the match.
            if room.party.match_id.is_none()
                && !room.starting
                && now.duration_since(room.seen) >= LAPSE
            {
                gone.push(code.clone());
            }
        }
        for code in gone {
            if let Some(room) = rooms.remove(&code) {
                room.view.send_modify(|v| v.gone = true);
                if let Some(store) = self.history.as_ref().and_then(|h| h.store()) {
                    let _ = store.send(Write::DropParty { code });
                }
            }
        }
        drop(rooms);
        let mut misses = self.misses.lock().unwrap_or_else(|e| e.into_inner());
        misses.retain(|_, b| {
            b.refill(now);
            !b.is_full()
        });
    }

    /// Takes back the rooms a store kept (at start, before anyone asks): each as it was,
    /// nobody connected yet, its lapse counted from now.
    pub fn restore(&self, kept: Vec<KeptParty>) -> usize {
        let mut rooms = self.rooms();
        let mut n = 0;
        for k in kept {
            let party = match PartyRecord::from_doc(&k.doc)
                .ok()
                .and_then(Party::from_record)
            {
                Some(p) => p,
                None => {
                    tracing::warn!(party = k.code, "a kept party could not be read: left out");
                    continue;
                }
            };
            let Some(host_client) = party.member(&party.host).map(|m| m.client) else {
                continue;
            };
            let room = Room::new(party, host_client);
            rooms.insert(k.code, room);
            n += 1;
        }
        n
    }

    pub fn len(&self) -> usize {
        self.rooms().len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The id of the member of `party` that `token` belongs to, or the refusal of a token that is
/// no member's.
fn member_holding(party: &Party, token: &str) -> Result<String, PartyError> {
    party
        .holder(token)
        .map(str::to_string)
        .ok_or_else(|| PartyError::NotMember(party.code.clone()))
}
