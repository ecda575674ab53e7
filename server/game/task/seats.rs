//! The people at a match: who holds which seat (an opponent slot, or a robot of the team's
//! pursuer slots), joining and connecting, and the numbered inputs each one's connection
//! sends, queued and applied one per tick.
//!
//! Seats are numbered: the opponent slots first (seat `i` is opponent `i`), then the robots
//! that are pursuer slots, in order ([`MatchTask::bodies`]).

use super::*;

/// Numbered inputs a player may have queued (ticks ahead of the match): a client whose
/// clock runs fast, or that sends a burst after a stall, would otherwise build up a lag of
/// its own; past this the oldest are merged away.
const MAX_QUEUED_INPUTS: usize = 8;

/// A person holding a seat.
#[derive(Debug)]
pub(super) struct Player {
    pub(super) id: String,
    pub(super) name: Arc<str>,
    /// The hash of the seat's token (the token itself went to the person who joined).
    pub(super) token: SecretHash,
    /// Bumped at every connection with this token; inputs from older ones are ignored.
    pub(super) generation: u64,
    /// Held while a connection plays this slot: its receiver is dropped when the
    /// connection ends (so the task notices), and sending on it closes an older connection.
    pub(super) kick: Option<oneshot::Sender<&'static str>>,
    /// Since when nobody plays this slot (joined but not connected yet, or dropped).
    pub(super) away_since: Option<Instant>,
    /// When it was joined: a slot not played `join_hold` later lapses.
    pub(super) joined_at: Instant,
    /// Whether a connection ever sent an input for it: until then the slot is only held,
    /// briefly, connected or not (an idle socket plays nothing).
    pub(super) played: bool,
    /// Who joined (for the few-unplayed-holds-per-client rule).
    pub(super) client: Option<ClientKey>,
    /// Its place in the seats its client holds over all matches.
    pub(super) _ledger: Option<crate::game::hub::LedgerSeat>,
    /// Numbered inputs not applied yet, oldest first, one per tick.
    pub(super) inputs: std::collections::VecDeque<(u64, HumanInput)>,
    /// The `seq` of the newest numbered input received, and of the last applied.
    pub(super) received: u64,
    pub(super) applied: u64,
    /// The keys last applied to a robot's seat (a robot's order holds until the next).
    pub(super) drive: Option<HumanInput>,
}

impl Player {
    pub(super) fn connected(&self) -> bool {
        self.kick.as_ref().is_some_and(|k| !k.is_closed())
    }
}

impl MatchTask {
    /// Seats the people a resumed match had (`game::resume`): each has the reconnect grace
    /// to come back with their token, from now, so the outage counts against nobody.
    pub(super) fn reseat(&mut self, seats: Vec<ResumedSeat>) {
        let now = Instant::now();
        for s in seats {
            let Some(place) = self.players.get_mut(s.seat) else {
                tracing::warn!(seat = s.seat, "a resumed seat the match does not have");
                continue;
            };
            let ledger = s
                .client
                .and_then(|c| self.settings.seats.take(c, usize::MAX).ok());
            *place = Some(Player {
                id: s.player_id,
                name: s.name.as_str().into(),
                token: s.token,
                generation: 0,
                kick: None,
                away_since: Some(now),
                joined_at: now,
                played: true,
                client: s.client,
                _ledger: ledger,
                inputs: Default::default(),
                received: 0,
                applied: 0,
                drive: None,
            });
        }
    }

    /// The seats people hold now, as the store keeps them to resume the match.
    pub(super) fn stored_seats(&self) -> Vec<crate::store::codec::StoredSeat> {
        self.players
            .iter()
            .enumerate()
            .filter_map(|(seat, p)| {
                let p = p.as_ref()?;
                Some(crate::store::codec::StoredSeat {
                    seat,
                    player_id: p.id.clone(),
                    name: p.name.to_string(),
                    token: p.token.to_hex(),
                    client: p.client.map(|c| c.to_string()),
                })
            })
            .collect()
    }

    /// Hands each player's next numbered input to the world: one per tick, in order. With
    /// none queued, the last one holds (keys still down).
    pub(super) fn feed_inputs(&mut self) {
        let mut keys = Vec::new();
        for (seat, p) in self.players.iter_mut().enumerate() {
            if let Some(p) = p
                && let Some((seq, input)) = p.inputs.pop_front()
            {
                p.applied = seq;
                keys.push((seat, input));
            }
        }
        for (seat, input) in keys {
            self.set_keys(seat, input);
        }
    }

    /// Where each seated person's opponent stands before a tick (see [`Self::count_walks`]).
    pub(super) fn seated_poses(&self) -> Vec<(usize, lasertag_core::sim::Pose)> {
        self.players
            .iter()
            .enumerate()
            .filter(|(_, p)| p.is_some())
            .filter_map(|(seat, _)| match self.bodies[seat] {
                AgentId::Opponent(slot) => Some((seat, self.world.opponents.get(slot)?.pose)),
                AgentId::Robot(_) => None,
            })
            .collect()
    }

    /// Adds what each seated person's opponent walked this tick to their name's part.
    pub(super) fn count_walks(&mut self, before: Vec<(usize, lasertag_core::sim::Pose)>) {
        for (seat, pose) in before {
            let (Some(Some(player)), AgentId::Opponent(slot)) =
                (self.players.get(seat), self.bodies[seat])
            else {
                continue;
            };
            if let Some(now) = self.world.opponents.get(slot) {
                let metres = (now.pose.pos - pose.pos).norm();
                self.people.walked(&player.name, metres);
            }
        }
    }

    /// The body each seat plays: opponent slots, then the robots that are pursuer slots.
    pub(super) fn bodies(world: &World) -> Vec<AgentId> {
        (0..world.opponents.len())
            .map(AgentId::Opponent)
            .chain(
                (0..world.robots.len())
                    .filter(|&r| world.robot_seat(r))
                    .map(AgentId::Robot),
            )
            .collect()
    }

    /// A person's keys for `seat`, applied (and recorded) when they change anything. On a
    /// robot they are its drive order (`WorldInput::RobotKeys`); a pressed trigger is given
    /// again each tick it is held (the device fires when it is ready).
    pub(super) fn set_keys(&mut self, seat: usize, input: HumanInput) {
        let input = crate::game::record::normalised(input);
        match self.bodies[seat] {
            AgentId::Opponent(slot) => {
                if self.world.human_input(slot) != Some(input) {
                    let _ = self.apply(WorldInput::Keys { slot, input });
                }
            }
            AgentId::Robot(robot) => {
                let Some(p) = self.players[seat].as_mut() else {
                    return;
                };
                // A robot's order holds until the next, so unchanged keys are not given
                // again; a held trigger is (the device fires once it is ready).
                if p.drive == Some(input) && !input.tag {
                    return;
                }
                p.drive = Some(input);
                let _ = self.apply(WorldInput::RobotKeys { robot, input });
            }
        }
    }

    /// A seated connection's keys: numbered ones are queued (one per tick, in order), others
    /// hold from the next tick. Ignored unless `generation` is the slot's current one.
    pub(super) fn queue_input(
        &mut self,
        seat: usize,
        generation: u64,
        input: HumanInput,
        seq: Option<u64>,
    ) {
        let Some(p) = self
            .players
            .get_mut(seat)
            .and_then(Option::as_mut)
            .filter(|p| p.generation == generation && p.connected())
        else {
            return;
        };
        p.played = true;
        match seq {
            None => self.set_keys(seat, input),
            // Late or repeated: already applied or queued.
            Some(s) if s <= p.received => {}
            Some(s) => {
                p.received = s;
                p.inputs.push_back((s, input));
                while p.inputs.len() > MAX_QUEUED_INPUTS {
                    // Merge the oldest into the next: its tag press is not lost.
                    if let Some((_, old)) = p.inputs.pop_front()
                        && let Some((_, next)) = p.inputs.front_mut()
                        && old.tag
                        && !next.tag
                    {
                        next.tag = true;
                        next.seen_tick = old.seen_tick;
                    }
                }
            }
        }
    }

    /// Whether a person may take `seat` now.
    pub(super) fn seat_free(&self, seat: usize) -> bool {
        if self.world.status != MatchStatus::Running || self.players[seat].is_some() {
            return false;
        }
        match self.bodies[seat] {
            AgentId::Opponent(i) => {
                let o = &self.world.opponents[i];
                !o.tagged
                    && match o.control {
                        Control::Human(_) => true,
                        Control::Bot(_) => self.meta.bots_joinable,
                        Control::Api(_) => false,
                    }
            }
            AgentId::Robot(_) => true,
        }
    }

    /// Free seats on `team`.
    pub(super) fn free_seats(&self, team: Team) -> usize {
        (0..self.players.len())
            .filter(|&i| self.seat_free(i) && Self::on(self.bodies[i], team))
            .count()
    }

    fn on(body: AgentId, team: Team) -> bool {
        matches!(
            (body, team),
            (AgentId::Opponent(_), Team::Opponents) | (AgentId::Robot(_), Team::Robots)
        )
    }

    /// Seats `joiner` (a name checked by `names`, and whether its claim's token was shown).
    pub(super) fn join(
        &mut self,
        joiner: crate::names::JoinName,
        team: Team,
        client: Option<ClientKey>,
    ) -> Result<Joined, MatchError> {
        let id = &self.meta.id;
        let name = joiner.name.as_str().to_string();
        if self.world.status == MatchStatus::Finished {
            return Err(MatchError::Finished(id.clone()));
        }
        let max = self.settings.max_players;
        if self.players.iter().flatten().count() >= max {
            self.settings.metrics.refuse(Refusal::PlayersFull);
            return Err(MatchError::Full(format!(
                "players: match {id} is at this server's limit of {max} per match"
            )));
        }
        // A slot joined but not played is held only briefly, and one client holds at most
        // one such slot at a time: otherwise a few anonymous requests keep every slot taken.
        if let Some(c) = client {
            let held = self
                .players
                .iter()
                .flatten()
                .filter(|p| p.client == Some(c) && !p.played)
                .count();
            if held >= self.settings.max_holds {
                self.settings.metrics.refuse(Refusal::ClientQuota);
                return Err(MatchError::Quota(format!(
                    "{c} holds {held} slot(s) of match {id} without playing them, its most; connect with a token, or wait {} s for a hold to lapse",
                    self.settings.join_hold.as_secs_f64()
                )));
            }
        }
        // One client plays one side of a match: a seat on each would show the hunted the
        // hunters' belief live (two people behind one address play on one side).
        if let Some(c) = client.filter(|_| !self.settings.both_sides)
            && let Some(other) = self
                .players
                .iter()
                .zip(&self.bodies)
                .find(|(p, body)| {
                    p.as_ref().is_some_and(|p| p.client == Some(c)) && !Self::on(**body, team)
                })
                .map(|(_, body)| *body)
        {
            self.settings.metrics.refuse(Refusal::ClientQuota);
            return Err(MatchError::Full(format!(
                "team: {c} plays {other} on the other side of match {id}; one address plays one side of a match"
            )));
        }
        let seat = (0..self.players.len())
            .find(|&i| self.seat_free(i) && Self::on(self.bodies[i], team))
            .ok_or_else(|| {
                MatchError::Full(match team {
                    Team::Opponents => format!("match {id} has no free opponent slot"),
                    Team::Robots => format!(
                        "team: match {id} has no free pursuer slot (its pursuer_slots are {})",
                        self.world.config.pursuer_slots
                    ),
                })
            })?;
        // Over every match too: a client takes at most a few seats at once.
        let ledger = match client {
            Some(c) => match self.settings.seats.take(c, self.settings.max_seats) {
                Ok(seat) => Some(seat),
                Err(held) => {
                    self.settings.metrics.refuse(Refusal::ClientQuota);
                    return Err(MatchError::Quota(format!(
                        "{c} holds {held} slot(s) on this server, its most; leave one first"
                    )));
                }
            },
            None => None,
        };
        let token = random_id(24);
        let player = Player {
            id: random_id(8),
            name: name.as_str().into(),
            token: SecretHash::of(&token),
            generation: 0,
            kick: None,
            away_since: Some(Instant::now()),
            joined_at: Instant::now(),
            played: false,
            client,
            _ledger: ledger,
            inputs: Default::default(),
            received: 0,
            applied: 0,
            drive: None,
        };
        let body = self.bodies[seat];
        tracing::info!(player = %player.name, %body, "player joined");
        let joined = Joined {
            player_id: player.id.clone(),
            body,
            token,
        };
        self.players[seat] = Some(player);
        self.people.joined(&name, joiner.claimed);
        let _ = self.apply(match body {
            AgentId::Opponent(slot) => WorldInput::Seat { slot, name },
            AgentId::Robot(robot) => WorldInput::SeatRobot { robot, name },
        });
        Ok(joined)
    }

    /// The person in `seat` leaves it (their body stands still, a bot kept aside comes back).
    pub(super) fn unseat(&mut self, seat: usize, name: String) {
        let _ = self.apply(match self.bodies[seat] {
            AgentId::Opponent(slot) => WorldInput::Unseat { slot, name },
            AgentId::Robot(robot) => WorldInput::UnseatRobot { robot, name },
        });
    }

    /// Seats a WebSocket connection on the seat `token` belongs to; an older connection with
    /// the same token is closed.
    pub(super) fn connect(&mut self, token: &str) -> Result<Seat, MatchError> {
        let seat = self
            .players
            .iter()
            .position(|p| p.as_ref().is_some_and(|p| p.token.matches(token)))
            .ok_or_else(|| {
                MatchError::NotAPlayer(format!("token: not a player of match {}", self.meta.id))
            })?;
        let Some(p) = self.players[seat].as_mut() else {
            return Err(MatchError::NotAPlayer("token: slot was freed".into()));
        };
        if let Some(old) = p.kick.take() {
            let _ = old.send("another connection took over this player");
        }
        let (kick, kicked) = oneshot::channel();
        p.kick = Some(kick);
        p.generation += 1;
        // A new connection numbers its inputs from 1 again.
        p.inputs.clear();
        p.received = 0;
        p.applied = 0;
        p.drive = None;
        p.away_since = None;
        let body = self.bodies[seat];
        tracing::info!(player = %p.name, %body, generation = p.generation, "player connected");
        Ok(Seat {
            seat,
            body,
            name: p.name.to_string(),
            generation: p.generation,
            kicked,
        })
    }
}
