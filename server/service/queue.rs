//! The queue's use cases: a person enters (their kept name's rating read from the store),
//! leaves, and, once a second, the groups the matchmaking forms are each seated in a match
//! against the robot team of their level ([`keep`]).

use std::sync::Arc;
use std::time::Duration;

use crate::access::ClientKey;
use crate::game::matchmaking::{Group, NEW_PLAYER_RATING, preset_for};
use crate::game::queue::{QueueError, Ticket, TicketView};
use crate::game::view::Team;
use crate::game::{MatchError, Registry};
use crate::protocol::fleet::Place;
use crate::protocol::parties::queue_match;
use crate::service::matches::{CreateError, Created, seat_all};
use crate::service::names::{NamesError, check_join};
use crate::service::{Pool, ReplayPool, Service};
use crate::store::StoreError;
use lasertag_core::difficulty::Difficulty;

#[derive(Debug, thiserror::Error)]
pub enum QueueRefused {
    #[error(transparent)]
    Queue(#[from] QueueError),
    #[error(transparent)]
    Name(#[from] NamesError),
}

/// `name` joins the queue: (ticket, token). A kept name (its token shown) waits at its
/// rating; any other at a newcomer's.
pub async fn enter(
    service: Service<'_>,
    client: ClientKey,
    name: &str,
    name_token: Option<&str>,
) -> Result<(String, String), QueueRefused> {
    let name = check_join(service, name, name_token).await?;
    let rating = if name.claimed {
        rating_of(service, name.name.as_str().to_string()).await
    } else {
        NEW_PLAYER_RATING
    };
    Ok(service.registry.queue.enter(name, client, rating)?)
}

/// A kept name's rating, or a newcomer's when it has none (or the store cannot say).
async fn rating_of(service: Service<'_>, name: String) -> f64 {
    let history = service.registry.history.clone();
    let read = service
        .pool
        .run("reading a rating", move || {
            let store = history.store().ok_or(StoreError::Closed)?;
            store.read(|b| b.player(&name))
        })
        .await;
    match read {
        Ok(Ok(Some(stats))) => stats.rating.map_or(NEW_PLAYER_RATING, |r| r.rating),
        _ => NEW_PLAYER_RATING,
    }
}

/// Forms groups once a second and seats each in a match of its own, for as long as the
/// server runs.
pub async fn keep(registry: Arc<Registry>, pool: Pool, replays: ReplayPool) {
    let mut every = tokio::time::interval(Duration::from_secs(1));
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    loop {
        tokio::select! {
            _ = every.tick() => {}
            _ = registry.shutdown.cancelled() => return,
        }
        let service = Service {
            registry: &registry,
            pool: &pool,
            replays: &replays,
            fleet: None,
        };
        for (group, tickets) in registry.queue.form() {
            if let Err(e) = seat(service, &group, &tickets).await {
                tracing::warn!(people = tickets.len(), "a queue group found no match: {e}");
                let why = format!("no match could start: {e}; queue again");
                for t in &tickets {
                    crate::game::queue::Queue::tell(t, TicketView::Gone(why.clone()));
                }
            }
        }
    }
}

/// Why a formed group was not seated.
#[derive(Debug, thiserror::Error)]
enum SeatError {
    #[error(transparent)]
    Create(#[from] CreateError),
    #[error("{0}")]
    Seat(MatchError),
}

/// Starts `group`'s match (people and the bots that fill for them against the preset of
/// their level) and tells each ticket its seat; nothing is left running when a seat cannot
/// be had.
async fn seat(service: Service<'_>, group: &Group, tickets: &[Ticket]) -> Result<(), SeatError> {
    let difficulty: Difficulty = preset_for(group.mean_rating);
    let body = queue_match(difficulty, tickets.len() + group.filled_by_bots)
        .map_err(CreateError::Invalid)?;
    let created =
        crate::service::matches::create(service, None, Place::Local, body, |_| None::<()>).await?;
    let Created::Here(created) = created else {
        return Err(SeatError::Seat(MatchError::Gone(String::new())));
    };
    let id = created.summary.id.clone();
    let people = tickets
        .iter()
        .map(|t| (t.name.clone(), Team::Opponents))
        .collect();
    let seats = seat_all(service, &id, people)
        .await
        .map_err(|u| SeatError::Seat(u.error))?;
    for (t, token) in tickets.iter().zip(seats) {
        crate::game::queue::Queue::tell(
            t,
            TicketView::Matched {
                match_id: id.clone(),
                token,
            },
        );
    }
    Ok(())
}
