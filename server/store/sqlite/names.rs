//! Names people keep, in SQLite: a claim is checked and stored in one transaction on the
//! writer's connection, so two claims of look-alikes cannot both win.

use rusqlite::{Connection, OptionalExtension, params};

use super::rows::db;
use crate::store::backend::{ClaimLimits, ClaimOutcome, NameClaim, ReleaseOutcome, StoreError};

pub fn claim(
    conn: &mut Connection,
    claim: &NameClaim,
    limits: ClaimLimits,
) -> Result<ClaimOutcome, StoreError> {
    let tx = conn.transaction().map_err(db)?;
    if let Some(kept) = tx
        .query_row("SELECT name FROM names WHERE key = ?1", [&claim.key], |r| {
            r.get::<_, String>(0)
        })
        .optional()
        .map_err(db)?
    {
        return Ok(ClaimOutcome::Taken(kept));
    }
    let count = |sql: &str, args: &[&dyn rusqlite::ToSql]| -> Result<u64, StoreError> {
        tx.query_row(sql, args, |r| r.get::<_, i64>(0))
            .map(|n| n.max(0) as u64)
            .map_err(db)
    };
    if count(
        "SELECT COUNT(*) FROM names WHERE client = ?1",
        &[&claim.client],
    )? >= limits.per_client
    {
        return Ok(ClaimOutcome::ClientFull);
    }
    if count("SELECT COUNT(*) FROM names", &[])? >= limits.total {
        return Ok(ClaimOutcome::ServerFull);
    }
    tx.execute(
        "INSERT INTO names (key, name, token, client, claimed_at) VALUES (?1, ?2, ?3, ?4, ?5)",
        params![
            claim.key,
            claim.name,
            claim.token,
            claim.client,
            claim.claimed_at
        ],
    )
    .map_err(db)?;
    tx.commit().map_err(db)?;
    Ok(ClaimOutcome::Claimed)
}

pub fn release(
    conn: &mut Connection,
    key: &str,
    token: &str,
) -> Result<ReleaseOutcome, StoreError> {
    let tx = conn.transaction().map_err(db)?;
    let Some(kept) = claimed(&tx, key)? else {
        return Ok(ReleaseOutcome::NotClaimed);
    };
    if !crate::access::same_secret(&kept.token, token) {
        return Ok(ReleaseOutcome::WrongToken);
    }
    tx.execute("DELETE FROM names WHERE key = ?1", [key])
        .map_err(db)?;
    tx.execute("DELETE FROM ratings WHERE name = ?1", [&kept.name])
        .map_err(db)?;
    tx.commit().map_err(db)?;
    Ok(ReleaseOutcome::Released)
}

pub fn claimed(conn: &Connection, key: &str) -> Result<Option<NameClaim>, StoreError> {
    conn.query_row(
        "SELECT key, name, token, client, claimed_at FROM names WHERE key = ?1",
        [key],
        |r| {
            Ok(NameClaim {
                key: r.get(0)?,
                name: r.get(1)?,
                token: r.get(2)?,
                client: r.get(3)?,
                claimed_at: r.get(4)?,
            })
        },
    )
    .optional()
    .map_err(db)
}
