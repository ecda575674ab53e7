//! Names people keep, in PostgreSQL: each operation is one statement, so that servers of a
//! fleet claiming look-alikes at once meet at the key's unique index, and one wins.

use ::postgres::Client;

use super::convert::big;
use crate::store::backend::{ClaimLimits, ClaimOutcome, NameClaim, ReleaseOutcome};

pub(super) fn claim(
    c: &mut Client,
    claim: &NameClaim,
    limits: ClaimLimits,
) -> Result<ClaimOutcome, ::postgres::Error> {
    let row = c.query_one(
        "WITH kept AS (SELECT name FROM names WHERE key = $1),
              mine AS (SELECT COUNT(*) AS n FROM names WHERE client = $4),
              every AS (SELECT COUNT(*) AS n FROM names),
              added AS (
                INSERT INTO names (key, name, token, client, claimed_at)
                SELECT $1, $2, $3, $4, $5
                WHERE NOT EXISTS (SELECT 1 FROM kept)
                  AND (SELECT n FROM mine) < $6 AND (SELECT n FROM every) < $7
                ON CONFLICT (key) DO NOTHING
                RETURNING 1)
         SELECT (SELECT name FROM kept), (SELECT n FROM mine), (SELECT n FROM every),
                (SELECT COUNT(*) FROM added)",
        &[
            &claim.key,
            &claim.name,
            &claim.token,
            &claim.client,
            &claim.claimed_at,
            &big(limits.per_client),
            &big(limits.total),
        ],
    )?;
    let kept: Option<String> = row.try_get(0)?;
    let mine: i64 = row.try_get(1)?;
    let every: i64 = row.try_get(2)?;
    let added: i64 = row.try_get(3)?;
    Ok(match kept {
        Some(name) => ClaimOutcome::Taken(name),
        None if added > 0 => ClaimOutcome::Claimed,
        None if mine >= big(limits.per_client) => ClaimOutcome::ClientFull,
        None if every >= big(limits.total) => ClaimOutcome::ServerFull,
        // Another server's claim of the same key landed between the snapshot and the insert.
        None => ClaimOutcome::Taken(claim.name.clone()),
    })
}

pub(super) fn release(
    c: &mut Client,
    key: &str,
    token: &str,
) -> Result<ReleaseOutcome, ::postgres::Error> {
    // The statement's snapshot is taken before its deletes: `EXISTS` still sees the claim.
    let row = c.query_one(
        "WITH gone AS (DELETE FROM names WHERE key = $1 AND token = $2 RETURNING name),
              unrated AS (DELETE FROM ratings WHERE name IN (SELECT name FROM gone) RETURNING 1)
         SELECT (SELECT COUNT(*) FROM gone), EXISTS (SELECT 1 FROM names WHERE key = $1)",
        &[&key, &token],
    )?;
    let gone: i64 = row.try_get(0)?;
    let existed: bool = row.try_get(1)?;
    Ok(match (gone, existed) {
        (0, false) => ReleaseOutcome::NotClaimed,
        (0, true) => ReleaseOutcome::WrongToken,
        _ => ReleaseOutcome::Released,
    })
}

pub(super) fn claimed(c: &mut Client, key: &str) -> Result<Option<NameClaim>, ::postgres::Error> {
    c.query_opt(
        "SELECT key, name, token, client, claimed_at FROM names WHERE key = $1",
        &[&key],
    )?
    .map(|r| {
        Ok(NameClaim {
            key: r.try_get(0)?,
            name: r.try_get(1)?,
            token: r.try_get(2)?,
            client: r.try_get(3)?,
            claimed_at: r.try_get(4)?,
        })
    })
    .transpose()
}
