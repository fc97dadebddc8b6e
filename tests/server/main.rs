//! The real server (`rally serve`, a child process) on a loopback port with a real store (SQLite, or
//! PostgreSQL on CI's second pass): submit and qualify a checkpoint, play matches, read the
//! leaderboard and replays, cancel, kill -9 in the middle of a match and restart (nothing lost,
//! nothing counted twice), and the bad-input table. Requests and answers go through the server's
//! own types (`server::wire`), so a field the server stops sending fails here; the bad-input table
//! sends raw bytes on purpose, and the drawings (arena, model, replay frames) stay JSON.

use std::io::BufRead;
use std::process::Command;
use std::time::{Duration, Instant};

use serde_json::{json, Value};
use server::db::{self, AgentKind, MatchStatus, SprtStatus};
use server::ratings::Leaderboard;
use server::tournament::ProgressState;
use server::wire::{
    AgentCrossings, AgentDetail, AgentList, ErrorBody, Health, IssuedToken, MatchDetail, MatchList,
    NewSprt, NewToken, NewTournament, QualificationRule, QueueMatch, RatingHistory, SprtView,
    SubmitAgent, Submitted, TournamentList, TournamentView,
};

#[path = "../common/mod.rs"]
mod common;
use common::*;

mod admission;
mod arenas;
mod bad_input;
mod cancel;
mod contests;
mod edge;
mod lifecycle;
mod load;
mod quotas;

fn template(name: &str) -> Value {
    let out = Command::new(env!("CARGO_BIN_EXE_rally"))
        .args(["checkpoint", "template", "--hidden", "16", "--name", name])
        .output()
        .unwrap();
    assert!(out.status.success());
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Everything the store of `dir` holds, as bytes to search: the SQLite file and its WAL, or on
/// PostgreSQL every row of every table as text.
fn stored_bytes(dir: &std::path::Path) -> Vec<Vec<u8>> {
    if postgres_admin().is_none() {
        return ["rally.db", "rally.db-wal"]
            .iter()
            .map(|f| std::fs::read(dir.join(f)).unwrap_or_default())
            .collect();
    }
    let location: server::db::Location = db(dir).parse().unwrap();
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
        .block_on(async {
            let pool = server::db::open(&location).await.unwrap();
            let tables: Vec<String> = sqlx::query_scalar(
                "SELECT table_name::text FROM information_schema.tables WHERE table_schema = 'public'",
            )
            .fetch_all(&pool)
            .await
            .unwrap();
            let mut out = Vec::new();
            for t in tables {
                let rows: Vec<String> =
                    sqlx::query_scalar(&format!("SELECT CAST(t.* AS TEXT) FROM {t} t"))
                        .fetch_all(&pool)
                        .await
                        .unwrap();
                out.extend(rows.into_iter().map(String::into_bytes));
            }
            pool.close().await;
            out
        })
}
