//! Storage: SQLite through sqlx (WAL), the `migrations/` applied at start. Every state change of a match
//! is one transaction. Runtime queries only (no build-time database).
//!
//! The queries are written in the SQL that SQLite and PostgreSQL share, the first step towards the
//! second engine (issue 12): numbered parameters (`$1`), `RETURNING id` rather than SQLite's last row
//! id, `ON CONFLICT … DO NOTHING` rather than `INSERT OR IGNORE`, timestamps cast to text, booleans
//! bound as integers.

use std::path::Path;
use std::str::FromStr;

use serde::Serialize;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions};
use sqlx::{FromRow, SqlitePool};

use ::agents::matchrun::MatchRecord;

pub use crate::domain::{AgentKind, MatchStatus, SprtStatus, WorkerStatus};

mod agents;
mod contests;
mod matches;
mod stats;
mod tokens;
pub mod workers;

pub use agents::*;
pub use contests::*;
pub use matches::*;
pub use stats::*;
pub use tokens::*;
pub use workers::Lease;

/// Opens (creating if needed) the database and applies the migrations.
pub async fn open(path: &Path) -> anyhow::Result<SqlitePool> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let opts = SqliteConnectOptions::from_str(&format!("sqlite://{}", path.display()))?
        .create_if_missing(true)
        .journal_mode(SqliteJournalMode::Wal)
        .foreign_keys(true)
        .busy_timeout(std::time::Duration::from_secs(10));
    let pool = SqlitePoolOptions::new()
        .max_connections(8)
        .connect_with(opts)
        .await?;
    sqlx::migrate!("../migrations").run(&pool).await?;
    Ok(pool)
}

/// A hex SHA-256-like digest of a spec (FNV-1a 64 over the bytes, printed twice salted; enough to tell
/// checkpoints apart and to recognise the same one again).
pub fn spec_hash(spec: &str) -> String {
    let fnv = |salt: u64| {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325 ^ salt;
        for b in spec.as_bytes() {
            h ^= *b as u64;
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
        h
    };
    format!("{:016x}{:016x}", fnv(0), fnv(0x9e37_79b9_7f4a_7c15))
}
