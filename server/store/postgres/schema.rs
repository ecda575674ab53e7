//! PostgreSQL's side of the history's SQL: the schema, its migrations (under an advisory
//! lock, so servers starting together migrate once) and every statement the backend runs,
//! prepared once a connection.

use ::postgres::{Client, Statement};

use super::convert::db;
use crate::store::backend::StoreError;

/// The schema, one migration a step: step i takes version i to i + 1.
const MIGRATIONS: &[&str] = &[
    // 1: SQLite's tables with the writer of each match, and the writers' heartbeats.
    "CREATE TABLE maps (
        hash TEXT PRIMARY KEY,
        name TEXT NOT NULL,
        document TEXT NOT NULL
    );
    CREATE TABLE matches (
        seq BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
        id TEXT NOT NULL UNIQUE,
        writer TEXT NOT NULL,
        map TEXT NOT NULL,
        map_hash TEXT NOT NULL REFERENCES maps(hash),
        settings TEXT NOT NULL,
        started_at BIGINT NOT NULL,
        updated_at BIGINT NOT NULL,
        ended_at BIGINT,
        ticks BIGINT NOT NULL DEFAULT 0,
        winner TEXT,
        reason TEXT,
        complete BOOLEAN NOT NULL DEFAULT FALSE,
        names TEXT NOT NULL DEFAULT '[]',
        bytes BIGINT NOT NULL DEFAULT 0
    );
    CREATE INDEX matches_ended ON matches(ended_at);
    CREATE INDEX matches_map ON matches(map_hash);
    CREATE INDEX matches_running ON matches(writer) WHERE ended_at IS NULL;
    CREATE TABLE inputs (
        n BIGINT GENERATED ALWAYS AS IDENTITY PRIMARY KEY,
        seq BIGINT NOT NULL REFERENCES matches(seq) ON DELETE CASCADE,
        chunk BYTEA NOT NULL
    );
    CREATE INDEX inputs_by_match ON inputs(seq, n);
    CREATE TABLE players (
        seq BIGINT NOT NULL REFERENCES matches(seq) ON DELETE CASCADE,
        name TEXT NOT NULL,
        tags BIGINT NOT NULL,
        survived_ticks BIGINT NOT NULL,
        won BOOLEAN NOT NULL
    );
    CREATE INDEX players_by_name ON players(name);
    CREATE INDEX players_by_match ON players(seq);
    CREATE TABLE writers (
        id TEXT PRIMARY KEY,
        started_at TIMESTAMPTZ NOT NULL DEFAULT now(),
        seen_at TIMESTAMPTZ NOT NULL DEFAULT now()
    );",
    // 2: ratings (docs/ratings.md): each name's, and what each rated match did to it.
    "CREATE TABLE ratings (
        name TEXT PRIMARY KEY,
        rating DOUBLE PRECISION NOT NULL,
        deviation DOUBLE PRECISION NOT NULL,
        volatility DOUBLE PRECISION NOT NULL,
        matches BIGINT NOT NULL,
        updated_at BIGINT NOT NULL
    );
    CREATE INDEX ratings_by_age ON ratings(updated_at);
    ALTER TABLE players ADD COLUMN rating_before DOUBLE PRECISION,
                        ADD COLUMN rating_after DOUBLE PRECISION;",
    // 3: what resumes a running match (`codec::StoredLive`: owner, seats, token hashes).
    "ALTER TABLE matches ADD COLUMN live TEXT;",
    // 4: a running match's lease: its holder is `writer`; `fence` counts the times it changed
    // hands, and a holder writes only with the fence it took it at.
    "ALTER TABLE matches ADD COLUMN fence BIGINT NOT NULL DEFAULT 0;",
    // 5: running matches' checkpoints (`backend::Write::Checkpoint`), the newest few each.
    "CREATE TABLE checkpoints (
        seq BIGINT NOT NULL REFERENCES matches(seq) ON DELETE CASCADE,
        tick BIGINT NOT NULL,
        applied BIGINT NOT NULL,
        state BYTEA NOT NULL,
        PRIMARY KEY (seq, tick)
    );",
    // 6: names people keep (`backend::NameClaim`), by their look-alikes' key.
    "CREATE TABLE names (
        key TEXT PRIMARY KEY,
        name TEXT NOT NULL,
        token TEXT NOT NULL,
        client TEXT NOT NULL,
        claimed_at BIGINT NOT NULL
    );
    CREATE INDEX names_by_client ON names(client);",
    // 7: uploaded policies (`backend::KeptPolicy`): every server of a fleet can load them.
    "CREATE TABLE policies (
        name TEXT PRIMARY KEY,
        model BYTEA NOT NULL,
        token TEXT NOT NULL,
        client TEXT NOT NULL,
        decide_every BIGINT NOT NULL,
        added_at BIGINT NOT NULL
    );",
    // 8: parties' rooms (`backend::KeptParty`), so that a room and its tokens outlive the
    // server.
    "CREATE TABLE parties (
        code TEXT PRIMARY KEY,
        doc TEXT NOT NULL
    );",
];

/// The schema version this build writes.
pub const SCHEMA_VERSION: usize = MIGRATIONS.len();

/// The advisory lock servers migrate under, one at a time ("lasertag" in ASCII).
const MIGRATION_LOCK: i64 = 0x6c61_7365_7274_6167;

/// Brings the schema up to date, one transaction a step, under [`MIGRATION_LOCK`].
pub fn migrate(client: &mut Client) -> Result<(), StoreError> {
    loop {
        let mut tx = client.transaction().map_err(db)?;
        tx.execute("SELECT pg_advisory_xact_lock($1)", &[&MIGRATION_LOCK])
            .map_err(db)?;
        tx.batch_execute("CREATE TABLE IF NOT EXISTS lasertag_schema (version INTEGER NOT NULL)")
            .map_err(db)?;
        let version: i32 = tx
            .query_one("SELECT COALESCE(MAX(version), 0) FROM lasertag_schema", &[])
            .and_then(|r| r.try_get(0))
            .map_err(db)?;
        let version = usize::try_from(version).unwrap_or(0);
        if version > SCHEMA_VERSION {
            return Err(StoreError::NewerSchema {
                found: version,
                known: SCHEMA_VERSION,
            });
        }
        let Some(step) = MIGRATIONS.get(version) else {
            return tx.commit().map_err(db);
        };
        tx.batch_execute(step).map_err(db)?;
        let next = i32::try_from(version + 1).unwrap_or(i32::MAX);
        tx.execute("DELETE FROM lasertag_schema", &[]).map_err(db)?;
        tx.execute(
            "INSERT INTO lasertag_schema (version) VALUES ($1)",
            &[&next],
        )
        .map_err(db)?;
        tx.commit().map_err(db)?;
    }
}

const LISTED: &str = "SELECT id, map, started_at, ended_at, ticks, winner, reason, complete, names
                      FROM matches";

const STATS: &str = "SELECT p.name, COUNT(*), SUM(p.won::INT)::BIGINT, SUM(p.tags)::BIGINT,
                            MAX(p.survived_ticks), r.rating, r.deviation, r.matches
                     FROM players p LEFT JOIN ratings r ON r.name = p.name";
const BY_NAME: &str = "GROUP BY p.name, r.rating, r.deviation, r.matches";

/// Every statement, prepared once a connection.
pub(super) struct Statements {
    pub(super) begin_map: Statement,
    pub(super) begin_match: Statement,
    pub(super) append: Statement,
    pub(super) lose: Statement,
    pub(super) checkpoint: Statement,
    pub(super) forget_checkpoints: Statement,
    pub(super) load_checkpoints: Statement,
    pub(super) finish: Statement,
    pub(super) adopt: Statement,
    pub(super) hand_over: Statement,
    pub(super) load_running: Statement,
    pub(super) add_players: Statement,
    pub(super) evict: Statement,
    pub(super) forget_maps: Statement,
    pub(super) list: Statement,
    pub(super) load: Statement,
    pub(super) input_chunks: Statement,
    pub(super) totals: Statement,
    pub(super) player: Statement,
    pub(super) played: Statement,
    /// By [`LeaderOrder`]: wins, tags, survival, matches.
    pub(super) leaders: [Statement; 5],
    pub(super) rating_lock: Statement,
    pub(super) rating_of: Statement,
    pub(super) rate: Statement,
    pub(super) forget_ratings: Statement,
    pub(super) beat: Statement,
    pub(super) close_silent: Statement,
    pub(super) forget_writers: Statement,
}

impl Statements {
    pub(super) fn prepare(c: &mut Client) -> Result<Statements, ::postgres::Error> {
        let leaders = |c: &mut Client, only: &str, by: &str| {
            // Ties by name in byte order, as SQLite orders them.
            c.prepare(&format!(
                "{STATS} {only} {BY_NAME} ORDER BY {by}, p.name COLLATE \"C\" LIMIT $1"
            ))
        };
        Ok(Statements {
            begin_map: c.prepare(
                "INSERT INTO maps (hash, name, document) VALUES ($1, $2, $3)
                 ON CONFLICT (hash) DO NOTHING",
            )?,
            begin_match: c.prepare(
                "INSERT INTO matches (id, writer, map, map_hash, settings, started_at,
                                      updated_at, bytes, live)
                 VALUES ($1, $2, $3, $4, $5, $6, $6, $7, $8) ON CONFLICT (id) DO NOTHING",
            )?,
            // One round trip: appends are most of the writes. A match a silent-writer sweep
            // closed is open again once its writer speaks.
            append: c.prepare(
                "WITH m AS (
                   UPDATE matches SET ticks = $3, updated_at = $4, bytes = bytes + $5,
                          names = COALESCE($6, names), live = COALESCE($8, live),
                          ended_at = CASE WHEN complete THEN ended_at END
                   WHERE id = $1 AND writer = $2 AND fence = $9 RETURNING seq
                 ), chunk AS (
                   INSERT INTO inputs (seq, chunk) SELECT seq, $7::BYTEA FROM m
                   WHERE $7::BYTEA IS NOT NULL
                 )
                 SELECT seq FROM m",
            )?,
            lose: c.prepare(
                "UPDATE matches SET ended_at = updated_at, complete = FALSE, reason = 'lost'
                 WHERE id = $1 AND writer = $2 AND fence = $3 AND ended_at IS NULL",
            )?,
            // Only the match's holder stores one (the fence), and the older ones go with it.
            checkpoint: c.prepare(
                "WITH m AS (
                   SELECT seq FROM matches
                   WHERE id = $1 AND writer = $2 AND fence = $3 AND ended_at IS NULL
                 ), kept AS (
                   INSERT INTO checkpoints (seq, tick, applied, state)
                   SELECT seq, $4, $5, $6 FROM m
                   ON CONFLICT (seq, tick) DO UPDATE
                     SET applied = EXCLUDED.applied, state = EXCLUDED.state
                   RETURNING seq
                 ), gone AS (
                   DELETE FROM checkpoints c USING m WHERE c.seq = m.seq AND c.tick < $7
                 )
                 SELECT seq FROM kept",
            )?,
            forget_checkpoints: c.prepare(
                "DELETE FROM checkpoints WHERE seq = (SELECT seq FROM matches WHERE id = $1)",
            )?,
            load_checkpoints: c.prepare(
                "SELECT tick, applied, state FROM checkpoints
                 WHERE seq = (SELECT seq FROM matches WHERE id = $1) ORDER BY tick DESC",
            )?,
            finish: c.prepare(
                "UPDATE matches SET ended_at = $3, ticks = $4, winner = $5, reason = $6,
                        complete = TRUE
                 WHERE id = $1 AND writer = $2 AND fence = $7 RETURNING seq",
            )?,
            // Takes, in one statement, at most $3 running matches whose holder's lease has
            // run out (its writer silent for $2 s) or that were handed to this writer ($1)
            // and are not among those it runs ($4): each changes hands, its fence one up.
            // Rows another server is taking at the same moment are locked: skipped.
            adopt: c.prepare(
                "WITH picked AS (
                   SELECT seq FROM matches m
                   WHERE ended_at IS NULL
                     AND (m.writer = $1 AND NOT (m.id = ANY($4::TEXT[]))
                          OR m.writer <> $1 AND NOT EXISTS (
                            SELECT 1 FROM writers w WHERE w.id = m.writer
                              AND w.seen_at > now() - make_interval(secs => $2)))
                   ORDER BY seq LIMIT $3 FOR UPDATE SKIP LOCKED)
                 UPDATE matches m SET writer = $1, fence = m.fence + 1
                 FROM picked WHERE m.seq = picked.seq
                 RETURNING m.id, m.fence",
            )?,
            // Hands this writer's ($1) running matches to writer $2, each with its fence one
            // up (the handing writer's last writes are committed before it).
            hand_over: c.prepare(
                "UPDATE matches SET writer = $2, fence = fence + 1
                 WHERE writer = $1 AND ended_at IS NULL RETURNING id",
            )?,
            load_running: c.prepare(
                "SELECT m.id, m.map, m.started_at, m.ended_at, m.ticks, m.winner, m.reason,
                        m.complete, m.names, m.settings, maps.document,
                        ARRAY(SELECT chunk FROM inputs WHERE inputs.seq = m.seq ORDER BY n),
                        m.live
                 FROM matches m JOIN maps ON maps.hash = m.map_hash
                 WHERE m.id = $1 AND m.ended_at IS NULL",
            )?,
            add_players: c.prepare(
                "INSERT INTO players (seq, name, tags, survived_ticks, won, rating_before,
                                      rating_after)
                 SELECT $1, * FROM UNNEST($2::TEXT[], $3::BIGINT[], $4::BIGINT[],
                                          $5::BOOLEAN[], $6::FLOAT8[], $7::FLOAT8[])",
            )?,
            // Servers rating one name at once take turns: the row is locked until commit
            // (a new name's row is made first, with no matches, so that there is a row to
            // lock).
            rating_lock: c.prepare(
                "INSERT INTO ratings (name, rating, deviation, volatility, matches, updated_at)
                 VALUES ($1, $2, $3, $4, 0, $5) ON CONFLICT (name) DO NOTHING",
            )?,
            rating_of: c.prepare(
                "SELECT rating, deviation, volatility, matches FROM ratings WHERE name = $1
                 FOR UPDATE",
            )?,
            rate: c.prepare(
                "UPDATE ratings SET rating = $2, deviation = $3, volatility = $4,
                                    matches = matches + 1, updated_at = $5
                 WHERE name = $1",
            )?,
            forget_ratings: c.prepare(
                "DELETE FROM ratings WHERE name IN (
                   SELECT name FROM ratings ORDER BY updated_at, name
                   LIMIT GREATEST(0, (SELECT COUNT(*) FROM ratings) - $1)
                   FOR UPDATE SKIP LOCKED)",
            )?,
            // The newest matches are kept while both their count and their bytes fit.
            evict: c.prepare(
                "DELETE FROM matches WHERE seq IN (
                   SELECT seq FROM (
                     SELECT seq, ROW_NUMBER() OVER w AS k, (SUM(bytes) OVER w)::BIGINT AS total
                     FROM matches WHERE ended_at IS NOT NULL
                     WINDOW w AS (ORDER BY seq DESC)
                   ) ranked WHERE k > $1
                     OR total > $2 - (SELECT COALESCE(SUM(octet_length(model)), 0) FROM policies))",
            )?,
            // A map another server is storing a match with right now is locked: skipped.
            forget_maps: c.prepare(
                "DELETE FROM maps WHERE hash IN (
                   SELECT hash FROM maps m
                   WHERE NOT EXISTS (SELECT 1 FROM matches WHERE map_hash = m.hash)
                   FOR UPDATE SKIP LOCKED)",
            )?,
            list: c.prepare(&format!(
                "{LISTED} WHERE ended_at IS NOT NULL
                   AND ($3::TEXT IS NULL OR NOT starts_with(id, $3::TEXT))
                   AND (NOT EXISTS (SELECT 1 FROM matches
                                    WHERE id = $1::TEXT AND ended_at IS NOT NULL)
                        OR (ended_at, seq) < (SELECT ended_at, seq FROM matches
                                              WHERE id = $1::TEXT))
                 ORDER BY ended_at DESC, seq DESC LIMIT $2"
            ))?,
            // The chunks come in the same statement: an eviction between two reads cannot
            // leave a match without its inputs.
            load: c.prepare(
                "SELECT m.id, m.map, m.started_at, m.ended_at, m.ticks, m.winner, m.reason,
                        m.complete, m.names, m.settings, maps.document,
                        ARRAY(SELECT chunk FROM inputs WHERE inputs.seq = m.seq ORDER BY n)
                 FROM matches m JOIN maps ON maps.hash = m.map_hash
                 WHERE m.id = $1 AND m.ended_at IS NOT NULL",
            )?,
            input_chunks: c.prepare(
                "SELECT chunk FROM inputs
                 WHERE seq = (SELECT seq FROM matches WHERE id = $1 AND ended_at IS NOT NULL)
                 ORDER BY n LIMIT $2 OFFSET $3",
            )?,
            totals: c.prepare(
                "SELECT COUNT(*), COALESCE(SUM(bytes), 0)::BIGINT FROM matches
                 WHERE ended_at IS NOT NULL",
            )?,
            player: c.prepare(&format!("{STATS} WHERE p.name = $1 {BY_NAME}"))?,
            played: c.prepare(
                "SELECT m.id, m.map, m.started_at, m.ended_at, m.ticks, m.winner, m.reason,
                        m.complete, m.names, p.rating_before, p.rating_after
                 FROM players p JOIN matches m ON m.seq = p.seq
                 WHERE p.name = $1 ORDER BY m.seq DESC LIMIT $2",
            )?,
            leaders: [
                leaders(c, "", "SUM(p.won::INT) DESC, COUNT(*) ASC")?,
                leaders(c, "", "SUM(p.tags) DESC, COUNT(*) ASC")?,
                leaders(c, "", "MAX(p.survived_ticks) DESC")?,
                leaders(c, "", "COUNT(*) DESC")?,
                leaders(
                    c,
                    "WHERE r.rating IS NOT NULL AND r.matches > 0",
                    "r.rating - 2 * r.deviation DESC",
                )?,
            ],
            beat: c.prepare(
                "INSERT INTO writers (id) VALUES ($1)
                 ON CONFLICT (id) DO UPDATE SET seen_at = now()",
            )?,
            close_silent: c.prepare(
                "UPDATE matches SET ended_at = updated_at, complete = FALSE
                 WHERE ended_at IS NULL AND writer <> $1
                   AND NOT EXISTS (SELECT 1 FROM writers w WHERE w.id = matches.writer
                                   AND w.seen_at > now() - make_interval(secs => $2))",
            )?,
            forget_writers: c.prepare(
                "DELETE FROM writers w
                 WHERE seen_at < now() - make_interval(secs => $1)
                   AND NOT EXISTS (SELECT 1 FROM matches
                                   WHERE writer = w.id AND ended_at IS NULL)",
            )?,
        })
    }
}
