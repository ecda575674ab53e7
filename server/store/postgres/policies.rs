//! Uploaded policies in PostgreSQL: one row each, the model as uploaded; servers of a fleet
//! uploading the same name at once meet at its primary key, and one keeps it.

use ::postgres::Client;

use super::convert::big;
use crate::store::backend::KeptPolicy;

/// Keeps `policy`; false, keeping nothing, when its name is kept already.
pub(super) fn keep(c: &mut Client, policy: &KeptPolicy) -> Result<bool, ::postgres::Error> {
    let added = c.execute(
        "INSERT INTO policies (name, model, token, client, decide_every, added_at)
         VALUES ($1, $2, $3, $4, $5, $6) ON CONFLICT (name) DO NOTHING",
        &[
            &policy.name,
            &policy.model,
            &policy.token,
            &policy.client,
            &big(policy.every),
            &policy.added_at,
        ],
    )?;
    Ok(added == 1)
}

pub(super) fn drop(c: &mut Client, name: &str) -> Result<(), ::postgres::Error> {
    c.execute("DELETE FROM policies WHERE name = $1", &[&name])?;
    Ok(())
}

/// The kept policies, oldest first: every one, or the one called `name`.
pub(super) fn kept(
    c: &mut Client,
    name: Option<&str>,
) -> Result<Vec<KeptPolicy>, ::postgres::Error> {
    c.query(
        "SELECT name, model, token, client, decide_every, added_at FROM policies
         WHERE $1::TEXT IS NULL OR name = $1 ORDER BY added_at, name",
        &[&name],
    )?
    .iter()
    .map(|r| {
        Ok(KeptPolicy {
            name: r.try_get(0)?,
            model: r.try_get(1)?,
            token: r.try_get(2)?,
            client: r.try_get(3)?,
            every: r.try_get::<_, i64>(4)?.max(0) as u64,
            added_at: r.try_get(5)?,
        })
    })
    .collect()
}
