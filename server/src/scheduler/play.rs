//! A match's lifecycle: its recipe, playing it (with the live feed), storing it, re-simulating a rally.

use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use agents::factory::PlayerSpec;
use agents::matchrun::MatchSpec;

use crate::db;
use crate::state::AppState;

/// The player recipe of a stored agent of match `m`'s robot, from the workers' cache (blocking on
/// a miss: the checkpoint is parsed and its network built).
pub fn player_spec(
    state: &AppState,
    m: &db::Match,
    kind: db::AgentKind,
    spec: &str,
) -> Result<PlayerSpec, String> {
    let arena = state.arenas.require(&m.model)?;
    state.players.get(&arena.model, kind, spec)
}

/// The match runner's recipe for stored match `m`: its robot, preset and simulator version must be
/// this server's.
pub fn match_spec(state: &AppState, m: &db::Match) -> Result<MatchSpec, String> {
    let arena = state.arenas.require(&m.model)?;
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
        model: arena.model.clone(),
        config: arena.config.clone(),
        preset,
        rallies: m.rallies as u32,
        seed: m.seed as u64,
        replay: m.keep_replay,
    })
}

/// Plays stored match `m` to completion (blocking: call it off the async runtime). While anyone
/// watches, the match's live channel gets the frames of the rally being played, [`crate::live::LIVE_CHUNK`]
/// at a time with body poses, and each rally's record as it ends (the frames are recorded for that
/// even when the match stores none, which changes no result). Sending never waits: a full channel
/// drops its oldest message for a viewer that lags.
pub fn play(
    state: &AppState,
    m: &db::Match,
    a: &PlayerSpec,
    b: &PlayerSpec,
    claimed: std::time::Instant,
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
    let mut chunk: Vec<agents::matchrun::Frame> = Vec::with_capacity(crate::live::LIVE_CHUNK);
    let mut recorded = 0usize;
    let head = |k: u32| {
        format!(
            "\"match\":{},\"rally\":{k},\"rallies\":{},\"hz\":{}",
            m.id,
            m.rallies,
            agents::matchrun::REPLAY_HZ
        )
    };
    let send_frames = |tx: &crate::live::LiveChannel,
                       k: u32,
                       recorded: usize,
                       chunk: &[agents::matchrun::Frame]| {
        let first = recorded - chunk.len();
        let frames = serde_json::to_string(chunk)
            .map_err(|e| e.to_string())
            .and_then(|f| crate::replay::with_body_poses(&spec.model, &f));
        if let Ok(frames) = frames {
            let data = format!("{{{},\"first\":{first},\"frames\":{frames}}}", head(k));
            let _ = tx.send(Arc::new(crate::live::LiveMsg {
                event: "frames",
                data,
            }));
        }
    };
    let mut first = true;
    let stop = state
        .playing
        .lock()
        .map_err(|_| "match registry poisoned".to_string())?
        .get(&m.id)
        .cloned();
    let (record, mut replay) =
        agents::matchrun::play_match_with(&spec, players, [a.name(), b.name()], &mut |e| {
            if std::mem::take(&mut first) {
                state.players.record_setup(claimed.elapsed());
            }
            let stopped = stop.as_ref().is_some_and(|s| s.load(Ordering::Relaxed));
            let watched = live.as_ref().filter(|tx| tx.receiver_count() > 0);
            match e {
                MatchEvent::Frame { rally, frame } => {
                    recorded += 1;
                    let Some(tx) = watched else {
                        // Nobody watches: keep nothing; a viewer who comes later starts here.
                        chunk.clear();
                        return ControlFlow::Continue(());
                    };
                    chunk.push(frame.clone());
                    if chunk.len() >= crate::live::LIVE_CHUNK {
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
                        let _ = tx.send(Arc::new(crate::live::LiveMsg {
                            event: "rally",
                            data,
                        }));
                    }
                    chunk.clear();
                    recorded = 0;
                }
            }
            if stopped {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
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
    let a = player_spec(state, m, ka, &sa)?;
    let b = player_spec(state, m, kb, &sb)?;
    agents::matchrun::replay_rally(&match_spec(state, m)?, &a, &b, k).map(|(_, frames)| frames)
}

/// A side of a match about to be played: its player from the cache, or the spec to build it from.
enum Side {
    Built(PlayerSpec),
    Spec(db::AgentKind, String),
}

/// Whether the agents' specs are still the ones match `m` was queued with.
fn specs_unchanged(m: &db::Match, spec_a: &str, spec_b: &str) -> bool {
    db::spec_hash(spec_a) == m.spec_hash_a && db::spec_hash(spec_b) == m.spec_hash_b
}

/// Both sides of match `m`: each agent's stored hash must still be the match's (none if one is not),
/// and its player comes from the cache by that hash; only a miss reads the spec (a checkpoint's
/// JSON, ~1 MB) for the blocking thread to build.
async fn sides(state: &AppState, m: &db::Match) -> anyhow::Result<Option<Vec<Side>>> {
    let mut sides = Vec::with_capacity(2);
    for (agent, queued_with) in [(m.agent_a, &m.spec_hash_a), (m.agent_b, &m.spec_hash_b)] {
        let (kind, hash) = db::agent_kind_and_hash(&state.pool, agent)
            .await?
            .ok_or_else(|| anyhow::anyhow!("agent {agent} no longer exists"))?;
        if &hash != queued_with {
            return Ok(None);
        }
        let side = match state.players.lookup(kind, &hash) {
            Some(player) => Side::Built(player),
            None => {
                let (kind, spec) = db::agent_spec(&state.pool, agent)
                    .await?
                    .ok_or_else(|| anyhow::anyhow!("agent {agent} no longer exists"))?;
                Side::Spec(kind, spec)
            }
        };
        sides.push(side);
    }
    Ok(Some(sides))
}

/// Stores a played match under its lease. A busy database is retried; a match that still cannot be
/// stored keeps its lease until the heartbeat stops (this process exits), then is queued again
/// (nothing half-written: it is one transaction).
async fn store_retrying(
    state: &AppState,
    lease: &db::Lease,
    record: &agents::matchrun::MatchRecord,
    frames: &[(i64, Vec<u8>)],
) -> anyhow::Result<db::Stored> {
    let quota = (state.settings.replay_quota_mb * (1u64 << 20) as f64) as u64;
    let mut attempt = 0;
    loop {
        match db::store_result(&state.pool, lease, record, frames, quota).await {
            Ok(stored) => return Ok(stored),
            Err(e) if attempt < 5 => {
                attempt += 1;
                let id = lease.match_id;
                tracing::warn!(id, attempt, error = %e, "storing a match failed; retrying");
                tokio::time::sleep(Duration::from_millis(200 * attempt)).await;
            }
            Err(e) => return Err(e.into()),
        }
    }
}

pub(super) async fn run_one(
    state: &AppState,
    m: db::Match,
    lease: db::Lease,
) -> anyhow::Result<()> {
    let claimed = std::time::Instant::now();
    if let Ok(mut playing) = state.playing.lock() {
        // Claimed as a shutdown's deadline passed: it stops at its first rally's end, queued again.
        let stop = state.shutting_down.load(Ordering::SeqCst);
        playing.insert(m.id, Arc::new(AtomicBool::new(stop)));
    }
    // The live channel first: the match is `running` from its claim on, so a viewer may ask for
    // its feed before the agents' specs are read (seen in CI: 409 while the specs were fetched).
    let id = m.id;
    if let Ok(mut live) = state.live.lock() {
        live.insert(
            id,
            tokio::sync::broadcast::channel(crate::live::LIVE_BUFFER).0,
        );
    }
    // Dropping the channel when this function returns ends every live viewer's stream.
    struct Unregister(AppState, i64);
    impl Drop for Unregister {
        fn drop(&mut self) {
            if let Ok(mut live) = self.0.live.lock() {
                live.remove(&self.1);
            }
            if let Ok(mut playing) = self.0.playing.lock() {
                playing.remove(&self.1);
            }
        }
    }
    let _unregister = Unregister(state.clone(), id);
    let Some(sides) = sides(state, &m).await? else {
        let error = "an agent's spec changed since the match was queued";
        if db::fail(&state.pool, &lease, error).await? == db::Stored::Done {
            state.publish_match(id, db::MatchStatus::Failed);
        }
        return Ok(());
    };
    let st = state.clone();
    let started = std::time::Instant::now();
    let result = tokio::task::spawn_blocking(move || {
        let mut built = sides.into_iter().map(|side| match side {
            Side::Built(player) => Ok(player),
            Side::Spec(kind, spec) => player_spec(&st, &m, kind, &spec),
        });
        let a = built.next().ok_or("no side A")??;
        let b = built.next().ok_or("no side B")??;
        let (record, replay) = play(&st, &m, &a, &b, claimed)?;
        // Compressed here, off the async threads: a 1 000-rally match's frames take seconds.
        let frames = db::compress_replay(&record, &replay);
        Ok::<_, String>((record, frames))
    })
    .await;
    let (stored, status) = match result {
        Ok(Ok((record, frames))) => {
            let stored = store_retrying(state, &lease, &record, &frames).await?;
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
            let stopped = state.playing.lock().ok().and_then(|p| p.get(&id).cloned());
            let stopped = stopped.is_some_and(|s| s.load(Ordering::SeqCst));
            if stopped && state.shutting_down.load(Ordering::SeqCst) {
                let queued = db::workers::release(&state.pool, &lease).await?;
                tracing::info!(id, queued, "stopped by the shutdown deadline: queued again");
                if queued {
                    state.publish_match(id, db::MatchStatus::Queued);
                }
                return Ok(());
            }
            if stopped {
                tracing::info!(id, "cancelled while playing: {e}");
            } else {
                tracing::warn!(id, error = %e, "match failed");
            }
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
