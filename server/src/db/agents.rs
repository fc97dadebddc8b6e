//! Agents: the built-in scripted ones, submitted and built-in checkpoints, their specs.

use super::*;

/// Registers the scripted variants as built-in agents of robot `model` (idempotent), named as
/// [`crate::arenas::builtin_name`] says. An `INSERT … SELECT … WHERE NOT EXISTS` rather than
/// `ON CONFLICT DO NOTHING`, which takes an id from the sequence even when it inserts nothing
/// (agent ids skipped three at every restart).
pub async fn register_builtins(pool: &Pool, model: &str) -> anyhow::Result<()> {
    for (variant, _) in ::agents::scripted::variants() {
        let name = crate::arenas::builtin_name(model, variant);
        let added = sqlx::query("INSERT INTO agents (name, kind, spec, spec_hash, builtin, model) SELECT $1, 'scripted', $2, $3, 1, $4 WHERE NOT EXISTS (SELECT 1 FROM agents WHERE lower(name) = lower($1))")
            .bind(&name)
            .bind(variant)
            .bind(spec_hash(variant))
            .bind(model)
            .execute(pool)
            .await?;
        if added.rows_affected() == 0 {
            if let Some(a) = agent_by_name(pool, &name).await? {
                if !a.builtin || a.model != model || a.kind != AgentKind::Scripted {
                    tracing::warn!(%name, robot = model, "another agent holds the name of a scripted built-in; keeping it (that robot's ratings have no anchor of that name)");
                }
            }
        }
    }
    Ok(())
}

pub(super) const AGENT_COLUMNS: &str = "id, name, kind, model, spec_hash, builtin, created_at, qual_episodes, hit_rate, success_rate, effort, retired_at";

/// All agents.
pub async fn agents(pool: &Pool) -> sqlx::Result<Vec<Agent>> {
    sqlx::query_as::<_, Row<Agent>>(&format!("SELECT {AGENT_COLUMNS} FROM agents ORDER BY id"))
        .fetch_all(pool)
        .await
        .map(rows)
}

/// The agents of robot `model`.
pub async fn agents_of(pool: &Pool, model: &str) -> sqlx::Result<Vec<Agent>> {
    sqlx::query_as::<_, Row<Agent>>(&format!(
        "SELECT {AGENT_COLUMNS} FROM agents WHERE model = $1 ORDER BY id"
    ))
    .bind(model)
    .fetch_all(pool)
    .await
    .map(rows)
}

/// One agent.
pub async fn agent(pool: &Pool, id: i64) -> sqlx::Result<Option<Agent>> {
    sqlx::query_as::<_, Row<Agent>>(&format!("SELECT {AGENT_COLUMNS} FROM agents WHERE id = $1"))
        .bind(id)
        .fetch_optional(pool)
        .await
        .map(row)
}

/// The agent with a name, in any case (names are unique regardless of case).
pub async fn agent_by_name(pool: &Pool, name: &str) -> sqlx::Result<Option<Agent>> {
    sqlx::query_as::<_, Row<Agent>>(&format!(
        "SELECT {AGENT_COLUMNS} FROM agents WHERE lower(name) = lower($1)"
    ))
    .bind(name)
    .fetch_optional(pool)
    .await
    .map(row)
}

/// The token an agent was submitted with (none: built in, or submitted with the admin token).
pub async fn agent_owner(pool: &Pool, id: i64) -> sqlx::Result<Option<i64>> {
    sqlx::query_scalar("SELECT submitted_by FROM agents WHERE id = $1")
        .bind(id)
        .fetch_optional(pool)
        .await
        .map(Option::flatten)
}

/// Retires agent `id` now; false if it was retired already (or does not exist).
pub async fn retire_agent(pool: &Pool, id: i64) -> sqlx::Result<bool> {
    let done =
        sqlx::query("UPDATE agents SET retired_at = $1 WHERE id = $2 AND retired_at IS NULL")
            .bind(now_text())
            .bind(id)
            .execute(pool)
            .await?;
    Ok(done.rows_affected() == 1)
}

/// An agent's kind and spec hash (to find its player kept built, without reading its spec).
pub async fn agent_kind_and_hash(
    pool: &Pool,
    id: i64,
) -> sqlx::Result<Option<(AgentKind, String)>> {
    let found: Option<(String, String)> =
        sqlx::query_as("SELECT kind, spec_hash FROM agents WHERE id = $1")
            .bind(id)
            .fetch_optional(pool)
            .await?;
    found
        .map(|(kind, hash)| Ok((word(&kind, "kind")?, hash)))
        .transpose()
}

/// An agent's kind and spec (for playing it).
pub async fn agent_spec(pool: &Pool, id: i64) -> sqlx::Result<Option<(AgentKind, String)>> {
    let found: Option<(String, String)> =
        sqlx::query_as("SELECT kind, spec FROM agents WHERE id = $1")
            .bind(id)
            .fetch_optional(pool)
            .await?;
    found
        .map(|(kind, spec)| Ok((word(&kind, "kind")?, spec)))
        .transpose()
}

/// Inserts a checkpoint agent (submitted, or built in) of robot `model` with its qualification.
#[allow(clippy::too_many_arguments)]
pub async fn insert_checkpoint_agent(
    pool: &Pool,
    name: &str,
    model: &str,
    spec: &str,
    qual: (usize, f64, f64, f64),
    builtin: bool,
    submitted_by: Option<i64>,
) -> sqlx::Result<i64> {
    sqlx::query_scalar(
        "INSERT INTO agents (name, kind, spec, spec_hash, qual_episodes, hit_rate, success_rate, effort, builtin, submitted_by, training_json, model) VALUES ($1, 'checkpoint', $2, $3, $4, $5, $6, $7, $8, $9, $10, $11) RETURNING id",
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
    .bind(training_of(spec))
    .bind(model)
    .fetch_one(pool)
    .await
}

/// The robot a checkpoint's JSON names (`model`; `default` when it names none), read without
/// keeping the rest; `None` when the text is not a JSON object with a text `model` or none.
pub fn model_of(spec: &str) -> Option<String> {
    #[derive(serde::Deserialize)]
    struct Part {
        #[serde(default)]
        model: Option<String>,
    }
    serde_json::from_str::<Part>(spec).ok().map(|p| {
        p.model
            .unwrap_or_else(|| sim::config::DEFAULT_ROBOT.to_string())
    })
}

/// A checkpoint's `training` section as compact JSON text, re-serialised from its fields (`null`
/// when it has none or the text is not a checkpoint's JSON): what validation bounded, whatever
/// space or digits the upload padded it with. The weights are skipped, not parsed.
pub fn training_of(spec: &str) -> String {
    #[derive(serde::Deserialize)]
    struct Part {
        #[serde(default)]
        training: Option<::agents::checkpoint::Training>,
    }
    serde_json::from_str::<Part>(spec)
        .ok()
        .and_then(|p| p.training)
        .and_then(|t| serde_json::to_string(&t).ok())
        .unwrap_or_else(|| "null".to_string())
}

/// A checkpoint agent's training provenance (its checkpoint's `training` section), if it has one.
pub async fn agent_training(pool: &Pool, id: i64) -> sqlx::Result<Option<serde_json::Value>> {
    let found: Option<(Option<String>,)> =
        sqlx::query_as("SELECT training_json FROM agents WHERE id = $1 AND kind = 'checkpoint'")
            .bind(id)
            .fetch_optional(pool)
            .await?;
    Ok(found
        .and_then(|(t,)| t)
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .filter(|t| !t.is_null()))
}

/// Fills in the training provenance of the checkpoint agents stored before it had a column of its
/// own (migration 0007), a few at a time, once: at every open it finds none left. Returns how many
/// it filled.
pub async fn extract_training(pool: &Pool) -> sqlx::Result<usize> {
    let mut filled = 0;
    loop {
        let batch: Vec<(i64, String)> = sqlx::query_as(
            "SELECT id, spec FROM agents WHERE kind = 'checkpoint' AND training_json IS NULL ORDER BY id LIMIT 16",
        )
        .fetch_all(pool)
        .await?;
        if batch.is_empty() {
            return Ok(filled);
        }
        for (id, spec) in &batch {
            sqlx::query("UPDATE agents SET training_json = $1 WHERE id = $2")
                .bind(training_of(spec))
                .bind(id)
                .execute(pool)
                .await?;
        }
        filled += batch.len();
    }
}

/// Rewrites the spec hashes of a store written before they were SHA-256 (32 hex digits then):
/// each such agent's, and each match side queued with that very hash, so that the matches still
/// replay (a side whose hash already differed keeps it, and stays refused as changed). One
/// transaction, run at every open; on a current store it only scans the agents' hashes. Returns how
/// many agents it rehashed.
pub async fn rehash_specs(pool: &Pool) -> sqlx::Result<usize> {
    let stale: Vec<(i64, String, String)> =
        sqlx::query_as("SELECT id, spec, spec_hash FROM agents WHERE length(spec_hash) <> 64")
            .fetch_all(pool)
            .await?;
    if stale.is_empty() {
        return Ok(0);
    }
    let mut tx = pool.begin().await?;
    for (id, spec, was) in &stale {
        let now = spec_hash(spec);
        for side in ["a", "b"] {
            sqlx::query(&format!(
                "UPDATE matches SET spec_hash_{side} = $1 WHERE agent_{side} = $2 AND spec_hash_{side} = $3"
            ))
            .bind(&now)
            .bind(id)
            .bind(was)
            .execute(&mut *tx)
            .await?;
        }
        sqlx::query("UPDATE agents SET spec_hash = $1 WHERE id = $2")
            .bind(&now)
            .bind(id)
            .execute(&mut *tx)
            .await?;
    }
    tx.commit().await?;
    tracing::info!(agents = stale.len(), "spec hashes rewritten as SHA-256");
    Ok(stale.len())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn training_provenance_is_kept_apart_and_filled_in_for_older_stores() {
        let pool = test_store("training_json").await;
        let kmac = ::agents::builtins::checkpoint("kmac").expect("built in");
        let qual = (6, 0.5, 0.1, 0.1);
        let id = insert_checkpoint_agent(&pool, "kmac", "default", kmac, qual, true, None)
            .await
            .unwrap();
        let none = insert_checkpoint_agent(&pool, "bare", "default", "{}", qual, false, None)
            .await
            .unwrap();
        let training = agent_training(&pool, id)
            .await
            .unwrap()
            .expect("provenance");
        let full: serde_json::Value = serde_json::from_str(kmac).unwrap();
        // Stored re-serialised from its fields (the defaults written out).
        let parsed: ::agents::checkpoint::Training =
            serde_json::from_value(full["training"].clone()).unwrap();
        let expected = serde_json::to_value(&parsed).unwrap();
        assert!(
            training == expected,
            "the stored provenance is the checkpoint's"
        );
        assert_eq!(agent_training(&pool, none).await.unwrap(), None);
        // Padding inside the section is not stored: a 1 MB upload of it keeps its few kilobytes.
        let section = serde_json::to_string(&full["training"]).unwrap();
        let padded = format!(
            "{{\"training\": {{{}{}}}",
            " ".repeat(1 << 20),
            &section[1..]
        );
        let pad = insert_checkpoint_agent(&pool, "padded", "default", &padded, qual, false, None)
            .await
            .unwrap();
        let (stored,): (String,) = sqlx::query_as("SELECT training_json FROM agents WHERE id = $1")
            .bind(pad)
            .fetch_one(&pool)
            .await
            .unwrap();
        assert!(stored.len() < 64 << 10, "{} bytes stored", stored.len());
        // A store from before the column: filled in at open, once.
        sqlx::query("UPDATE agents SET training_json = NULL")
            .execute(&pool)
            .await
            .unwrap();
        assert_eq!(agent_training(&pool, id).await.unwrap(), None);
        assert_eq!(extract_training(&pool).await.unwrap(), 3);
        assert_eq!(extract_training(&pool).await.unwrap(), 0);
        assert!(agent_training(&pool, id).await.unwrap() == Some(expected));
        pool.close().await;
    }

    #[tokio::test]
    async fn restarts_take_no_ids_and_names_are_unique_in_any_case() {
        let pool = test_store("agent_names").await;
        // Three starts register the scripted agents once, and take no id for the ones that exist.
        for _ in 0..3 {
            register_builtins(&pool, "default").await.unwrap();
        }
        let n = ::agents::scripted::variants().len() as i64;
        let ids: Vec<i64> = agents(&pool).await.unwrap().iter().map(|a| a.id).collect();
        assert_eq!(ids, (1..=n).collect::<Vec<_>>());
        let qual = (6, 0.5, 0.1, 0.1);
        let id = insert_checkpoint_agent(&pool, "mine", "default", "{}", qual, false, None)
            .await
            .unwrap();
        assert_eq!(id, n + 1);
        // The store itself refuses a name that differs only in case, whoever checks first.
        let err = insert_checkpoint_agent(&pool, "MINE", "default", "{}", qual, false, None)
            .await
            .unwrap_err();
        assert!(
            matches!(&err, sqlx::Error::Database(e) if e.is_unique_violation()),
            "{err}"
        );
        let found = agent_by_name(&pool, "Mine").await.unwrap().unwrap();
        assert_eq!((found.id, found.name.as_str()), (id, "mine"));
        assert!(agent_by_name(&pool, "SCRIPTED").await.unwrap().is_some());
    }

    #[tokio::test]
    async fn a_store_of_the_old_spec_hashes_is_rehashed_and_its_matches_still_match() {
        let pool = test_store("rehash").await;
        register_builtins(&pool, "default").await.unwrap();
        let spec = r#"{"a": "checkpoint"}"#;
        let qual = (6, 0.5, 0.1, 0.1);
        let id = insert_checkpoint_agent(&pool, "old", "default", spec, qual, false, None)
            .await
            .unwrap();
        // As a store written with the 32-digit FNV digests has them: the agent, a match queued
        // with its hash, and one whose side had another (a spec changed since).
        let fnv = "00112233445566778899aabbccddeeff";
        sqlx::query("UPDATE agents SET spec_hash = $1 WHERE id = $2")
            .bind(fnv)
            .bind(id)
            .execute(&pool)
            .await
            .unwrap();
        let a = agent(&pool, id).await.unwrap().unwrap();
        let queue = |pool: Pool, a: Agent| async move {
            queue_match(&pool, &a, &a, 1, 7, false, Origin::default())
                .await
                .unwrap()
        };
        let kept = queue(pool.clone(), a.clone()).await;
        let changed = queue(
            pool.clone(),
            Agent {
                spec_hash: "ffff".repeat(8),
                ..a
            },
        )
        .await;
        assert_eq!(rehash_specs(&pool).await.unwrap(), 1);
        assert_eq!(rehash_specs(&pool).await.unwrap(), 0, "idempotent");
        let now = agent(&pool, id).await.unwrap().unwrap().spec_hash;
        assert_eq!(now, spec_hash(spec));
        assert_eq!(now.len(), 64);
        let m = match_row(&pool, kept).await.unwrap().unwrap();
        assert_eq!(
            (m.spec_hash_a.as_str(), m.spec_hash_b.as_str()),
            (now.as_str(), now.as_str())
        );
        let m = match_row(&pool, changed).await.unwrap().unwrap();
        assert_eq!(
            m.spec_hash_a,
            "ffff".repeat(8),
            "a changed side stays changed"
        );
        // The scripted agents' hashes were current already.
        for a in agents(&pool).await.unwrap() {
            assert_eq!(a.spec_hash.len(), 64, "{}", a.name);
        }
    }
}
