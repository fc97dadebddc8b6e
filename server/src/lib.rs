//! # server — the tournament service
//!
//! An axum service on SQLite or PostgreSQL (sqlx, `migrations/` applied at start): agents (the
//! built-ins registered on first start), matches queued over REST and played by a bounded pool of
//! workers off the async runtime, rallies, crossings and replays stored, Bradley–Terry ratings on a
//! leaderboard, and an HTML page. See `scheduler/` for a match's lifecycle. This file: starting and
//! stopping; `state.rs` what handlers and workers share; `live.rs` the event stream and the live
//! feeds; `settings.rs` the settings; `admission.rs` what a checkpoint passes to become an agent;
//! `players.rs` the built players the workers share.
//!
//! Must never: simulate physics or run policies itself (it calls `agents`' match runner), or block the
//! async runtime with a match.
#![forbid(unsafe_code)]

mod admission;
pub mod api;
pub mod arenas;
pub mod board;
pub mod db;
pub mod domain;
pub mod edge;
mod live;
pub mod page;
pub mod players;
pub mod ratings;
pub mod replay;
pub mod scheduler;
mod settings;
mod state;
pub mod tournament;

use std::net::SocketAddr;
use std::sync::Arc;

use tokio::sync::Notify;

/// The agents crate the server schedules matches with.
pub use agents;
/// The API's types (the handlers answer with them).
pub use wire;

pub use admission::*;
pub use live::*;
pub use settings::*;
pub use state::*;

/// Opens the database, applies the migrations, re-queues matches whose lease ran out, registers the
/// built-in agents, starts the workers (none with `workers = 0`: `rally worker` processes play) and
/// serves until SIGINT/SIGTERM.
pub async fn serve(settings: Settings, on_ready: impl FnOnce(SocketAddr)) -> anyhow::Result<()> {
    let state = start(settings).await?;
    let listener = tokio::net::TcpListener::bind(state.settings.addr).await?;
    let addr = listener.local_addr()?;
    let shutdown = Arc::new(Notify::new());
    // A worker name that a live process holds is refused before the server says it is ready.
    let workers = scheduler::Workers::start(state.clone(), shutdown.clone()).await?;
    on_ready(addr);
    let background = scheduler::spawn_background(state.clone(), shutdown.clone());
    let app = api::router(state.clone());
    let limits = edge::Limits {
        max_connections: state.settings.max_connections,
        header_read_timeout: std::time::Duration::from_secs_f64(
            state.settings.header_read_timeout_s,
        ),
        shutdown_deadline: std::time::Duration::from_secs_f64(state.settings.shutdown_deadline_s),
    };
    edge::serve(listener, app, limits, async move {
        shutdown_signal().await;
        shutdown.notify_waiters();
    })
    .await?;
    workers.join(&state).await;
    for b in background {
        b.abort();
    }
    state.pool.close().await;
    Ok(())
}

/// `rally worker`: plays queued matches from the database until SIGINT/SIGTERM (the matches it is
/// playing are finished and stored first), with no HTTP server. `on_ready` gets the worker's name.
pub async fn work(settings: Settings, on_ready: impl FnOnce(&str)) -> anyhow::Result<()> {
    let state = open_state(settings).await?;
    let shutdown = Arc::new(Notify::new());
    let workers = scheduler::Workers::start(state.clone(), shutdown.clone()).await?;
    on_ready(&state.worker);
    shutdown_signal().await;
    shutdown.notify_waiters();
    workers.join(&state).await;
    state.pool.close().await;
    Ok(())
}

/// The state of a server: database ready, built-in agents of every robot it plays registered.
pub async fn start(settings: Settings) -> anyhow::Result<AppState> {
    let state = open_state(settings).await?;
    for arena in state.arenas.iter() {
        db::register_builtins(&state.pool, &arena.name).await?;
        register_builtin_checkpoints(&state, arena).await?;
    }
    Ok(state)
}

async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        if let Ok(mut s) = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        {
            s.recv().await;
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {}
        _ = term => {}
    }
}
