//! Submitter tokens, kept as SHA-256.

use super::*;

/// The SHA-256 of a token, hex.
pub fn token_sha256(token: &str) -> String {
    sha256_hex(token)
}

/// Stores a new submitter token (its hash only); the id.
pub async fn insert_token(pool: &Pool, name: &str, token: &str) -> sqlx::Result<i64> {
    sqlx::query_scalar("INSERT INTO tokens (name, token_sha256) VALUES ($1, $2) RETURNING id")
        .bind(name)
        .bind(token_sha256(token))
        .fetch_one(pool)
        .await
}

/// The id of the submitter token `token`, if it is one.
pub async fn token_id(pool: &Pool, token: &str) -> sqlx::Result<Option<i64>> {
    let r: Option<(i64,)> = sqlx::query_as("SELECT id FROM tokens WHERE token_sha256 = $1")
        .bind(token_sha256(token))
        .fetch_optional(pool)
        .await?;
    Ok(r.map(|x| x.0))
}
