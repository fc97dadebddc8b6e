//! Storage: one store on two engines through sqlx's `Any` driver — SQLite (the default, embedded: a
//! file, WAL) or PostgreSQL 15 (`postgres://…`, for many `rally worker` processes on several
//! machines). The migrations are applied at start: `migrations/` on SQLite, `migrations/postgres/`
//! on PostgreSQL, the same versions and the same tables, columns and constraints (a test compares the
//! two schemas). Every state change of a match is one transaction. Runtime queries only (no
//! build-time database).
//!
//! The queries are written in the SQL both engines share: numbered parameters (`$1`), `RETURNING`
//! rather than SQLite's last row id, `ON CONFLICT … DO NOTHING` rather than `INSERT OR IGNORE`,
//! timestamps written by the process as text ([`now_text`]), booleans stored as 0/1 integers on both
//! (read through [`Flag`]), aggregates cast where PostgreSQL would answer `NUMERIC`. The few
//! statements that differ ([`Engine`]) are chosen at run time: the claim's `FOR UPDATE SKIP LOCKED`,
//! and the lock that serialises result storage on PostgreSQL.

use std::path::PathBuf;
use std::str::FromStr;

use serde::Serialize;
use sqlx::any::{AnyPoolOptions, AnyTypeInfo};
use sqlx::{Any, Decode, Executor, Type};

use ::agents::matchrun::MatchRecord;

pub use wire::{
    Agent, AgentCrossing, AgentDrift, AgentKind, Match, MatchStatus, Rally, RatingPoint, Sprt,
    SprtStatus, Tournament, WorkerStatus,
};

mod agents;
mod contests;
mod counts;
mod matches;
mod rows;
mod stats;
mod tokens;
pub mod workers;

pub use agents::*;
pub use contests::*;
pub use counts::*;
pub use matches::*;
use rows::{row, rows, Row};
pub use stats::*;
pub use tokens::*;
pub use workers::Lease;

/// A connection pool on either engine.
pub type Pool = sqlx::AnyPool;

/// Where the store lives: `--db data/rally.db` (a path, or `sqlite://PATH`) or
/// `--db postgres://USER:PASS@HOST:PORT/DB`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Location {
    /// An SQLite file (created if missing).
    Sqlite(PathBuf),
    /// A PostgreSQL database URL (the database must exist).
    Postgres(String),
}

impl FromStr for Location {
    type Err = String;

    fn from_str(s: &str) -> Result<Location, String> {
        let s = s.trim();
        if s.is_empty() {
            return Err("the database is empty: give a file path or a postgres:// URL".into());
        }
        if s.starts_with("postgres://") || s.starts_with("postgresql://") {
            let ok = url::Url::parse(s).is_ok_and(|u| u.host_str().is_some_and(|h| !h.is_empty()));
            if !ok {
                return Err(format!(
                    "{}: no host in the PostgreSQL URL (postgres://USER:PASS@HOST:PORT/DB)",
                    Location::Postgres(s.into())
                ));
            }
            return Ok(Location::Postgres(s.to_string()));
        }
        if let Some((scheme, _)) = s.split_once("://") {
            if scheme != "sqlite" {
                return Err(format!(
                    "{scheme}:// databases are not supported: give an SQLite file path or a postgres:// URL"
                ));
            }
        }
        let path = s.strip_prefix("sqlite://").unwrap_or(s);
        if path.contains('?') || path.contains('#') {
            return Err(format!("{path}: an SQLite path may not contain '?' or '#'"));
        }
        Ok(Location::Sqlite(PathBuf::from(path)))
    }
}

impl Location {
    /// The text that names this store on a command line (`--db`), password included.
    pub fn arg(&self) -> String {
        match self {
            Location::Sqlite(p) => p.display().to_string(),
            Location::Postgres(url) => url.clone(),
        }
    }
}

impl std::fmt::Display for Location {
    /// The path, or the URL with its password hidden (for logs and messages).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Location::Sqlite(p) => write!(f, "{}", p.display()),
            Location::Postgres(text) => match url::Url::parse(text) {
                Ok(mut u) if u.password().is_some() => {
                    let _ = u.set_password(Some("***"));
                    write!(f, "{u}")
                }
                _ => write!(f, "{text}"),
            },
        }
    }
}

impl<'de> serde::Deserialize<'de> for Location {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Location, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// The engine a pool talks to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Engine {
    /// SQLite.
    Sqlite,
    /// PostgreSQL.
    Postgres,
}

impl Engine {
    /// The engine of `pool`.
    pub fn of(pool: &Pool) -> Engine {
        match pool.connect_options().database_url.scheme() {
            "postgres" | "postgresql" => Engine::Postgres,
            _ => Engine::Sqlite,
        }
    }

    /// Its name (`sqlite`, `postgres`).
    pub fn name(self) -> &'static str {
        match self {
            Engine::Sqlite => "sqlite",
            Engine::Postgres => "postgres",
        }
    }
}

/// Opens the store at `location` and applies the migrations: an SQLite file is created if missing
/// (and its directory); a PostgreSQL database must exist.
pub async fn open(location: &Location) -> anyhow::Result<Pool> {
    sqlx::any::install_default_drivers();
    match location {
        Location::Sqlite(path) => {
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)?;
            }
            let url = format!("sqlite://{}?mode=rwc", path.display());
            let pool = AnyPoolOptions::new()
                .max_connections(8)
                .after_connect(|conn, _| {
                    Box::pin(async move {
                        conn.execute(
                            "PRAGMA journal_mode = WAL; PRAGMA foreign_keys = ON; PRAGMA busy_timeout = 10000;",
                        )
                        .await?;
                        Ok(())
                    })
                })
                .connect(&url)
                .await?;
            sqlx::migrate!("../migrations").run(&pool).await?;
            agents::rehash_specs(&pool).await?;
            agents::extract_training(&pool).await?;
            Ok(pool)
        }
        Location::Postgres(url) => {
            let pool = AnyPoolOptions::new()
                .max_connections(8)
                .acquire_timeout(std::time::Duration::from_secs(30))
                .connect(url)
                .await
                .map_err(|e| anyhow::anyhow!("{location}: {e}"))?;
            sqlx::migrate!("../migrations/postgres").run(&pool).await?;
            agents::rehash_specs(&pool).await?;
            agents::extract_training(&pool).await?;
            Ok(pool)
        }
    }
}

/// Creates database `name` on the PostgreSQL server that `admin_url` reaches (dropping a database of
/// that name first, with its connections) and returns the new database's URL. For tests and
/// benchmarks that need a fresh store each; `name` is letters, digits and `_`.
pub async fn recreate_postgres_database(admin_url: &str, name: &str) -> anyhow::Result<String> {
    use sqlx::Connection;
    anyhow::ensure!(
        !name.is_empty()
            && name.len() <= 63
            && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'),
        "{name}: a database name here is 1 to 63 letters, digits or '_'"
    );
    let Location::Postgres(_) = admin_url.parse::<Location>().map_err(anyhow::Error::msg)? else {
        anyhow::bail!("{admin_url}: not a postgres:// URL");
    };
    sqlx::any::install_default_drivers();
    let mut conn = sqlx::AnyConnection::connect(admin_url).await?;
    conn.execute(format!("DROP DATABASE IF EXISTS {name} WITH (FORCE)").as_str())
        .await?;
    conn.execute(format!("CREATE DATABASE {name}").as_str())
        .await?;
    conn.close().await?;
    let mut url = url::Url::parse(admin_url)?;
    url.set_path(&format!("/{name}"));
    Ok(url.to_string())
}

/// Makes the transaction `tx` the only one storing a result until it ends. SQLite has one writer at a
/// time anyway; on PostgreSQL two workers storing at once would both read the same last ratings
/// (and an SPRT's finished matches) and one update would be lost, so each takes the same
/// transaction-scoped advisory lock first and they take turns.
pub(crate) async fn serialise_writers(
    pool: &Pool,
    tx: &mut sqlx::Transaction<'_, Any>,
) -> sqlx::Result<()> {
    if Engine::of(pool) == Engine::Postgres {
        sqlx::query("SELECT 1 FROM (SELECT pg_advisory_xact_lock(7215)) AS held")
            .execute(&mut **tx)
            .await?;
    }
    Ok(())
}

/// Now, UTC, as the store's text timestamps write it (`YYYY-MM-DD HH:MM:SS`, SQLite's
/// `CURRENT_TIMESTAMP` format).
pub fn now_text() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs() as i64)
        .unwrap_or(0);
    timestamp_text(secs)
}

/// Unix seconds as `YYYY-MM-DD HH:MM:SS` (UTC; the proleptic Gregorian calendar).
pub fn timestamp_text(secs: i64) -> String {
    let t =
        time::OffsetDateTime::from_unix_timestamp(secs).unwrap_or(time::OffsetDateTime::UNIX_EPOCH);
    format!(
        "{:04}-{:02}-{:02} {:02}:{:02}:{:02}",
        t.year(),
        u8::from(t.month()),
        t.day(),
        t.hour(),
        t.minute(),
        t.second()
    )
}

/// A boolean column: stored as 0/1 on both engines (SQLite has no other), read as `bool` on either
/// (`#[sqlx(try_from = "Flag")]` on a `bool` field).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Flag(pub bool);

impl From<Flag> for bool {
    fn from(f: Flag) -> bool {
        f.0
    }
}

impl Type<Any> for Flag {
    fn type_info() -> AnyTypeInfo {
        <i64 as Type<Any>>::type_info()
    }

    fn compatible(ty: &AnyTypeInfo) -> bool {
        <i64 as Type<Any>>::compatible(ty) || <bool as Type<Any>>::compatible(ty)
    }
}

impl<'r> Decode<'r, Any> for Flag {
    fn decode(value: sqlx::any::AnyValueRef<'r>) -> Result<Flag, sqlx::error::BoxDynError> {
        match <i64 as Decode<Any>>::decode(value.clone()) {
            Ok(i) => Ok(Flag(i != 0)),
            Err(_) => <bool as Decode<Any>>::decode(value).map(Flag),
        }
    }
}

/// A stored word (a status, a kind) read back; a word the API does not know is a decoding error
/// naming the column.
pub(crate) fn word<W: FromStr<Err = String>>(text: &str, column: &str) -> sqlx::Result<W> {
    text.parse().map_err(|e: String| sqlx::Error::ColumnDecode {
        index: column.to_string(),
        source: format!("'{text}': {e}").into(),
    })
}

/// The SHA-256 of `text`, as 64 lowercase hex digits.
pub fn sha256_hex(text: &str) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(text.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// An agent's spec's identity: its SHA-256. Each side of a match records it when the match is
/// queued (a side whose agent's spec no longer has it is refused, not replayed with other weights),
/// and the workers' cache of built players is keyed by it: a collision would put one agent's
/// network in another's place, so it is a cryptographic hash.
pub fn spec_hash(spec: &str) -> String {
    sha256_hex(spec)
}

/// A fresh store for a unit test named `tag`: an SQLite file in the temporary directory, or a new
/// database on the PostgreSQL server of `RALLY_TEST_POSTGRES` when it is set (CI's second pass).
#[cfg(test)]
pub(crate) async fn test_store(tag: &str) -> Pool {
    let name = format!("rally_unit_{tag}_{}", std::process::id());
    let location = match std::env::var("RALLY_TEST_POSTGRES") {
        Ok(admin) if !admin.is_empty() => Location::Postgres(
            recreate_postgres_database(&admin, &name)
                .await
                .expect("a PostgreSQL test database"),
        ),
        _ => {
            let path = std::env::temp_dir().join(format!("{name}.db"));
            for suffix in ["", "-wal", "-shm"] {
                let _ = std::fs::remove_file(format!("{}{suffix}", path.display()));
            }
            Location::Sqlite(path)
        }
    };
    open(&location).await.expect("the test store opens")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Both engines' migrations, by version: (file name, SQLite text, PostgreSQL text).
    fn migration_pairs() -> Vec<(String, String, String)> {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../migrations");
        let mut names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.path().extension().is_some_and(|x| x == "sql"))
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        let pg: Vec<String> = {
            let mut v: Vec<String> = std::fs::read_dir(dir.join("postgres"))
                .unwrap()
                .filter_map(|e| e.ok())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect();
            v.sort();
            v
        };
        assert_eq!(names, pg, "the same migration versions on both engines");
        names
            .into_iter()
            .map(|n| {
                let read = |p: PathBuf| std::fs::read_to_string(p).unwrap();
                (
                    n.clone(),
                    read(dir.join(&n)),
                    read(dir.join("postgres").join(&n)),
                )
            })
            .collect()
    }

    /// A migration's statements without comments and blank space, PostgreSQL's types spelled as
    /// SQLite's (the only differences the PostgreSQL copies may have).
    fn statements(sql: &str, from_postgres: bool) -> Vec<String> {
        let mut text: String = sql
            .lines()
            .map(|l| l.split("--").next().unwrap_or(""))
            .collect::<Vec<_>>()
            .join(" ");
        if from_postgres {
            for (pg, lite) in [
                (
                    "BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY",
                    "INTEGER PRIMARY KEY AUTOINCREMENT",
                ),
                ("BIGINT", "INTEGER"),
                ("DOUBLE PRECISION", "REAL"),
                ("BYTEA", "BLOB"),
                (
                    "DEFAULT to_char(now() AT TIME ZONE 'UTC', 'YYYY-MM-DD HH24:MI:SS')",
                    "DEFAULT CURRENT_TIMESTAMP",
                ),
            ] {
                text = text.replace(pg, lite);
            }
        }
        text.split(';')
            .map(|s| s.split_whitespace().collect::<Vec<_>>().join(" "))
            .filter(|s| !s.is_empty())
            .collect()
    }

    #[test]
    fn the_postgres_migrations_are_the_sqlite_ones_in_postgres_types() {
        for (name, lite, pg) in migration_pairs() {
            assert_eq!(
                statements(&lite, false),
                statements(&pg, true),
                "migrations/postgres/{name} differs from migrations/{name} beyond the types"
            );
        }
    }

    #[test]
    fn locations_parse_and_hide_passwords() {
        let pg: Location = "postgres://rally:s3cret@db.lab:5432/rally".parse().unwrap();
        assert_eq!(
            pg,
            Location::Postgres("postgres://rally:s3cret@db.lab:5432/rally".into())
        );
        assert_eq!(pg.to_string(), "postgres://rally:***@db.lab:5432/rally");
        assert_eq!(
            "data/rally.db".parse::<Location>().unwrap(),
            Location::Sqlite("data/rally.db".into())
        );
        assert_eq!(
            "sqlite://x/y.db".parse::<Location>().unwrap(),
            Location::Sqlite("x/y.db".into())
        );
        for bad in ["", "mysql://h/db", "postgres:///db", "a?b.db"] {
            assert!(bad.parse::<Location>().is_err(), "{bad:?} accepted");
        }
        assert_eq!(timestamp_text(0), "1970-01-01 00:00:00");
        assert_eq!(timestamp_text(1_796_126_400), "2026-12-01 12:00:00");
    }

    /// The columns of every table as the engine reports them: (table, column, type family, not null).
    async fn columns(pool: &Pool) -> Vec<(String, String, String, bool)> {
        let family = |t: &str| -> String {
            let t = t.to_ascii_lowercase();
            if t.contains("int") {
                "integer"
            } else if t.contains("real") || t.contains("double") {
                "real"
            } else if t.contains("text") {
                "text"
            } else if t.contains("blob") || t.contains("bytea") {
                "blob"
            } else {
                "other"
            }
            .to_string()
        };
        let mut out = Vec::new();
        match Engine::of(pool) {
            Engine::Postgres => {
                let rows: Vec<(String, String, String, String)> = sqlx::query_as(
                    "SELECT table_name::text, column_name::text, data_type::text, is_nullable::text \
                     FROM information_schema.columns WHERE table_schema = 'public' AND table_name <> '_sqlx_migrations'",
                )
                .fetch_all(pool)
                .await
                .unwrap();
                for (t, c, ty, nullable) in rows {
                    out.push((t, c, family(&ty), nullable == "NO"));
                }
            }
            Engine::Sqlite => {
                let tables: Vec<String> = sqlx::query_scalar(
                    "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite_%' AND name <> '_sqlx_migrations'",
                )
                .fetch_all(pool)
                .await
                .unwrap();
                for t in tables {
                    let rows: Vec<(String, String, i64, i64)> = sqlx::query_as(&format!(
                        "SELECT name, type, \"notnull\", pk FROM pragma_table_info('{t}')"
                    ))
                    .fetch_all(pool)
                    .await
                    .unwrap();
                    for (c, ty, notnull, pk) in rows {
                        out.push((t.clone(), c, family(&ty), notnull == 1 || pk > 0));
                    }
                }
            }
        }
        out.sort();
        out
    }

    /// With `RALLY_TEST_POSTGRES` set (CI's second pass), both engines are migrated and report the
    /// same tables and columns, of the same type families and nullability.
    #[tokio::test]
    async fn both_engines_end_with_the_same_schema() {
        let Ok(admin) = std::env::var("RALLY_TEST_POSTGRES") else {
            eprintln!("RALLY_TEST_POSTGRES is not set: the SQLite side only");
            let lite = test_store("schema_lite").await;
            assert!(columns(&lite).await.len() > 50);
            return;
        };
        let path = std::env::temp_dir().join(format!("rally_schema_{}.db", std::process::id()));
        let _ = std::fs::remove_file(&path);
        let lite = open(&Location::Sqlite(path.clone())).await.unwrap();
        let url =
            recreate_postgres_database(&admin, &format!("rally_schema_{}", std::process::id()))
                .await
                .unwrap();
        let pg = open(&Location::Postgres(url)).await.unwrap();
        let (a, b) = (columns(&lite).await, columns(&pg).await);
        assert!(a.len() > 50, "{a:?}");
        assert_eq!(a, b);
    }
}
