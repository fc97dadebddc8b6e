//! Admission: a submitted (or built-in) checkpoint validated off the async threads within a budget,
//! qualified on P2 serves, held to the thresholds; the built-in checkpoints registered at start.

use std::path::PathBuf;
use std::sync::Arc;

use crate::settings::{Settings, EMBEDDED_BUILTINS};
use crate::state::AppState;
use crate::{api, db};

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
pub(crate) async fn register_builtin_checkpoints(state: &AppState) -> anyhow::Result<()> {
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
