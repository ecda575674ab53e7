//! A batch's writes as PostgreSQL statements: each [`Write`](crate::store::backend::Write) encoded
//! before the transaction begins, applied in it, and the eviction that follows a finish.

use ::postgres::Transaction;

use super::convert::big;
use super::schema::Statements;
use crate::store::backend::{Ended, Retention, StoreError};
use crate::store::ratings::{self, Rating};
use lasertag_core::difficulty::Difficulty;

/// A write, encoded before its transaction begins.
pub(super) enum Change<'a> {
    Begin {
        id: &'a str,
        map: &'a str,
        hash: String,
        document: String,
        settings: String,
        live: String,
        started_at: i64,
    },
    Append {
        id: &'a str,
        chunk: Option<Vec<u8>>,
        names: Option<String>,
        live: Option<String>,
        tick: i64,
    },
    Lost {
        id: &'a str,
    },
    Checkpoint {
        id: &'a str,
        tick: i64,
        applied: i64,
        keep_from: i64,
        state: Vec<u8>,
    },
    Finish {
        id: &'a str,
        ended: &'a Ended,
    },
}

impl<'a> Change<'a> {
    pub(super) fn of(
        w: &'a crate::store::backend::Write,
    ) -> Option<Result<Change<'a>, StoreError>> {
        use crate::store::backend::Write;
        Some(match w {
            Write::Begin {
                id,
                arena,
                settings,
                live,
                started_at,
            } => {
                let document = crate::maps::import::to_json(&crate::maps::to_file(&arena.def));
                serde_json::to_string(settings)
                    .map_err(|e| StoreError::Database(e.to_string()))
                    .map(|settings| Change::Begin {
                        id,
                        map: &arena.def.name,
                        hash: crate::store::backend::map_key(&document),
                        document,
                        settings,
                        live: live.to_json(),
                        started_at: crate::store::backend::unix_ms(*started_at),
                    })
            }
            Write::Append {
                id,
                inputs,
                names,
                live,
                tick,
            } => Ok(Change::Append {
                id,
                chunk: (!inputs.is_empty()).then(|| crate::store::codec::encode_inputs(inputs)),
                names: names
                    .as_ref()
                    .map(|n| serde_json::to_string(n).unwrap_or_else(|_| "[]".into())),
                live: live.as_ref().map(|l| l.to_json()),
                tick: big(*tick),
            }),
            Write::Finish { id, ended } => Ok(Change::Finish { id, ended }),
            Write::Lost { id } => Ok(Change::Lost { id }),
            Write::Checkpoint {
                id,
                tick,
                applied,
                keep_from,
                world,
                max_bytes,
            } => crate::store::backend::checkpoint_state(id, world, *max_bytes).map(|state| {
                Change::Checkpoint {
                    id,
                    tick: big(*tick),
                    applied: big(*applied),
                    keep_from: big((*keep_from).min(*tick)),
                    state,
                }
            }),
            Write::Flush(_)
            | Write::Adopt { .. }
            | Write::HandOver { .. }
            | Write::Claim { .. }
            | Write::Release { .. }
            | Write::KeepPolicy { .. }
            | Write::DropPolicy { .. }
            | Write::KeepParty(_)
            | Write::DropParty { .. } => return None,
        })
    }
}

/// Applies one change: `Err` when the database failed (the transaction is lost), `Ok(Err)`
/// when the change was refused (a match not stored, or another writer's).
pub(super) fn apply(
    tx: &mut Transaction<'_>,
    st: &Statements,
    writer: &str,
    fences: &std::collections::HashMap<String, i64>,
    change: &Change<'_>,
    now: i64,
) -> Result<Result<(), StoreError>, ::postgres::Error> {
    // The fence this writer holds a match at (0: it began it); a match it no longer holds
    // refuses the write.
    let fence = |id: &str| fences.get(id).copied().unwrap_or(0);
    match change {
        Change::Begin {
            id,
            map,
            hash,
            document,
            settings,
            live,
            started_at,
        } => {
            tx.execute(&st.begin_map, &[hash, map, document])?;
            // Each match counts its map's document as well (a map several matches share is
            // counted with each, so the history errs towards keeping less): stored maps
            // weigh in retention as they do on disk.
            let bytes = (settings.len() + document.len()) as i64;
            let added = tx.execute(
                &st.begin_match,
                &[id, &writer, map, hash, settings, started_at, &bytes, live],
            )?;
            Ok(if added == 0 {
                Err(StoreError::Duplicate(id.to_string()))
            } else {
                Ok(())
            })
        }
        Change::Append {
            id,
            chunk,
            names,
            live,
            tick,
        } => {
            let bytes = chunk.as_ref().map_or(0, |c| c.len() as i64);
            let found = tx.query_opt(
                &st.append,
                &[
                    id,
                    &writer,
                    tick,
                    &now,
                    &bytes,
                    names,
                    chunk,
                    live,
                    &fence(id),
                ],
            )?;
            Ok(match found {
                Some(_) => Ok(()),
                None => Err(StoreError::Unknown(id.to_string())),
            })
        }
        Change::Lost { id } => {
            if tx.execute(&st.lose, &[id, &writer, &fence(id)])? > 0 {
                tx.execute(&st.forget_checkpoints, &[id])?;
            }
            Ok(Ok(()))
        }
        Change::Checkpoint {
            id,
            tick,
            applied,
            keep_from,
            state,
        } => {
            let kept = tx.query_opt(
                &st.checkpoint,
                &[id, &writer, &fence(id), tick, applied, state, keep_from],
            )?;
            Ok(match kept {
                Some(_) => Ok(()),
                None => Err(StoreError::Unknown(id.to_string())),
            })
        }
        Change::Finish { id, ended } => {
            let ticks = big(ended.ticks);
            let Some(row) = tx.query_opt(
                &st.finish,
                &[
                    id,
                    &writer,
                    &ended.ended_at,
                    &ticks,
                    &ended.winner,
                    &ended.reason,
                    &fence(id),
                ],
            )?
            else {
                return Ok(Err(StoreError::Unknown(id.to_string())));
            };
            let seq: i64 = row.try_get(0)?;
            tx.execute(&st.forget_checkpoints, &[id])?;
            if !ended.players.is_empty() {
                let p = &ended.players;
                let names: Vec<&str> = p.iter().map(|p| p.name.as_str()).collect();
                let tags: Vec<i64> = p.iter().map(|p| i64::from(p.tags)).collect();
                let survived: Vec<i64> = p.iter().map(|p| big(p.survived_ticks)).collect();
                let won: Vec<bool> = p.iter().map(|p| p.won).collect();
                let mut before: Vec<Option<f64>> = vec![None; p.len()];
                let mut after: Vec<Option<f64>> = vec![None; p.len()];
                if let Some(preset) = ended.rated {
                    for (i, person) in p.iter().enumerate().filter(|(_, p)| p.rated) {
                        let (b, a) = rate(tx, st, &person.name, preset, person.won, now)?;
                        before[i] = Some(b.rating);
                        after[i] = Some(a.rating);
                    }
                }
                tx.execute(
                    &st.add_players,
                    &[&seq, &names, &tags, &survived, &won, &before, &after],
                )?;
            }
            Ok(Ok(()))
        }
    }
}

/// Rates `name` for one match against `preset`, with its row locked until the transaction
/// ends: answers (before, after). A new name past [`ratings::MAX_RATED_NAMES`] pushes out the
/// one rated longest ago.
fn rate(
    tx: &mut Transaction<'_>,
    st: &Statements,
    name: &str,
    preset: Difficulty,
    won: bool,
    now: i64,
) -> Result<(Rating, Rating), ::postgres::Error> {
    let new = Rating::newcomer();
    let made = tx.execute(
        &st.rating_lock,
        &[&name, &new.rating, &new.deviation, &new.volatility, &now],
    )?;
    let row = tx.query_one(&st.rating_of, &[&name])?;
    let before = Rating {
        rating: row.try_get(0)?,
        deviation: row.try_get(1)?,
        volatility: row.try_get(2)?,
    };
    let after = ratings::after(before, preset, won);
    tx.execute(
        &st.rate,
        &[
            &name,
            &after.rating,
            &after.deviation,
            &after.volatility,
            &now,
        ],
    )?;
    if made > 0 {
        tx.execute(&st.forget_ratings, &[&big(ratings::MAX_RATED_NAMES)])?;
    }
    Ok((before, after))
}

/// Deletes the oldest ended matches past `retention`, and the maps no match uses any more,
/// in a savepoint: an eviction that fails (two servers evicting at once) costs nothing else.
pub(super) fn evict(
    tx: &mut Transaction<'_>,
    st: &Statements,
    retention: Retention,
) -> Result<u64, ::postgres::Error> {
    let mut sp = tx.transaction()?;
    let evicted = sp.execute(
        &st.evict,
        &[&big(retention.max_matches), &big(retention.max_bytes)],
    )?;
    if evicted > 0 {
        sp.execute(&st.forget_maps, &[])?;
    }
    sp.commit()?;
    Ok(evicted)
}
