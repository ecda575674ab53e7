//! The queue: people who pressed *Play with others* wait here as tickets until
//! [`matchmaking`](crate::game::matchmaking) groups them; each ticket's socket is told how
//! long it has waited and how many are looking, then its seat. A ticket lives only while its
//! holder waits (a restart empties the queue: the page queues again by itself).

use std::collections::BTreeMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use tokio::sync::watch;

use crate::access::{ClientKey, SecretHash, random_id};
use crate::config::Config;
use crate::game::matchmaking::{Group, Pool, Rules};
use crate::names::JoinName;

/// What a ticket's socket shows.
#[derive(Debug, Clone, PartialEq)]
pub enum TicketView {
    Waiting {
        seconds: u64,
        people: usize,
    },
    /// Matched: the seat's token in `match_id`.
    Matched {
        match_id: String,
        token: String,
    },
    /// The queue could not seat it (the message says why), or it left.
    Gone(String),
}

/// A person waiting.
#[derive(Debug)]
pub struct Ticket {
    pub name: JoinName,
    pub client: ClientKey,
    token: SecretHash,
    view: watch::Sender<TicketView>,
}

/// Why the queue refused.
#[derive(Debug, thiserror::Error)]
pub enum QueueError {
    #[error("no ticket {0:?} in the queue")]
    NoTicket(String),
    #[error("that is not ticket {0}'s token")]
    WrongToken(String),
    #[error("this address holds {0} tickets in the queue already")]
    ClientFull(usize),
    #[error("the queue holds as many people as it may ({0}); try again shortly")]
    Full(usize),
}

/// The tickets waiting and the pool that groups them.
#[derive(Debug)]
pub struct Queue {
    inner: Mutex<Inner>,
    max: usize,
    per_client: usize,
}

#[derive(Debug)]
struct Inner {
    pool: Pool,
    tickets: BTreeMap<u64, Ticket>,
    /// The queue's own clock's origin (the pool takes time since it).
    origin: Instant,
}

impl Default for Queue {
    fn default() -> Queue {
        Queue::new(&Config::default())
    }
}

/// A ticket's id on the wire (a number is the pool's; a wire id says nothing about order).
pub fn ticket_name(id: u64) -> String {
    format!("q{id:016x}")
}

fn ticket_id(name: &str) -> Option<u64> {
    u64::from_str_radix(name.strip_prefix('q')?, 16).ok()
}

impl Queue {
    pub fn new(config: &Config) -> Queue {
        Queue {
            inner: Mutex::new(Inner {
                pool: Pool::new(Rules::default()),
                tickets: BTreeMap::new(),
                origin: Instant::now(),
            }),
            max: config.max_queued,
            per_client: config.max_queued_per_address,
        }
    }

    fn inner(&self) -> std::sync::MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// `name`, rated `rating`, joins the queue: (ticket, token).
    pub fn enter(
        &self,
        name: JoinName,
        client: ClientKey,
        rating: f64,
    ) -> Result<(String, String), QueueError> {
        let mut inner = self.inner();
        if inner.tickets.len() >= self.max {
            return Err(QueueError::Full(self.max));
        }
        let held = inner
            .tickets
            .values()
            .filter(|t| t.client == client)
            .count();
        if held >= self.per_client {
            return Err(QueueError::ClientFull(held));
        }
        // Random ids: a ticket's number is no guide to another's.
        let id = loop {
            let id = u64::from_str_radix(&random_id(8), 16).unwrap_or(0);
            if !inner.tickets.contains_key(&id) {
                break id;
            }
        };
        let token = random_id(16);
        let now = inner.origin.elapsed();
        inner.pool.join(id, rating, now);
        let people = inner.tickets.len() + 1;
        inner.tickets.insert(
            id,
            Ticket {
                name,
                client,
                token: SecretHash::of(&token),
                view: watch::Sender::new(TicketView::Waiting { seconds: 0, people }),
            },
        );
        Ok((ticket_name(id), token))
    }

    fn find(inner: &Inner, ticket: &str, token: &str) -> Result<u64, QueueError> {
        let id = ticket_id(ticket)
            .filter(|id| inner.tickets.contains_key(id))
            .ok_or_else(|| QueueError::NoTicket(ticket.to_string()))?;
        if !inner.tickets[&id].token.matches(token) {
            return Err(QueueError::WrongToken(ticket.to_string()));
        }
        Ok(id)
    }

    /// The ticket's changes, for its socket.
    pub fn watch(
        &self,
        ticket: &str,
        token: &str,
    ) -> Result<watch::Receiver<TicketView>, QueueError> {
        let inner = self.inner();
        let id = Queue::find(&inner, ticket, token)?;
        Ok(inner.tickets[&id].view.subscribe())
    }

    /// The ticket leaves the queue.
    pub fn leave(&self, ticket: &str, token: &str) -> Result<(), QueueError> {
        let mut inner = self.inner();
        let id = Queue::find(&inner, ticket, token)?;
        inner.pool.leave(id);
        if let Some(t) = inner.tickets.remove(&id) {
            t.view
                .send_replace(TicketView::Gone("left the queue".into()));
        }
        Ok(())
    }

    /// The groups that start now, each member's ticket taken out of the queue (the caller
    /// seats them and tells each through [`Queue::tell`]); the others are told how long
    /// they have waited.
    pub fn form(&self) -> Vec<(Group, Vec<Ticket>)> {
        let mut inner = self.inner();
        let now = inner.origin.elapsed();
        let groups = inner.pool.form(now);
        let formed = groups
            .into_iter()
            .map(|g| {
                let tickets = g
                    .members
                    .iter()
                    .filter_map(|id| inner.tickets.remove(id))
                    .collect();
                (g, tickets)
            })
            .collect();
        let people = inner.tickets.len();
        for (id, t) in &inner.tickets {
            let waited = inner.pool.waited(*id, now).unwrap_or(Duration::ZERO);
            t.view.send_replace(TicketView::Waiting {
                seconds: waited.as_secs(),
                people,
            });
        }
        formed
    }

    /// Tells the holder of `ticket` (taken out by [`Queue::form`]) what became of it.
    pub fn tell(ticket: &Ticket, view: TicketView) {
        ticket.view.send_replace(view);
    }

    pub fn waiting(&self) -> usize {
        self.inner().tickets.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::names::Name;
    use std::net::{IpAddr, Ipv4Addr};

    fn person(n: &str) -> JoinName {
        JoinName::unclaimed(Name::parse(n).unwrap())
    }

    fn client(n: u8) -> ClientKey {
        ClientKey::of(IpAddr::V4(Ipv4Addr::new(10, 0, 0, n)))
    }

    #[test]
    fn a_ticket_is_its_tokens_and_an_address_holds_few() {
        let q = Queue::default();
        let (a, token) = q.enter(person("a"), client(1), 1500.0).unwrap();
        q.enter(person("b"), client(1), 1500.0).unwrap();
        assert!(matches!(
            q.enter(person("c"), client(1), 1500.0),
            Err(QueueError::ClientFull(2))
        ));
        assert!(matches!(
            q.watch(&a, "nope"),
            Err(QueueError::WrongToken(_))
        ));
        assert!(matches!(
            q.watch("q1", &token),
            Err(QueueError::NoTicket(_))
        ));
        let mut rx = q.watch(&a, &token).unwrap();
        q.leave(&a, &token).unwrap();
        assert!(matches!(&*rx.borrow_and_update(), TicketView::Gone(_)));
        assert_eq!(q.waiting(), 1);
    }
}
