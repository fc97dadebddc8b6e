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
//! stores them and marks the worker stopped. A match cancelled while running is played out and its
//! result discarded.
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

use std::sync::Arc;
use std::time::Duration;

use agents::factory::PlayerSpec;
use agents::matchrun::MatchSpec;
use tokio::sync::Notify;
use tokio::task::JoinHandle;

use crate::{db, AppState};

/// Builds the player recipe of a stored agent.
pub fn player_spec(
    state: &AppState,
    kind: db::AgentKind,
    spec: &str,
) -> Result<PlayerSpec, String> {
    match kind {
        db::AgentKind::Scripted => {
            PlayerSpec::scripted(spec).ok_or_else(|| format!("unknown scripted agent '{spec}'"))
        }
        db::AgentKind::Checkpoint => agents::checkpoint::Checkpoint::from_json(spec, &state.model)
            .map(|c| PlayerSpec::Checkpoint(Arc::new(c)))
            .map_err(|e| e.to_string()),
    }
}

/// The match runner's recipe for stored match `m`: its preset and simulator version must be this
/// server's.
pub fn match_spec(state: &AppState, m: &db::Match) -> Result<MatchSpec, String> {
    let preset = sim::arena::PRESETS
        .iter()
        .find(|p| p.name == m.preset)
        .copied()
        .ok_or_else(|| format!("unknown preset '{}'", m.preset))?;
    if m.sim_version != sim::SIM_VERSION {
        return Err(format!(
            "match was queued for simulator {} but this server runs {}",
            m.sim_version,
            sim::SIM_VERSION
        ));
    }
    Ok(MatchSpec {
        model: state.model.clone(),
        config: state.arena.clone(),
        preset,
        rallies: m.rallies as u32,
        seed: m.seed as u64,
        replay: m.keep_replay,
    })
}

/// Plays stored match `m` to completion (blocking: call it off the async runtime). While anyone
/// watches, the match's live channel gets the frames of the rally being played, [`crate::LIVE_CHUNK`]
/// at a time with body poses, and each rally's record as it ends (the frames are recorded for that
/// even when the match stores none, which changes no result). Sending never waits: a full channel
/// drops its oldest message for a viewer that lags.
pub fn play(
    state: &AppState,
    m: &db::Match,
    a: &PlayerSpec,
    b: &PlayerSpec,
) -> Result<(agents::matchrun::MatchRecord, agents::matchrun::Replay), String> {
    use agents::matchrun::MatchEvent;
    let spec = agents::matchrun::MatchSpec {
        replay: true,
        ..match_spec(state, m)?
    };
    let live = state
        .live
        .lock()
        .map_err(|_| "live registry poisoned".to_string())?
        .get(&m.id)
        .cloned();
    let players = [
        a.build(&spec.model, &spec.preset, 0)?,
        b.build(&spec.model, &spec.preset, 0)?,
    ];
    // Frames of the current rally not sent yet, and how many it has recorded (the last of `chunk`
    // is frame `recorded - 1`).
    let mut chunk: Vec<agents::matchrun::Frame> = Vec::with_capacity(crate::LIVE_CHUNK);
    let mut recorded = 0usize;
    let head = |k: u32| {
        format!(
            "\"match\":{},\"rally\":{k},\"rallies\":{},\"hz\":{}",
            m.id,
            m.rallies,
            agents::matchrun::REPLAY_HZ
        )
    };
    let send_frames =
        |tx: &crate::LiveChannel, k: u32, recorded: usize, chunk: &[agents::matchrun::Frame]| {
            let first = recorded - chunk.len();
            let frames = serde_json::to_string(chunk)
                .map_err(|e| e.to_string())
                .and_then(|f| crate::replay::with_body_poses(&state.model, &f));
            if let Ok(frames) = frames {
                let data = format!("{{{},\"first\":{first},\"frames\":{frames}}}", head(k));
                let _ = tx.send(Arc::new(crate::LiveMsg {
                    event: "frames",
                    data,
                }));
            }
        };
    let (record, mut replay) =
        agents::matchrun::play_match_with(&spec, players, [a.name(), b.name()], &mut |e| {
            let watched = live.as_ref().filter(|tx| tx.receiver_count() > 0);
            match e {
                MatchEvent::Frame { rally, frame } => {
                    recorded += 1;
                    let Some(tx) = watched else {
                        // Nobody watches: keep nothing; a viewer who comes later starts here.
                        chunk.clear();
                        return;
                    };
                    chunk.push(frame.clone());
                    if chunk.len() >= crate::LIVE_CHUNK {
                        send_frames(tx, rally, recorded, &chunk);
                        chunk.clear();
                    }
                }
                MatchEvent::Rally { rally, record, .. } => {
                    if let Some(tx) = watched {
                        if !chunk.is_empty() {
                            send_frames(tx, rally, recorded, &chunk);
                        }
                        let data = format!(
                            "{{{},\"record\":{}}}",
                            head(rally),
                            serde_json::to_string(record).unwrap_or_else(|_| "null".into())
                        );
                        let _ = tx.send(Arc::new(crate::LiveMsg {
                            event: "rally",
                            data,
                        }));
                    }
                    chunk.clear();
                    recorded = 0;
                }
            }
        })?;
    if !m.keep_replay {
        replay.iter_mut().for_each(Vec::clear);
    }
    Ok((record, replay))
}

/// Re-simulates rally `k` of finished match `m` with replay frames (blocking), after checking that
/// both agents are still the ones it was played with.
pub fn resimulate_rally(
    state: &AppState,
    m: &db::Match,
    agents: [(db::AgentKind, String); 2],
    k: u32,
) -> Result<Vec<agents::matchrun::Frame>, String> {
    let [(ka, sa), (kb, sb)] = agents;
    if !specs_unchanged(m, &sa, &sb) {
        return Err("an agent's spec changed since the match was played".into());
    }
    let a = player_spec(state, ka, &sa)?;
    let b = player_spec(state, kb, &sb)?;
    agents::matchrun::replay_rally(&match_spec(state, m)?, &a, &b, k).map(|(_, frames)| frames)
}

/// Whether the agents' specs are still the ones match `m` was queued with.
fn specs_unchanged(m: &db::Match, spec_a: &str, spec_b: &str) -> bool {
    db::spec_hash(spec_a) == m.spec_hash_a && db::spec_hash(spec_b) == m.spec_hash_b
}

async fn run_one(state: &AppState, m: db::Match, lease: db::Lease) -> anyhow::Result<()> {
    // The live channel first: the match is `running` from its claim on, so a viewer may ask for
    // its feed before the agents' specs are read (seen in CI: 409 while the specs were fetched).
    let id = m.id;
    if let Ok(mut live) = state.live.lock() {
        live.insert(id, tokio::sync::broadcast::channel(crate::LIVE_BUFFER).0);
    }
    // Dropping the channel when this function returns ends every live viewer's stream.
    struct Unregister(AppState, i64);
    impl Drop for Unregister {
        fn drop(&mut self) {
            if let Ok(mut live) = self.0.live.lock() {
                live.remove(&self.1);
            }
        }
    }
    let _unregister = Unregister(state.clone(), id);
    let spec_of = |id: i64| {
        let state = state.clone();
        async move {
            db::agent_spec(&state.pool, id)
                .await?
                .ok_or_else(|| anyhow::anyhow!("agent {id} no longer exists"))
        }
    };
    let (ka, sa) = spec_of(m.agent_a).await?;
    let (kb, sb) = spec_of(m.agent_b).await?;
    if !specs_unchanged(&m, &sa, &sb) {
        let error = "an agent's spec changed since the match was queued";
        if db::fail(&state.pool, &lease, error).await? == db::Stored::Done {
            state.publish_match(id, db::MatchStatus::Failed);
        }
        return Ok(());
    }
    let st = state.clone();
    let started = std::time::Instant::now();
    let result = tokio::task::spawn_blocking(move || {
        let a = player_spec(&st, ka, &sa)?;
        let b = player_spec(&st, kb, &sb)?;
        play(&st, &m, &a, &b)
    })
    .await;
    let (stored, status) = match result {
        Ok(Ok((record, replay))) => {
            // A busy database is retried; a match that still cannot be stored keeps its lease
            // until the heartbeat stops (this process exits), then is queued again (nothing
            // half-written: it is one transaction).
            let mut attempt = 0;
            let stored = loop {
                match db::store_result(&state.pool, &lease, &record, &replay).await {
                    Ok(stored) => break stored,
                    Err(e) if attempt < 5 => {
                        attempt += 1;
                        tracing::warn!(id, attempt, error = %e, "storing a match failed; retrying");
                        tokio::time::sleep(Duration::from_millis(200 * attempt)).await;
                    }
                    Err(e) => return Err(e.into()),
                }
            };
            tracing::info!(
                id,
                points_a = record.points[0],
                points_b = record.points[1],
                seconds = started.elapsed().as_secs_f64(),
                ?stored,
                "match finished"
            );
            (stored, db::MatchStatus::Done)
        }
        Ok(Err(e)) => {
            tracing::warn!(id, error = %e, "match failed");
            (
                db::fail(&state.pool, &lease, &e).await?,
                db::MatchStatus::Failed,
            )
        }
        Err(join) => {
            let e = format!("match worker panicked: {join}");
            tracing::error!(id, error = %e);
            (
                db::fail(&state.pool, &lease, &e).await?,
                db::MatchStatus::Failed,
            )
        }
    };
    match stored {
        db::Stored::Done => state.publish_match(id, status),
        db::Stored::Cancelled => {}
        db::Stored::LeaseLost => tracing::warn!(
            id,
            worker = %lease.worker,
            "the lease of the match was lost (queued again for another worker): result refused"
        ),
    }
    Ok(())
}

/// Queues one continuous-mode match if the queue is empty; true if it did.
async fn queue_continuous(state: &AppState) -> anyhow::Result<bool> {
    let queued = db::matches(
        &state.pool,
        db::MatchFilter {
            status: Some(db::MatchStatus::Queued),
            ..db::MatchFilter::default()
        },
        1,
    )
    .await?;
    if !queued.is_empty() {
        return Ok(false);
    }
    let agents = db::agents(&state.pool).await?;
    let every = i64::from(state.settings.continuous_self_play_every);
    if every > 0 && !agents.is_empty() && cooperative_turn(state, every).await? {
        let self_played: Vec<(i64, i64)> = sqlx::query_as(
            "SELECT agent_a, COUNT(*) FROM matches WHERE agent_a = agent_b AND status <> 'cancelled' AND status <> 'failed' GROUP BY agent_a",
        )
        .fetch_all(&state.pool)
        .await?;
        let agent = cooperative_pick(&agents, &self_played).expect("an agent");
        return queue_continuous_match(state, agent, agent).await;
    }
    if agents.len() < 2 {
        return Ok(false);
    }
    let outcomes = db::outcomes(&state.pool).await?;
    // The leaderboard the API serves (cached; recomputed off the async threads when it changed).
    let board = crate::board::current_board(state)
        .await
        .map_err(|e| anyhow::anyhow!("computing the leaderboard: {e:?}"))?;
    let width = |id: i64| {
        board
            .rows
            .iter()
            .find(|r| r.agent_id == id)
            .and_then(|r| Some(r.rating_high? - r.rating_low?))
            .unwrap_or(f64::INFINITY)
    };
    // Matches being played count as met, and their agents are picked last: the leaderboard does
    // not know their results yet.
    let pending: Vec<(i64, i64)> =
        sqlx::query_as("SELECT agent_a, agent_b FROM matches WHERE status = 'running'")
            .fetch_all(&state.pool)
            .await?;
    let met = |x: i64, y: i64| {
        let pair = |a: i64, b: i64| (a == x && b == y) || (a == y && b == x);
        outcomes.iter().filter(|o| pair(o.0, o.1)).count()
            + pending.iter().filter(|p| pair(p.0, p.1)).count()
    };
    let busy = |id: i64| pending.iter().any(|p| p.0 == id || p.1 == id);
    let first = agents
        .iter()
        .max_by(|p, q| {
            busy(q.id)
                .cmp(&busy(p.id))
                .then(width(p.id).total_cmp(&width(q.id)))
                .then(q.id.cmp(&p.id))
        })
        .expect("two agents");
    let second = agents
        .iter()
        .filter(|o| o.id != first.id)
        .min_by(|p, q| {
            met(first.id, p.id)
                .cmp(&met(first.id, q.id))
                .then(p.id.cmp(&q.id))
        })
        .expect("two agents");
    // Alternate sides so neither agent always serves first.
    let n = met(first.id, second.id);
    let (a, b) = if n % 2 == 0 {
        (first, second)
    } else {
        (second, first)
    };
    queue_continuous_match(state, a, b).await
}

/// Whether continuous mode's next match is cooperative: every `every`-th match, the first included.
async fn cooperative_turn(state: &AppState, every: i64) -> anyhow::Result<bool> {
    let (matches_so_far,): (i64,) = sqlx::query_as("SELECT COUNT(*) FROM matches")
        .fetch_one(&state.pool)
        .await?;
    Ok(matches_so_far % every == 0)
}

/// The agent of continuous mode's next cooperative match: the fewest such matches so far
/// (`self_played`: agent id, count), then the highest qualification success rate (none: last), then
/// the lowest id — so a fresh server shows its best rally player's rallies first.
fn cooperative_pick<'a>(
    agents: &'a [db::Agent],
    self_played: &[(i64, i64)],
) -> Option<&'a db::Agent> {
    let count = |id: i64| {
        self_played
            .iter()
            .find(|(a, _)| *a == id)
            .map_or(0, |(_, n)| *n)
    };
    agents.iter().min_by(|p, q| {
        count(p.id)
            .cmp(&count(q.id))
            .then(
                q.success_rate
                    .unwrap_or(-1.0)
                    .total_cmp(&p.success_rate.unwrap_or(-1.0)),
            )
            .then(p.id.cmp(&q.id))
    })
}

/// Queues continuous mode's match of `a` against `b`, without replay frames.
async fn queue_continuous_match(
    state: &AppState,
    a: &db::Agent,
    b: &db::Agent,
) -> anyhow::Result<bool> {
    // Distinct seeds for distinct matches (the next id; results not yet known do not repeat it).
    let (last_id,): (i64,) = sqlx::query_as("SELECT COALESCE(MAX(id), 0) FROM matches")
        .fetch_one(&state.pool)
        .await?;
    let seed = last_id as u64 + 1;
    let id = db::queue_match(
        &state.pool,
        a,
        b,
        state.settings.continuous_rallies,
        seed,
        false,
        db::Origin::default(),
    )
    .await?;
    tracing::debug!(id, a = %a.name, b = %b.name, "continuous mode queued a match");
    Ok(true)
}

/// This process's match workers: `settings.workers` tasks and the heartbeat that renews their leases.
pub struct Workers {
    tasks: Vec<JoinHandle<()>>,
    heartbeat: Option<JoinHandle<()>>,
}

impl Workers {
    /// Registers this process as worker `state.worker` (refused if a live process holds the name)
    /// and starts its tasks; they stop after `shutdown` is notified, each finishing the match it
    /// plays. With `settings.workers = 0` nothing is registered or started.
    pub async fn start(state: AppState, shutdown: Arc<Notify>) -> anyhow::Result<Workers> {
        let n = state.settings.workers;
        if n == 0 {
            return Ok(Workers {
                tasks: Vec::new(),
                heartbeat: None,
            });
        }
        let lease_ms = state.settings.lease_ms();
        let host = crate::hostname();
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
            tokio::spawn(async move {
                shutdown.notified().await;
                stopping.store(true, std::sync::atomic::Ordering::SeqCst);
                wake.notify_waiters();
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
                }
            })
        };
        let tasks = (0..n)
            .map(|w| {
                let (state, stopping) = (state.clone(), stopping.clone());
                tokio::spawn(async move {
                    while !stopping.load(std::sync::atomic::Ordering::SeqCst) {
                        let notified = state.wake.notified();
                        match db::workers::claim(&state.pool, &state.worker, lease_ms).await {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn agent(id: i64, success_rate: Option<f64>) -> db::Agent {
        db::Agent {
            id,
            name: format!("a{id}"),
            kind: crate::domain::AgentKind::Checkpoint,
            spec_hash: String::new(),
            builtin: true,
            created_at: String::new(),
            qual_episodes: success_rate.map(|_| 100),
            hit_rate: success_rate,
            success_rate,
            effort: None,
        }
    }

    #[test]
    fn the_cooperative_pick_takes_the_fewest_then_the_best_qualified() {
        let agents = [agent(1, None), agent(2, Some(0.4)), agent(3, Some(0.78))];
        let pick = |played: &[(i64, i64)]| cooperative_pick(&agents, played).unwrap().id;
        assert_eq!(pick(&[]), 3, "the best qualified first");
        assert_eq!(pick(&[(3, 1)]), 2);
        assert_eq!(pick(&[(3, 1), (2, 1)]), 1, "then the unqualified");
        assert_eq!(pick(&[(3, 1), (2, 1), (1, 1)]), 3, "and round again");
        assert!(cooperative_pick(&[], &[]).is_none());
    }
}
