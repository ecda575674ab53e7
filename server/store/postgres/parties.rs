//! Parties' rooms in PostgreSQL: one row each, the room as one document; every server of a
//! fleet reads them at its start.

use ::postgres::Client;

use crate::store::backend::KeptParty;

pub(super) fn keep(c: &mut Client, party: &KeptParty) -> Result<(), ::postgres::Error> {
    c.execute(
        "INSERT INTO parties (code, doc) VALUES ($1, $2)
         ON CONFLICT (code) DO UPDATE SET doc = EXCLUDED.doc",
        &[&party.code, &party.doc],
    )?;
    Ok(())
}

pub(super) fn drop(c: &mut Client, code: &str) -> Result<(), ::postgres::Error> {
    c.execute("DELETE FROM parties WHERE code = $1", &[&code])?;
    Ok(())
}

pub(super) fn kept(c: &mut Client) -> Result<Vec<KeptParty>, ::postgres::Error> {
    c.query("SELECT code, doc FROM parties ORDER BY code", &[])?
        .iter()
        .map(|r| {
            Ok(KeptParty {
                code: r.try_get(0)?,
                doc: r.try_get(1)?,
            })
        })
        .collect()
}
