//! A player's events: those it saw come live with its frames, the rest as late as
//! spectators get them, none twice and none lost (see the module docs of `http::ws`).

use std::sync::Arc;

use super::Connection;
use crate::game::Sight;
use crate::game::view::{Frame, Visible, event_seen};
use crate::http::socket::End;
use crate::protocol::ws as wire;
use lasertag_core::sim::AgentId;
use lasertag_core::world::{Event, MatchStatus};

impl Connection {
    /// The events since the last one sent, and `finished` once. A player (`sight`: its slot
    /// and what it sees in `frame`) gets those it saw now; the others come with the
    /// spectators' frames ([`Connection::deliver_held`]).
    pub(super) async fn deliver_events(
        &mut self,
        frame: &Frame,
        with_events: bool,
        sight: Option<&(AgentId, Visible)>,
    ) -> Result<(), End> {
        if with_events && frame.last_seq > self.last_seq {
            let mut events = Vec::new();
            if self.last_seq < frame.since_seq {
                // Frames were skipped while this client was slow: fetch what it missed.
                events = self.logged(self.last_seq, frame.since_seq).await;
            }
            let last = self.last_seq;
            events.extend(frame.events.iter().filter(|e| e.seq > last).cloned());
            for e in &events {
                match sight {
                    Some((you, v)) => {
                        if event_seen(e, v, *you) {
                            self.sock.text(wire::event_seen(e, v.anonymous)).await?;
                            self.sent_live.push_back(e.seq);
                        }
                    }
                    None => {
                        // A player gone over to watching has had some of these live.
                        if !self.already_sent(e.seq) {
                            self.sock.text(wire::event(e)).await?;
                        }
                    }
                }
            }
            self.last_seq = frame.last_seq;
        }
        if frame.status == MatchStatus::Finished && !self.finished_sent {
            if sight.is_some() {
                self.deliver_unseen(frame.last_seq).await?;
            }
            self.finished_sent = true;
            self.sock.text(wire::finished(frame)).await?;
        }
        Ok(())
    }

    /// Whether event `seq` came live already (and forgets those before it).
    pub(super) fn already_sent(&mut self, seq: u64) -> bool {
        while self.sent_live.front().is_some_and(|s| *s < seq) {
            self.sent_live.pop_front();
        }
        self.sent_live.front() == Some(&seq)
    }

    /// A player's share of a spectators' frame: the events up to it that it did not see
    /// live, and its belief.
    pub(super) async fn deliver_held(&mut self, shown: &Arc<Frame>) -> Result<(), End> {
        if !self.on_robot_team() {
            self.keep_belief(shown);
        }
        if shown.last_seq <= self.held_seq {
            return Ok(());
        }
        let mut events = Vec::new();
        if self.held_seq < shown.since_seq {
            // Released several frames at once, or skipped: the rest from the match's log.
            events = self.logged(self.held_seq, shown.since_seq).await;
        }
        let last = self.held_seq;
        events.extend(shown.events.iter().filter(|e| e.seq > last).cloned());
        self.send_unseen(&events).await?;
        self.held_seq = shown.last_seq;
        Ok(())
    }

    /// A player's events after `held_seq` up to `last` that it has not had: once the match
    /// has ended nothing is hidden, so they come before `finished`.
    async fn deliver_unseen(&mut self, last: u64) -> Result<(), End> {
        if last > self.held_seq {
            let events = self.logged(self.held_seq, last).await;
            self.send_unseen(&events).await?;
            self.held_seq = last;
        }
        Ok(())
    }

    /// `events` (in order), but those that came live.
    async fn send_unseen(&mut self, events: &[Event]) -> Result<(), End> {
        for e in events {
            if !self.already_sent(e.seq) {
                self.sock.text(wire::event(e)).await?;
            }
        }
        Ok(())
    }

    /// The match's events after `since` up to `last`, from its log.
    async fn logged(&mut self, since: u64, last: u64) -> Vec<Event> {
        let missed = self
            .handle
            .read(Sight::Live, move |r| Ok(r.events(since).to_vec()))
            .await
            .unwrap_or_default();
        missed.into_iter().filter(|e| e.seq <= last).collect()
    }
}
