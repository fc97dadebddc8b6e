//! Agents: the built-in scripted ones, submitted and built-in checkpoints, their specs.

use super::*;

/// Registers the scripted variants as built-in agents (idempotent).
pub async fn register_builtins(pool: &Pool) -> anyhow::Result<()> {
    for (name, _) in ::agents::scripted::variants() {
        sqlx::query("INSERT INTO agents (name, kind, spec, spec_hash, builtin) VALUES ($1, 'scripted', $2, $3, 1) ON CONFLICT (name) DO NOTHING")
            .bind(name)
            .bind(name)
            .bind(spec_hash(name))
            .execute(pool)
            .await?;
    }
    Ok(())
}

/// An agent row.
#[derive(Debug, Clone, Serialize, serde::Deserialize, FromRow)]
pub struct Agent {
    /// Id.
    pub id: i64,
    /// Unique name.
    pub name: String,
    /// What it is.
    pub kind: AgentKind,
    /// Hash of its spec.
    pub spec_hash: String,
    /// Registered by the server itself.
    #[sqlx(try_from = "super::Flag")]
    pub builtin: bool,
    /// When registered.
    pub created_at: String,
    /// Qualification episodes played.
    pub qual_episodes: Option<i64>,
    /// Qualification hit rate.
    pub hit_rate: Option<f64>,
    /// Qualification success rate.
    pub success_rate: Option<f64>,
    /// Qualification effort.
    pub effort: Option<f64>,
}

pub(super) const AGENT_COLUMNS: &str =
    "id, name, kind, spec_hash, builtin, created_at, qual_episodes, hit_rate, success_rate, effort";

/// All agents.
pub async fn agents(pool: &Pool) -> sqlx::Result<Vec<Agent>> {
    sqlx::query_as(&format!("SELECT {AGENT_COLUMNS} FROM agents ORDER BY id"))
        .fetch_all(pool)
        .await
}

/// One agent.
pub async fn agent(pool: &Pool, id: i64) -> sqlx::Result<Option<Agent>> {
    sqlx::query_as(&format!("SELECT {AGENT_COLUMNS} FROM agents WHERE id = $1"))
        .bind(id)
        .fetch_optional(pool)
        .await
}

/// The agent with a name.
pub async fn agent_by_name(pool: &Pool, name: &str) -> sqlx::Result<Option<Agent>> {
    sqlx::query_as(&format!(
        "SELECT {AGENT_COLUMNS} FROM agents WHERE name = $1"
    ))
    .bind(name)
    .fetch_optional(pool)
    .await
}

/// An agent's kind and spec (for playing it).
pub async fn agent_spec(pool: &Pool, id: i64) -> sqlx::Result<Option<(AgentKind, String)>> {
    sqlx::query_as("SELECT kind, spec FROM agents WHERE id = $1")
        .bind(id)
        .fetch_optional(pool)
        .await
}

/// Inserts a checkpoint agent (submitted, or built in) with its qualification.
pub async fn insert_checkpoint_agent(
    pool: &Pool,
    name: &str,
    spec: &str,
    qual: (usize, f64, f64, f64),
    builtin: bool,
    submitted_by: Option<i64>,
) -> sqlx::Result<i64> {
    sqlx::query_scalar(
        "INSERT INTO agents (name, kind, spec, spec_hash, qual_episodes, hit_rate, success_rate, effort, builtin, submitted_by) VALUES ($1, 'checkpoint', $2, $3, $4, $5, $6, $7, $8, $9) RETURNING id",
    )
    .bind(name)
    .bind(spec)
    .bind(spec_hash(spec))
    .bind(qual.0 as i64)
    .bind(qual.1)
    .bind(qual.2)
    .bind(qual.3)
    .bind(builtin as i64)
    .bind(submitted_by)
    .fetch_one(pool)
    .await
}
