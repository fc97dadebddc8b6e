//! # server — the tournament service
//!
//! Will hold (issue 5): the axum REST API under `/api/v1`, the scheduler and its worker pool, SQLite
//! storage through sqlx and the `migrations/`, ratings (Bradley–Terry, Glicko-2), replays and the
//! leaderboard page.
//!
//! Must never: simulate physics or run policies itself (it calls `agents`' match runner), or block the
//! async runtime with a match. Nothing is implemented here yet.
#![forbid(unsafe_code)]

/// The agents crate the server schedules matches with.
pub use agents;
