//! The scheduler: `settings.workers` async tasks, each claiming the oldest queued match
//! (queued → running, one transaction), playing it on a blocking thread with `agents`' match runner,
//! and storing rallies, crossings, replay and summary with the `done` mark in one transaction (or
//! marking it `failed`). A match cancelled while running is played out and its result discarded.
//! A match left `running` by a killed process is re-queued at the next start (`db::requeue_running`):
//! since results are written only with the `done` mark, none is lost and none counted twice.
//!
//! Continuous mode: when the queue is empty a worker queues a match for the agent whose rating
//! interval is widest (no interval counts as widest), against the opponent it has met least, at most
//! one every `continuous_pause_s` seconds. Continuous-mode matches store no replay frames (about
//! 50 kB a rally even gzipped); `GET /matches/{id}/replay` re-simulates such a rally on request,
//! bit-identical to the one played (rallies are independent: `agents::matchrun::replay_rally`).

use std::sync::Arc;
use std::time::Duration;

use agents::factory::PlayerSpec;
use agents::matchrun::MatchSpec;
use tokio::sync::{Mutex, Notify};
use tokio::task::JoinHandle;

use crate::{db, AppState};

/// Builds the player recipe of a stored agent.
pub fn player_spec(state: &AppState, kind: &str, spec: &str) -> Result<PlayerSpec, String> {
    match kind {
        "scripted" => {
            PlayerSpec::scripted(spec).ok_or_else(|| format!("unknown scripted agent '{spec}'"))
        }
        "checkpoint" => agents::checkpoint::Checkpoint::from_json(spec, &state.model)
            .map(|c| PlayerSpec::Checkpoint(Arc::new(c)))
            .map_err(|e| e.to_string()),
        other => Err(format!("unknown agent kind '{other}'")),
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

/// Plays stored match `m` to completion (blocking: call it off the async runtime). Each finished
/// rally goes to the match's live channel while anyone watches (frames with body poses; the frames
/// are recorded for that even when the match stores none, which changes no result).
pub fn play(
    state: &AppState,
    m: &db::Match,
    a: &PlayerSpec,
    b: &PlayerSpec,
) -> Result<(agents::matchrun::MatchRecord, agents::matchrun::Replay), String> {
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
    let (record, mut replay) = agents::matchrun::play_match_with(
        &spec,
        players,
        [a.name(), b.name()],
        &mut |k, rally, frames| {
            if let Some(tx) = live.as_ref().filter(|tx| tx.receiver_count() > 0) {
                let frames = serde_json::to_string(frames)
                    .map_err(|e| e.to_string())
                    .and_then(|f| crate::replay::with_body_poses(&state.model, &f));
                if let Ok(frames) = frames {
                    let msg = format!(
                        "{{\"match\":{},\"rally\":{k},\"rallies\":{},\"hz\":{},\"record\":{},\"frames\":{frames}}}",
                        m.id,
                        m.rallies,
                        agents::matchrun::REPLAY_HZ,
                        serde_json::to_string(rally).unwrap_or_else(|_| "null".into())
                    );
                    // A full channel drops its oldest message for a lagging viewer; never waits.
                    let _ = tx.send(Arc::new(msg));
                }
            }
        },
    )?;
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
    agents: [(String, String); 2],
    k: u32,
) -> Result<Vec<agents::matchrun::Frame>, String> {
    let [(ka, sa), (kb, sb)] = agents;
    if !specs_unchanged(m, &sa, &sb) {
        return Err("an agent's spec changed since the match was played".into());
    }
    let a = player_spec(state, &ka, &sa)?;
    let b = player_spec(state, &kb, &sb)?;
    agents::matchrun::replay_rally(&match_spec(state, m)?, &a, &b, k).map(|(_, frames)| frames)
}

/// Whether the agents' specs are still the ones match `m` was queued with.
fn specs_unchanged(m: &db::Match, spec_a: &str, spec_b: &str) -> bool {
    db::spec_hash(spec_a) == m.spec_hash_a && db::spec_hash(spec_b) == m.spec_hash_b
}

async fn run_one(state: &AppState, m: db::Match) -> anyhow::Result<()> {
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
        db::fail(
            &state.pool,
            m.id,
            "an agent's spec changed since the match was queued",
        )
        .await?;
        return Ok(());
    }
    let st = state.clone();
    let started = std::time::Instant::now();
    let result = tokio::task::spawn_blocking(move || {
        let a = player_spec(&st, &ka, &sa)?;
        let b = player_spec(&st, &kb, &sb)?;
        play(&st, &m, &a, &b)
    })
    .await;
    match result {
        Ok(Ok((record, replay))) => {
            // A busy database is retried; a match that still cannot be stored stays `running` and
            // is re-queued at the next start (nothing half-written: it is one transaction).
            let mut attempt = 0;
            let stored = loop {
                match db::store_result(&state.pool, id, &record, &replay).await {
                    Ok(stored) => break stored,
                    Err(e) if attempt < 5 => {
                        attempt += 1;
                        tracing::warn!(id, attempt, error = %e, "storing a match failed; retrying");
                        tokio::time::sleep(Duration::from_millis(200 * attempt)).await;
                    }
                    Err(e) => return Err(e.into()),
                }
            };
            if stored {
                state.publish("match", id, Some("done"));
            }
            tracing::info!(
                id,
                points_a = record.points[0],
                points_b = record.points[1],
                seconds = started.elapsed().as_secs_f64(),
                stored,
                "match finished"
            );
        }
        Ok(Err(e)) => {
            tracing::warn!(id, error = %e, "match failed");
            db::fail(&state.pool, id, &e).await?;
            state.publish("match", id, Some("failed"));
        }
        Err(join) => {
            let e = format!("match worker panicked: {join}");
            tracing::error!(id, error = %e);
            db::fail(&state.pool, id, &e).await?;
            state.publish("match", id, Some("failed"));
        }
    }
    Ok(())
}

/// Queues one continuous-mode match if the queue is empty; true if it did.
async fn queue_continuous(state: &AppState) -> anyhow::Result<bool> {
    let queued = db::matches(
        &state.pool,
        db::MatchFilter {
            status: Some("queued"),
            ..db::MatchFilter::default()
        },
        1,
    )
    .await?;
    if !queued.is_empty() {
        return Ok(false);
    }
    let agents = db::agents(&state.pool).await?;
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
    let met = |x: i64, y: i64| {
        outcomes
            .iter()
            .filter(|o| (o.0 == x && o.1 == y) || (o.0 == y && o.1 == x))
            .count()
    };
    let first = agents
        .iter()
        .max_by(|p, q| width(p.id).total_cmp(&width(q.id)).then(q.id.cmp(&p.id)))
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
    let seed = outcomes.len() as u64 + 1;
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

/// Starts the workers; they stop after `shutdown` is notified (a running match is finished first).
pub fn spawn_workers(state: AppState, shutdown: Arc<Notify>) -> Vec<JoinHandle<()>> {
    // When continuous mode last queued a match (it waits `continuous_pause_s` between them).
    let queue_lock: Arc<Mutex<Option<std::time::Instant>>> = Arc::new(Mutex::new(None));
    let stopping = Arc::new(std::sync::atomic::AtomicBool::new(false));
    {
        let (shutdown, stopping, wake) = (shutdown.clone(), stopping.clone(), state.wake.clone());
        tokio::spawn(async move {
            shutdown.notified().await;
            stopping.store(true, std::sync::atomic::Ordering::SeqCst);
            wake.notify_waiters();
        });
    }
    (0..state.settings.workers)
        .map(|w| {
            let (state, queue_lock, stopping) =
                (state.clone(), queue_lock.clone(), stopping.clone());
            tokio::spawn(async move {
                while !stopping.load(std::sync::atomic::Ordering::SeqCst) {
                    let claimed = db::claim(&state.pool).await;
                    match claimed {
                        Ok(Some(m)) => {
                            state.publish("match", m.id, Some("running"));
                            if let Err(e) = run_one(&state, m).await {
                                tracing::error!(worker = w, error = %e, "storing a match failed");
                            }
                            continue;
                        }
                        Ok(None) => {}
                        Err(e) => {
                            tracing::error!(worker = w, error = %e, "claiming a match failed")
                        }
                    }
                    if state.settings.continuous {
                        let mut last = queue_lock.lock().await;
                        let pause = Duration::from_secs_f64(state.settings.continuous_pause_s);
                        let due = last.is_none_or(|t| t.elapsed() >= pause);
                        match if due {
                            queue_continuous(&state).await
                        } else {
                            Ok(false)
                        } {
                            Ok(true) => {
                                *last = Some(std::time::Instant::now());
                                continue;
                            }
                            Ok(false) => {}
                            Err(e) => {
                                tracing::error!(worker = w, error = %e, "continuous mode failed")
                            }
                        }
                    }
                    let notified = state.wake.notified();
                    if stopping.load(std::sync::atomic::Ordering::SeqCst) {
                        break;
                    }
                    let _ = tokio::time::timeout(Duration::from_secs(1), notified).await;
                }
            })
        })
        .collect()
}
