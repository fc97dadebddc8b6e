//! # server — the tournament service
//!
//! An axum service on SQLite or PostgreSQL (sqlx, `migrations/` applied at start): agents (the
//! built-ins registered on first start), matches queued over REST and played by a bounded pool of
//! workers off the async runtime, rallies, crossings and replays stored, Bradley–Terry ratings on a
//! leaderboard, and an HTML page. See `scheduler/` for a match's lifecycle. This file: the shared
//! state, the events and live channels, starting and stopping; `settings.rs` the settings;
//! `admission.rs` what a checkpoint passes to become an agent.
//!
//! Must never: simulate physics or run policies itself (it calls `agents`' match runner), or block the
//! async runtime with a match.
#![forbid(unsafe_code)]

mod admission;
pub mod api;
pub mod board;
pub mod db;
pub mod domain;
pub mod edge;
pub mod page;
pub mod ratings;
pub mod replay;
pub mod scheduler;
mod settings;
pub mod tournament;
pub mod wire;

use std::net::SocketAddr;
use std::sync::Arc;

use crate::db::Pool;
use tokio::sync::Notify;

/// The agents crate the server schedules matches with.
pub use agents;

pub use admission::*;
pub use settings::*;

/// What changed on the server, as `GET /api/v1/events` streams it (server-sent events): a match
/// queued, started, finished, failed or cancelled, or an agent registered.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ServerEvent {
    /// What it is about.
    pub kind: EventKind,
    /// The match's or the agent's id.
    pub id: i64,
    /// A match's new status; none for agents.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status: Option<domain::MatchStatus>,
}

/// What a [`ServerEvent`] is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EventKind {
    /// A match (queued, running, done, failed, cancelled).
    Match,
    /// An agent (registered).
    Agent,
}

/// Events kept for a slow subscriber before it starts missing some (it is told, and refreshes).
pub const EVENT_BUFFER: usize = 256;

/// One message of a running match's live feed: an SSE event name (`frames` or `rally`) and its JSON.
#[derive(Debug)]
pub struct LiveMsg {
    /// The event's name.
    pub event: &'static str,
    /// Its JSON data.
    pub data: String,
}

/// A running match's live feed: the frames of the rally being played, [`LIVE_CHUNK`] at a time as
/// they are recorded, and each rally's record as it ends.
pub type LiveChannel = tokio::sync::broadcast::Sender<Arc<LiveMsg>>;

/// Frames per `frames` message of a live feed: 0.2 s of play at the replay's 50 Hz.
pub const LIVE_CHUNK: usize = 10;

/// Messages a live viewer may fall behind (about 13 s of play: a few rallies) before it skips to
/// the newest (the worker never waits).
pub const LIVE_BUFFER: usize = 64;

impl AppState {
    /// Publishes an event to every subscriber; never waits (a subscriber that lags loses the oldest
    /// events, not the sender's time), and having no subscriber is fine.
    pub fn publish_match(&self, id: i64, status: domain::MatchStatus) {
        let _ = self.events.send(ServerEvent {
            kind: EventKind::Match,
            id,
            status: Some(status),
        });
    }

    /// Publishes that agent `id` was registered (see [`AppState::publish_match`]).
    pub fn publish_agent(&self, id: i64) {
        let _ = self.events.send(ServerEvent {
            kind: EventKind::Agent,
            id,
            status: None,
        });
    }
}

/// A leaderboard with the agent count and finished-match count it was computed from.
pub type CachedBoard = (usize, i64, Arc<ratings::Leaderboard>);

/// Everything the handlers and workers share.
#[derive(Clone)]
pub struct AppState {
    /// This process's worker name (see [`Settings::worker`]).
    pub worker: Arc<String>,
    /// The database.
    pub pool: Pool,
    /// The robot model both sides play with.
    pub model: Arc<sim::model::Model>,
    /// Arena constants.
    pub arena: sim::config::ArenaConfig,
    /// Settings.
    pub settings: Arc<Settings>,
    /// Wakes the workers when a match is queued.
    pub wake: Arc<Notify>,
    /// The last leaderboard computed, with the number of finished matches it was computed from.
    pub board: Arc<tokio::sync::Mutex<Option<CachedBoard>>>,
    /// What each submitter token spent of its budgets recently (when, how much).
    pub rate: Arc<std::sync::Mutex<RateLog>>,
    /// One qualification at a time: submissions wait their turn instead of piling up on the CPU.
    pub qualify: Arc<tokio::sync::Semaphore>,
    /// One checkpoint validation at a time, off the async threads ([`validate_checkpoint`]).
    pub validate: Arc<tokio::sync::Semaphore>,
    /// What changed, for the event stream's subscribers.
    pub events: tokio::sync::broadcast::Sender<ServerEvent>,
    /// Running matches that can be watched live: the frames of the rally being played (with body
    /// poses, as JSON) and each rally's record go to the match's channel, which its worker drops
    /// when the match ends.
    pub live: Arc<std::sync::Mutex<std::collections::HashMap<i64, LiveChannel>>>,
    /// Replays of matches that kept no frames are re-simulated, as many at a time as there are workers.
    pub resim: Arc<tokio::sync::Semaphore>,
}

/// The budgets a submitter token spends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Budget {
    /// Matches queued, per minute.
    Matches,
    /// Agents submitted, per hour.
    Agents,
}

/// Per (submitter token id, budget), the (time, amount) of its recent requests.
pub type RateLog =
    std::collections::HashMap<(i64, Budget), std::collections::VecDeque<(std::time::Instant, u32)>>;

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

/// The state of a server: database ready, built-in agents registered.
pub async fn start(settings: Settings) -> anyhow::Result<AppState> {
    let state = open_state(settings).await?;
    db::register_builtins(&state.pool).await?;
    register_builtin_checkpoints(&state).await?;
    Ok(state)
}

/// The state a process that plays matches needs (`rally serve`, `rally worker`): the database
/// open and migrated, the model loaded, matches whose lease ran out queued again.
pub async fn open_state(settings: Settings) -> anyhow::Result<AppState> {
    let pool = db::open(&settings.db).await?;
    let requeued = db::workers::requeue_expired(&pool, db::workers::now_ms()).await?;
    if requeued > 0 {
        tracing::info!(
            requeued,
            "re-queued running matches whose worker's lease ran out"
        );
    }
    let model = Arc::new(sim::mjcf::parse_str(
        sim::config::DEFAULT_MODEL_XML,
        "config/models/upper_body.xml",
    )?);
    let workers = settings.workers.max(1);
    let worker = Arc::new(settings.worker());
    Ok(AppState {
        worker,
        pool,
        model,
        arena: sim::config::ArenaConfig::default(),
        settings: Arc::new(settings),
        wake: Arc::new(Notify::new()),
        board: Arc::new(tokio::sync::Mutex::new(None)),
        rate: Arc::new(std::sync::Mutex::new(RateLog::new())),
        qualify: Arc::new(tokio::sync::Semaphore::new(1)),
        validate: Arc::new(tokio::sync::Semaphore::new(1)),
        events: tokio::sync::broadcast::channel(EVENT_BUFFER).0,
        live: Arc::new(std::sync::Mutex::new(std::collections::HashMap::new())),
        resim: Arc::new(tokio::sync::Semaphore::new(workers)),
    })
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
