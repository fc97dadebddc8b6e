//! What the handlers and workers share ([`AppState`]), the budgets a token spends, and opening it.

use std::sync::Arc;

use tokio::sync::Notify;

use crate::db::{self, Pool};
use crate::live::{EventKind, LiveChannel, ServerEvent, EVENT_BUFFER};
use crate::settings::Settings;
use crate::{domain, ratings};

/// A leaderboard with the agent count and finished-match count it was computed from.
pub type CachedBoard = (usize, i64, Arc<ratings::Leaderboard>);

/// Everything the handlers and workers share.
#[derive(Clone)]
pub struct AppState {
    /// This process's worker name (see [`Settings::worker`]).
    pub worker: Arc<String>,
    /// The database.
    pub pool: Pool,
    /// The robots this process plays, each in its arena.
    pub arenas: crate::arenas::Arenas,
    /// Settings.
    pub settings: Arc<Settings>,
    /// Wakes the workers when a match is queued.
    pub wake: Arc<Notify>,
    /// The last leaderboard computed of each robot, with the number of finished matches it was
    /// computed from.
    pub board: Arc<tokio::sync::Mutex<std::collections::HashMap<String, CachedBoard>>>,
    /// What each submitter token spent of its budgets recently (when, how much).
    pub rate: Arc<std::sync::Mutex<RateLog>>,
    /// One admission (a checkpoint validated and qualified) at a time: submissions wait their
    /// turn instead of piling up on the CPU ([`crate::admission::admit_submission`]).
    pub admit: Arc<tokio::sync::Semaphore>,
    /// Submissions admitted or waiting for their turn (at most `admission_queue`).
    pub admit_waiting: Arc<std::sync::atomic::AtomicUsize>,
    /// What changed, for the event stream's subscribers.
    pub events: tokio::sync::broadcast::Sender<ServerEvent>,
    /// Running matches that can be watched live: the frames of the rally being played (with body
    /// poses, as JSON) and each rally's record go to the match's channel, which its worker drops
    /// when the match ends.
    pub live: Arc<std::sync::Mutex<std::collections::HashMap<i64, LiveChannel>>>,
    /// Replays are read (stored frames decompressed, or a rally re-simulated for a match that kept
    /// none) as many at a time as there are workers.
    pub resim: Arc<tokio::sync::Semaphore>,
    /// The agents' built players, shared by the workers and the re-simulations.
    pub players: Arc<crate::players::PlayerCache>,
    /// The matches this process plays, each with the flag that stops it at the end of its rally
    /// (set when it is cancelled: here by the API, or seen by the heartbeat).
    pub playing:
        Arc<std::sync::Mutex<std::collections::HashMap<i64, Arc<std::sync::atomic::AtomicBool>>>>,
    /// Set when a shutdown's deadline passed with matches still playing: they were stopped at the
    /// end of their rally, and go back to the queue instead of failing.
    pub shutting_down: Arc<std::sync::atomic::AtomicBool>,
}

/// The budgets a submitter token spends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Budget {
    /// Matches queued, per minute.
    Matches,
    /// Rallies asked for (those of a tournament's matches, the most an SPRT may play), per hour.
    Rallies,
    /// Agents submitted, per hour.
    Agents,
}

/// Per (submitter token id, budget), the (time, amount) of its recent requests.
pub type RateLog =
    std::collections::HashMap<(i64, Budget), std::collections::VecDeque<(std::time::Instant, u64)>>;

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

    /// Stops match `id` at the end of its rally if this process plays it (it was cancelled); whether
    /// it did.
    pub fn stop_playing(&self, id: i64) -> bool {
        let flag = self.playing.lock().ok().and_then(|p| p.get(&id).cloned());
        if let Some(f) = &flag {
            f.store(true, std::sync::atomic::Ordering::SeqCst);
        }
        flag.is_some()
    }

    /// Stops every match this process plays at the end of its rally, to be queued again: a
    /// shutdown's deadline passed. Returns how many.
    pub fn stop_all_playing(&self) -> usize {
        self.shutting_down
            .store(true, std::sync::atomic::Ordering::SeqCst);
        let playing = self
            .playing
            .lock()
            .map(|p| p.values().cloned().collect::<Vec<_>>());
        let flags = playing.unwrap_or_default();
        for f in &flags {
            f.store(true, std::sync::atomic::Ordering::SeqCst);
        }
        flags.len()
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
    let arenas = crate::arenas::Arenas::load(&crate::settings::data_dir())?;
    let workers = settings.workers.max(1);
    let worker = Arc::new(settings.worker());
    let players = Arc::new(crate::players::PlayerCache::new(settings.player_cache));
    Ok(AppState {
        worker,
        pool,
        arenas,
        settings: Arc::new(settings),
        wake: Arc::new(Notify::new()),
        board: Arc::new(tokio::sync::Mutex::new(std::collections::HashMap::new())),
        rate: Arc::new(std::sync::Mutex::new(RateLog::new())),
        admit: Arc::new(tokio::sync::Semaphore::new(1)),
        admit_waiting: Arc::new(std::sync::atomic::AtomicUsize::new(0)),
        events: tokio::sync::broadcast::channel(EVENT_BUFFER).0,
        live: Arc::new(std::sync::Mutex::new(std::collections::HashMap::new())),
        resim: Arc::new(tokio::sync::Semaphore::new(workers)),
        players,
        playing: Arc::new(std::sync::Mutex::new(std::collections::HashMap::new())),
        shutting_down: Arc::new(std::sync::atomic::AtomicBool::new(false)),
    })
}
