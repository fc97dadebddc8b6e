//! The scheduler. A process that plays matches — `rally serve` with `workers > 0`, or a
//! `rally worker` — registers itself in the `workers` table under its name and runs
//! `settings.workers` async tasks. Each is fishtest's worker loop: **ask** (claim the oldest queued
//! match: queued → running with a lease, one statement), **play** (on a blocking thread, with
//! `agents`' match runner), **report** (rallies, crossings, replay, summary, ratings and the SPRT's
//! step with the `done` mark in one transaction, under the lease), **repeat**. With nothing queued
//! a task waits to be woken (a match queued by this process) or one second (one queued by another).
//!
//! Leases (`db::workers`): the process's heartbeat renews the leases of every match it plays each
//! quarter of `lease_s`. A worker killed with -9, or cut off from the database, stops renewing; once
//! its leases run out, the next claim (by any worker) queues its matches again, and a result it
//! reports after that is refused. Results are written only with the `done` mark, under the current
//! claim, so no match is lost and none is stored twice. SIGTERM finishes the matches being played,
//! stores them and marks the worker stopped. A match cancelled while running stops at the end of the
//! rally being played (at once when this process's API cancelled it, else at the next heartbeat),
//! stores nothing, and frees its worker.
//!
//! Continuous mode (`rally serve` only, [`spawn_background`]): when the queue is empty the server
//! queues a match for the agent whose rating interval is widest (no interval counts as widest),
//! against the opponent it has met least, at most one every `continuous_pause_s` seconds; any
//! worker may play it. Every `continuous_self_play_every`-th match (the first included) is
//! cooperative instead: an agent against itself, the one with the fewest such matches, best
//! qualified first. It rates nothing (`domain::rating_update`) and fills the rally-length and drift
//! statistics: against weaker partners a strong agent's rallies stay short. Continuous-mode
//! matches store no replay frames (about 50 kB a rally even gzipped); `GET /matches/{id}/replay`
//! re-simulates such a rally on request, bit-identical to the one played (rallies are
//! independent: `agents::matchrun::replay_rally`).
//!
//! By part: this file (the worker loop and the background tasks), [`play`] (a match's lifecycle:
//! recipes, playing with the live feed, storing, re-simulation), `continuous` (continuous mode's
//! pairing).

mod continuous;
use continuous::queue_continuous;
pub mod play;

pub use play::*;

use std::sync::Arc;
use std::time::Duration;

use tokio::sync::Notify;
use tokio::task::JoinHandle;

use crate::db;
use crate::state::AppState;

/// Stops the matches this process plays that were cancelled meanwhile (by any process: a match,
/// its tournament or its SPRT), at the end of their rallies.
async fn stop_cancelled(state: &AppState) {
    let ids: Vec<i64> = match state.playing.lock() {
        Ok(p) => p.keys().copied().collect(),
        Err(_) => return,
    };
    for id in ids {
        if let Ok(Some((db::MatchStatus::Cancelled, _))) =
            db::workers::status_of(&state.pool, id).await
        {
            if state.stop_playing(id) {
                tracing::info!(
                    id,
                    "cancelled while playing: stopped at the end of its rally"
                );
            }
        }
    }
}

/// This process's match workers: `settings.workers` tasks and the heartbeat that renews their leases.
pub struct Workers {
    tasks: Vec<JoinHandle<()>>,
    heartbeat: Option<JoinHandle<()>>,
}

impl Workers {
    /// Registers this process as worker `state.worker` (refused if a live process holds the name)
    /// and starts its tasks; they stop after `shutdown` is notified, each finishing the match it
    /// plays within `shutdown_deadline_s`: past it, the matches still playing stop at the end of
    /// their rally and are queued again (nothing of them stored). With `settings.workers = 0`
    /// nothing is registered or started.
    pub async fn start(state: AppState, shutdown: Arc<Notify>) -> anyhow::Result<Workers> {
        let n = state.settings.workers;
        if n == 0 {
            return Ok(Workers {
                tasks: Vec::new(),
                heartbeat: None,
            });
        }
        let lease_ms = state.settings.lease_ms();
        let host = crate::settings::hostname();
        db::workers::register(
            &state.pool,
            &state.worker,
            &host,
            std::process::id(),
            n,
            lease_ms,
        )
        .await?;
        let stopping = Arc::new(std::sync::atomic::AtomicBool::new(false));
        {
            let (shutdown, stopping, wake) =
                (shutdown.clone(), stopping.clone(), state.wake.clone());
            let state = state.clone();
            tokio::spawn(async move {
                shutdown.notified().await;
                stopping.store(true, std::sync::atomic::Ordering::SeqCst);
                wake.notify_waiters();
                let deadline = Duration::from_secs_f64(state.settings.shutdown_deadline_s);
                tokio::time::sleep(deadline).await;
                let stopped = state.stop_all_playing();
                if stopped > 0 {
                    tracing::info!(
                        stopped,
                        "shutdown deadline passed: running matches stop at the end of their rally and are queued again"
                    );
                }
            });
        }
        let heartbeat = {
            let state = state.clone();
            tokio::spawn(async move {
                let every = Duration::from_millis((lease_ms / 4).max(100) as u64);
                loop {
                    tokio::time::sleep(every).await;
                    if let Err(e) =
                        db::workers::heartbeat(&state.pool, &state.worker, lease_ms).await
                    {
                        tracing::warn!(worker = %state.worker, error = %e, "heartbeat failed");
                    }
                    stop_cancelled(&state).await;
                }
            })
        };
        let tasks = (0..n)
            .map(|w| {
                let (state, stopping) = (state.clone(), stopping.clone());
                tokio::spawn(async move {
                    while !stopping.load(std::sync::atomic::Ordering::SeqCst) {
                        let notified = state.wake.notified();
                        let robots: Vec<&str> =
                            state.arenas.iter().map(|a| a.name.as_str()).collect();
                        match db::workers::claim(&state.pool, &state.worker, lease_ms, &robots)
                            .await
                        {
                            Ok(Some((m, lease))) => {
                                state.publish_match(m.id, db::MatchStatus::Running);
                                if let Err(e) = run_one(&state, m, lease).await {
                                    tracing::error!(worker = w, error = %e, "storing a match failed");
                                }
                                continue;
                            }
                            Ok(None) => {}
                            Err(e) => {
                                tracing::error!(worker = w, error = %e, "claiming a match failed")
                            }
                        }
                        if stopping.load(std::sync::atomic::Ordering::SeqCst) {
                            break;
                        }
                        let _ = tokio::time::timeout(Duration::from_secs(1), notified).await;
                    }
                })
            })
            .collect();
        Ok(Workers {
            tasks,
            heartbeat: Some(heartbeat),
        })
    }

    /// Waits for the tasks to finish their matches, stops the heartbeat and marks the worker stopped.
    pub async fn join(self, state: &AppState) {
        if self.tasks.is_empty() {
            return;
        }
        for t in self.tasks {
            let _ = t.await;
        }
        if let Some(h) = self.heartbeat {
            h.abort();
        }
        if let Err(e) = db::workers::stopped(&state.pool, &state.worker).await {
            tracing::warn!(worker = %state.worker, error = %e, "marking the worker stopped failed");
        }
    }
}

/// The server's own background tasks: continuous mode (if on), and the watcher that turns what
/// other processes' workers did to the matches (claimed, finished) into this server's events.
pub fn spawn_background(state: AppState, shutdown: Arc<Notify>) -> Vec<JoinHandle<()>> {
    let mut tasks = Vec::new();
    if state.settings.continuous {
        let (state, shutdown) = (state.clone(), shutdown.clone());
        tasks.push(tokio::spawn(async move {
            let pause = Duration::from_secs_f64(state.settings.continuous_pause_s)
                .max(Duration::from_millis(100));
            loop {
                match queue_continuous(&state).await {
                    Ok(true) => state.wake.notify_waiters(),
                    Ok(false) => {}
                    Err(e) => tracing::error!(error = %e, "continuous mode failed"),
                }
                tokio::select! {
                    _ = tokio::time::sleep(pause) => {}
                    _ = shutdown.notified() => break,
                }
            }
        }));
    }
    tasks.push(tokio::spawn(async move {
        // Every half second: the matches not finished at the last look (and the highest id seen),
        // so that a match another process claimed and finished between two looks — or queued,
        // claimed and finished — is still told. This process's own workers publish their matches
        // themselves; the watcher tells the others' (worker column not ours).
        let mut last: Vec<(i64, db::MatchStatus)> = Vec::new();
        let mut seen = loop {
            match db::workers::last_match_id(&state.pool).await {
                Ok(id) => break id,
                Err(_) => tokio::time::sleep(Duration::from_millis(500)).await,
            }
        };
        loop {
            tokio::time::sleep(Duration::from_millis(500)).await;
            let Ok(now) = db::workers::watched(&state.pool, seen).await else {
                continue;
            };
            let ours = |w: &Option<String>| w.as_deref() == Some(state.worker.as_str());
            for (id, status, worker) in &now {
                let before = last.iter().find(|(l, _)| l == id).map(|(_, s)| *s);
                // Finished rows here are new since the last look (above `seen`).
                let tell = match status {
                    // Queuing and cancelling happen in an API process, which tells them itself.
                    db::MatchStatus::Queued | db::MatchStatus::Cancelled => false,
                    db::MatchStatus::Running => before != Some(db::MatchStatus::Running),
                    _ => true,
                };
                if tell && !ours(worker) {
                    state.publish_match(*id, *status);
                }
            }
            // Unfinished at the last look, finished now.
            for (id, _) in &last {
                if now.iter().any(|(n, ..)| n == id) {
                    continue;
                }
                if let Ok(Some((status, worker))) = db::workers::status_of(&state.pool, *id).await {
                    if !ours(&worker) && status != db::MatchStatus::Cancelled {
                        state.publish_match(*id, status);
                    }
                }
            }
            seen = now.iter().map(|(id, ..)| *id).fold(seen, i64::max);
            last = now
                .iter()
                .filter(|(_, s, _)| matches!(s, db::MatchStatus::Queued | db::MatchStatus::Running))
                .map(|(id, s, _)| (*id, *s))
                .collect();
        }
    }));
    tasks
}
