//! # server — the tournament service
//!
//! An axum service on SQLite or PostgreSQL (sqlx, `migrations/` applied at start): agents (the
//! built-ins registered on first start), matches queued over REST and played by a bounded pool of
//! workers off the async runtime, rallies, crossings and replays stored, Bradley–Terry ratings on a
//! leaderboard, and an HTML page. See `scheduler.rs` for a match's lifecycle.
//!
//! Must never: simulate physics or run policies itself (it calls `agents`' match runner), or block the
//! async runtime with a match.
#![forbid(unsafe_code)]

pub mod api;
pub mod board;
pub mod db;
pub mod domain;
pub mod edge;
pub mod page;
pub mod ratings;
pub mod replay;
pub mod scheduler;
pub mod tournament;
pub mod wire;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;

use crate::db::Pool;
use serde::Deserialize;
use tokio::sync::Notify;

/// The agents crate the server schedules matches with.
pub use agents;

/// The default settings file, `config/default.toml`.
pub const DEFAULT_SETTINGS_TOML: &str = include_str!("../../config/default.toml");

/// Server settings (`config/default.toml`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settings {
    /// Listen address.
    pub addr: SocketAddr,
    /// The store: an SQLite file (created if missing) or a `postgres://` URL (db::Location).
    pub db: db::Location,
    /// Match workers (each a blocking thread).
    pub workers: usize,
    /// Keep scheduling matches between the agents with the fewest matches when the queue is empty.
    pub continuous: bool,
    /// Rallies per match scheduled by the continuous mode.
    pub continuous_rallies: u32,
    /// Least time between two matches queued by the continuous mode, s.
    pub continuous_pause_s: f64,
    /// Every this many matches, continuous mode queues a cooperative one: an agent against itself
    /// (it rates nothing; it fills the rally-length and drift statistics, which a strong agent's
    /// matches against weak ones leave short). 0: never.
    #[serde(default = "default_self_play_every")]
    pub continuous_self_play_every: u32,
    /// Most rallies a requested match may have.
    pub max_rallies: u32,
    /// Qualification episodes run for a submitted agent.
    pub qualification_episodes: usize,
    /// Least share of the qualification's P2 serves an agent must hit to be admitted.
    #[serde(default = "default_min_hit_rate")]
    pub qualification_min_hit_rate: f64,
    /// Largest share of the qualification's episodes in which an agent may drop its paddle.
    #[serde(default = "default_max_dropped")]
    pub qualification_max_dropped: f64,
    /// The longest a submitted checkpoint's validation (parsing, checking, building its network —
    /// an ONNX graph is optimised by tract) may take, waiting for its turn included, s: past it the
    /// submission is refused (422 naming this setting).
    #[serde(default = "default_validation_budget_s")]
    pub validation_budget_s: f64,
    /// Largest request body, bytes.
    pub max_body_bytes: usize,
    /// Admin token (the `RALLY_ADMIN_TOKEN` environment variable overrides it); empty disables
    /// submissions.
    pub admin_token: String,
    /// Matches a submitter token may queue per minute (plain matches, tournaments' and SPRTs'
    /// first ones); the admin token is not limited.
    #[serde(default = "default_matches_per_minute")]
    pub max_matches_per_minute: u32,
    /// Most matches one tournament may queue.
    #[serde(default = "default_tournament_matches")]
    pub max_tournament_matches: u32,
    /// Agents a submitter token may submit per hour (each one is qualified on
    /// `qualification_episodes` episodes); the admin token is not limited.
    #[serde(default = "default_agents_per_hour")]
    pub max_agents_per_hour: u32,
    /// The checkpoints registered as built-in agents on start, qualified like submissions:
    /// [`EMBEDDED_BUILTINS`] (the default) for those compiled into the binary, whatever directory
    /// it starts in; else a directory of `NAME.json` files; empty: none. One that does not load is
    /// skipped with a warning.
    #[serde(default = "default_builtin_checkpoints")]
    pub builtin_checkpoints: PathBuf,
    /// How long a running match's lease lasts without a heartbeat, s: a worker that died or lost
    /// the database loses its matches after this long (they are queued again). Heartbeats come
    /// every quarter of it.
    #[serde(default = "default_lease_s")]
    pub lease_s: f64,
    /// HTTP connections open at once; more wait in the kernel's backlog.
    #[serde(default = "default_max_connections")]
    pub max_connections: usize,
    /// How long a client may take to send a request's headers, s (also the longest a keep-alive
    /// connection waits idle for its next request): past it, the connection is closed.
    #[serde(default = "default_header_read_timeout_s")]
    pub header_read_timeout_s: f64,
    /// How long a shutdown (SIGTERM, Ctrl-C) waits for open HTTP connections (live streams, slow
    /// clients) before closing them, s. Running matches are finished and stored either way.
    #[serde(default = "default_shutdown_deadline_s")]
    pub shutdown_deadline_s: f64,
    /// This process's worker name in the `workers` table and the matches it plays; empty:
    /// `HOST:PID`.
    #[serde(default)]
    pub worker_name: String,
}

fn default_validation_budget_s() -> f64 {
    10.0
}

fn default_min_hit_rate() -> f64 {
    0.3
}

fn default_max_dropped() -> f64 {
    0.1
}

fn default_self_play_every() -> u32 {
    3
}

fn default_lease_s() -> f64 {
    20.0
}

fn default_max_connections() -> usize {
    1024
}

fn default_header_read_timeout_s() -> f64 {
    10.0
}

fn default_shutdown_deadline_s() -> f64 {
    10.0
}

impl Settings {
    /// The lease of a claimed match, ms.
    pub fn lease_ms(&self) -> i64 {
        (self.lease_s * 1000.0).round() as i64
    }

    /// This process's worker name (`worker_name`, or `HOST:PID`).
    pub fn worker(&self) -> String {
        if self.worker_name.is_empty() {
            format!("{}:{}", hostname(), std::process::id())
        } else {
            self.worker_name.clone()
        }
    }
}

/// This machine's name (Linux: the kernel's; else `HOSTNAME`, else "localhost").
pub fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "localhost".into())
}

/// `builtin_checkpoints = "embedded"`: the checkpoints compiled into the binary
/// ([`agents::builtins`]).
pub const EMBEDDED_BUILTINS: &str = "embedded";

fn default_builtin_checkpoints() -> PathBuf {
    PathBuf::from(EMBEDDED_BUILTINS)
}

fn default_agents_per_hour() -> u32 {
    30
}

fn default_matches_per_minute() -> u32 {
    600
}

fn default_tournament_matches() -> u32 {
    2000
}

impl Settings {
    /// Parses settings, naming the field that is wrong.
    pub fn from_toml(text: &str) -> Result<Settings, String> {
        let s: Settings = toml::from_str(text).map_err(|e| e.to_string())?;
        if s.workers > 64 {
            return Err("workers must be between 0 (serve the API alone) and 64".into());
        }
        if !(s.lease_s.is_finite() && s.lease_s >= 1.0) {
            return Err("lease_s must be at least 1 second".into());
        }
        if s.max_connections == 0 {
            return Err("max_connections must be positive".into());
        }
        for (name, v) in [
            ("header_read_timeout_s", s.header_read_timeout_s),
            ("shutdown_deadline_s", s.shutdown_deadline_s),
            ("validation_budget_s", s.validation_budget_s),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= 86_400.0) {
                return Err(format!(
                    "{name} must be a positive number of seconds (at most a day)"
                ));
            }
        }
        if s.max_rallies == 0 || s.continuous_rallies == 0 || s.continuous_rallies > s.max_rallies {
            return Err("max_rallies and continuous_rallies must be positive, continuous_rallies ≤ max_rallies".into());
        }
        if !(s.continuous_pause_s.is_finite() && s.continuous_pause_s >= 0.0) {
            return Err("continuous_pause_s must be a non-negative number of seconds".into());
        }
        if s.max_matches_per_minute == 0 {
            return Err("max_matches_per_minute must be positive".into());
        }
        if s.max_agents_per_hour == 0 {
            return Err("max_agents_per_hour must be positive".into());
        }
        if s.max_tournament_matches == 0 {
            return Err("max_tournament_matches must be positive".into());
        }
        if s.qualification_episodes == 0 || s.qualification_episodes > 10_000 {
            return Err("qualification_episodes must be between 1 and 10000".into());
        }
        for (name, v) in [
            ("qualification_min_hit_rate", s.qualification_min_hit_rate),
            ("qualification_max_dropped", s.qualification_max_dropped),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(format!("{name} must be a share, from 0 to 1"));
            }
        }
        Ok(s)
    }
}

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

/// Why [`validate_checkpoint`] refused.
#[derive(Debug)]
pub enum Refused {
    /// The checkpoint is wrong: the field and what.
    Invalid(agents::checkpoint::CheckpointError),
    /// Validation ran past `validation_budget_s`.
    OverBudget(f64),
}

/// Parses and validates a submitted checkpoint against the server's model on the blocking pool,
/// one at a time, within `validation_budget_s` (its turn included). Past the budget the caller gets
/// [`Refused::OverBudget`] at once; the work itself cannot be interrupted and finishes on its
/// thread, holding the turn, so a flood of slow uploads queues rather than piling onto the CPU.
pub async fn validate_checkpoint(
    state: &AppState,
    text: String,
) -> anyhow::Result<Result<agents::checkpoint::Checkpoint, Refused>> {
    let budget = state.settings.validation_budget_s;
    let turn = state.validate.clone();
    let model = state.model.clone();
    let job = async move {
        let permit = turn
            .acquire_owned()
            .await
            .map_err(|e| anyhow::anyhow!("validation queue closed: {e}"))?;
        tokio::task::spawn_blocking(move || {
            let _permit = permit;
            agents::checkpoint::Checkpoint::from_json(&text, &model)
        })
        .await
        .map_err(|e| anyhow::anyhow!("checkpoint validation panicked: {e}"))
    };
    match tokio::time::timeout(std::time::Duration::from_secs_f64(budget), job).await {
        Err(_) => Ok(Err(Refused::OverBudget(budget))),
        Ok(r) => Ok(r?.map_err(Refused::Invalid)),
    }
}

/// Whether a qualification report clears the admission thresholds (`qualification_min_hit_rate`,
/// `qualification_max_dropped`); `Err` gives the figures that fell short, for the 422 and the log.
pub fn admits(settings: &Settings, r: &agents::eval::EvalReport) -> Result<(), String> {
    let n = r.episodes.max(1);
    let hits = (r.hit_rate.value * n as f64).round() as usize;
    let dropped = r
        .ends
        .iter()
        .find(|(end, _)| end == "DROPPED_PADDLE")
        .map_or(0, |e| e.1);
    let mut short = Vec::new();
    if r.hit_rate.value < settings.qualification_min_hit_rate {
        short.push(format!(
            "it hit {hits} of {n} P2 serves ({:.1}%; at least {:.0}% qualifies)",
            100.0 * r.hit_rate.value,
            100.0 * settings.qualification_min_hit_rate
        ));
    }
    let dropped_share = dropped as f64 / n as f64;
    if dropped_share > settings.qualification_max_dropped {
        short.push(format!(
            "it dropped its paddle in {dropped} of {n} episodes ({:.1}%; at most {:.0}% qualifies)",
            100.0 * dropped_share,
            100.0 * settings.qualification_max_dropped
        ));
    }
    if short.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "below the qualification thresholds: {}",
            short.join("; ")
        ))
    }
}

/// Qualifies an agent on `qualification_episodes` P2 serves (seed 0), one qualification at a time
/// (each one already uses every core). The outer error is the server's, the inner one the agent's.
pub async fn qualify(
    state: &AppState,
    spec: agents::factory::PlayerSpec,
) -> anyhow::Result<Result<agents::eval::EvalReport, String>> {
    let eval = agents::eval::Evaluation {
        model: state.model.clone(),
        config: state.arena.clone(),
        preset: sim::arena::MYOCHALLENGE,
        kind: sim::serve::ServeKind::P2,
        episodes: state.settings.qualification_episodes,
        seed: 0,
    };
    let _turn = state
        .qualify
        .acquire()
        .await
        .map_err(|e| anyhow::anyhow!("qualification queue closed: {e}"))?;
    tokio::task::spawn_blocking(move || agents::eval::evaluate(&eval, &spec, &|| {}))
        .await
        .map_err(|e| anyhow::anyhow!("qualification panicked: {e}"))
}

/// Registers every checkpoint `settings.builtin_checkpoints` names that is not an agent yet, as a
/// built-in agent named after its file, qualified like a submission. A checkpoint that does not
/// load or qualify is skipped with a warning (the committed ones are held to loading by a test);
/// a name already taken keeps its agent.
async fn register_builtin_checkpoints(state: &AppState) -> anyhow::Result<()> {
    let dir = &state.settings.builtin_checkpoints;
    // (name, where it comes from, its text or why it has none)
    let sources: Vec<(String, String, Result<String, String>)> = if dir.as_os_str().is_empty() {
        return Ok(());
    } else if dir.as_os_str() == EMBEDDED_BUILTINS {
        agents::builtins::CHECKPOINTS
            .iter()
            .map(|(name, text)| {
                let from = format!("embedded {name}.json");
                (name.to_string(), from, Ok(text.to_string()))
            })
            .collect()
    } else {
        let mut files: Vec<PathBuf> = match std::fs::read_dir(dir) {
            Ok(entries) => entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "json"))
                .collect(),
            Err(e) => {
                tracing::warn!(dir = %dir.display(), "no built-in checkpoints: {e}");
                return Ok(());
            }
        };
        files.sort();
        files
            .into_iter()
            .filter_map(|path| {
                let name = path.file_stem()?.to_string_lossy().to_string();
                let text = std::fs::read_to_string(&path).map_err(|e| e.to_string());
                Some((name, path.display().to_string(), text))
            })
            .collect()
    };
    for (name, path, text) in sources {
        if let Err(e) = api::check_name(&name) {
            tracing::warn!(%path, "built-in checkpoint skipped: {e}");
            continue;
        }
        if let Some(existing) = db::agent_by_name(&state.pool, &name).await? {
            if !existing.builtin {
                tracing::warn!(%name, "a submitted agent holds the name of a built-in checkpoint; keeping it");
            } else if text
                .as_ref()
                .is_ok_and(|text| db::spec_hash(text) != existing.spec_hash)
            {
                tracing::warn!(
                    %name,
                    %path,
                    "the committed checkpoint differs from the built-in this database registered; keeping the registered one (its matches were played with it): a new database registers the new one"
                );
            }
            continue;
        }
        let loaded = text.and_then(|text| {
            agents::checkpoint::Checkpoint::from_json(&text, &state.model)
                .map(|c| (text, c))
                .map_err(|e| e.to_string())
        });
        let (text, checkpoint) = match loaded {
            Ok(x) => x,
            Err(e) => {
                tracing::warn!(%path, "built-in checkpoint skipped: {e}");
                continue;
            }
        };
        let spec = agents::factory::PlayerSpec::Checkpoint(Arc::new(checkpoint));
        let report = match qualify(state, spec)
            .await?
            .and_then(|r| admits(&state.settings, &r).map(|()| r))
        {
            Ok(r) => r,
            Err(e) => {
                tracing::warn!(%name, "built-in checkpoint did not qualify: {e}");
                continue;
            }
        };
        let qual = (
            report.episodes,
            report.hit_rate.value,
            report.success_rate.value,
            report.effort.value,
        );
        let id = db::insert_checkpoint_agent(&state.pool, &name, &text, qual, true, None).await?;
        state.publish_agent(id);
        tracing::info!(%name, hit = qual.1, success = qual.2, "built-in checkpoint registered");
    }
    Ok(())
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
