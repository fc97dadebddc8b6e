//! Admission: a submitted checkpoint validated and qualified in a child process under a CPU-time and
//! a memory budget (`rally checkpoint admit`), held to the qualification thresholds; the built-in
//! checkpoints registered at start (trusted: admitted in process).

use std::path::PathBuf;
use std::process::Stdio;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use agents::admit::Admission;
use agents::eval::EvalReport;
use tokio::io::AsyncWriteExt;

use crate::settings::{Settings, EMBEDDED_BUILTINS};
use crate::state::AppState;
use crate::{api, db};

/// Exit status of `rally checkpoint admit` when it could not set itself up (its limits, its
/// input): the server's failure (a 500), not the checkpoint's.
pub const ADMIT_SETUP_FAILED: i32 = 3;

/// Why a submitted checkpoint was not admitted.
#[derive(Debug)]
pub enum Refused {
    /// Not a valid checkpoint of the server's model: the field and what.
    Invalid(String),
    /// Valid, but its network failed in the qualification.
    Failed(String),
    /// It used the CPU time `admission_cpu_s` allows (s), or its process ran past its wall-clock
    /// bound ([`wall_bound`]).
    OverCpu(f64),
    /// Its process was killed (SIGKILL: its hard CPU limit, or the kernel's out-of-memory killer).
    Killed,
    /// It asked for more memory than `admission_memory_mb` allows (MiB; what failed).
    OverMemory(u64, String),
    /// Its admission process died otherwise (how).
    Crashed(String),
    /// `admission_queue` submissions already wait for their turn.
    Busy,
}

/// The wall-clock bound on an admission process: four times its CPU budget and 10 s (its CPU
/// limit ends it first unless it waits on nothing; this bounds a machine so loaded that it waits).
pub fn wall_bound(settings: &Settings) -> Duration {
    Duration::from_secs_f64(4.0 * settings.admission_cpu_s + 10.0)
}

/// Admits a submitted checkpoint: one admission at a time (each uses every core), in a child
/// process of this executable (`rally checkpoint admit`) that limits its own CPU time
/// (`admission_cpu_s`) and memory (`admission_memory_mb`), so a graph that allocates without
/// bound or runs without end costs the server neither memory nor its threads. The outer error is
/// the server's (the child could not be started), the inner one the checkpoint's. `robot` is the
/// robot the checkpoint names, one this server plays: the child loads it (from the data directory
/// for MyoSuite's) and qualifies the checkpoint in its arena.
pub async fn admit_submission(
    state: &AppState,
    robot: &str,
    text: String,
) -> anyhow::Result<Result<EvalReport, Refused>> {
    let s = &state.settings;
    let waiting = state.admit_waiting.fetch_add(1, Ordering::SeqCst);
    let _leave = Leave(&state.admit_waiting);
    if waiting >= s.admission_queue {
        return Ok(Err(Refused::Busy));
    }
    let _turn = state
        .admit
        .acquire()
        .await
        .map_err(|e| anyhow::anyhow!("admission queue closed: {e}"))?;
    // This very executable, even if its file was replaced or removed since it started.
    let exe = match std::path::Path::new("/proc/self/exe").exists() {
        true => std::path::PathBuf::from("/proc/self/exe"),
        false => std::env::current_exe().map_err(|e| {
            anyhow::anyhow!("the server's executable, to run the admission in: {e}")
        })?,
    };
    let mut child = tokio::process::Command::new(exe)
        .args(["checkpoint", "admit", "--episodes"])
        .arg(s.qualification_episodes.to_string())
        .args(["--seed", "0", "--cpu-s"])
        .arg(s.admission_cpu_s.to_string())
        .arg("--memory-mb")
        .arg(s.admission_memory_mb.to_string())
        .args(["--model", robot])
        // Nothing of the server's environment (its admin token, its database's password) but
        // where the imported robots are.
        .env_clear()
        .env("RALLY_DATA_DIR", crate::settings::data_dir())
        .env("RUST_LOG", "warn")
        .env("RUST_BACKTRACE", "0")
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .kill_on_drop(true)
        .spawn()
        .map_err(|e| anyhow::anyhow!("starting the admission process: {e}"))?;
    if let Some(mut stdin) = child.stdin.take() {
        // A child that died before reading all of it says why in its status.
        tokio::spawn(async move {
            let _ = stdin.write_all(text.as_bytes()).await;
        });
    }
    let Ok(out) = tokio::time::timeout(wall_bound(s), child.wait_with_output()).await else {
        // Dropping the child killed it.
        return Ok(Err(Refused::OverCpu(s.admission_cpu_s)));
    };
    let out = out.map_err(|e| anyhow::anyhow!("waiting for the admission process: {e}"))?;
    if out.status.code() == Some(ADMIT_SETUP_FAILED) {
        anyhow::bail!(
            "the admission process could not set itself up: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(judge(s, &out))
}

/// Counts itself out of the admission queue when dropped.
struct Leave<'a>(&'a AtomicUsize);

impl Drop for Leave<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

const SIGKILL: i32 = libc::SIGKILL;
const SIGXCPU: i32 = libc::SIGXCPU;

/// What an admission process's exit and output say.
fn judge(s: &Settings, out: &std::process::Output) -> Result<EvalReport, Refused> {
    use std::os::unix::process::ExitStatusExt;
    let stderr = String::from_utf8_lossy(&out.stderr);
    // Rust's own words when an allocation fails outside a place that can report it.
    if let Some(line) = stderr.lines().find(|l| l.contains("memory allocation of")) {
        return Err(Refused::OverMemory(
            s.admission_memory_mb,
            line.trim().into(),
        ));
    }
    if out.status.success() {
        let stdout = String::from_utf8_lossy(&out.stdout);
        let line = stdout.lines().last().unwrap_or_default();
        return match serde_json::from_str::<Admission>(line) {
            Ok(a) => outcome(s, a),
            Err(e) => Err(Refused::Crashed(format!(
                "its admission process answered no outcome ({e})"
            ))),
        };
    }
    match out.status.signal() {
        // SIGXCPU at the soft CPU limit.
        Some(SIGXCPU) => Err(Refused::OverCpu(s.admission_cpu_s)),
        Some(SIGKILL) => Err(Refused::Killed),
        signal => {
            let last = stderr.lines().rev().find(|l| !l.trim().is_empty());
            Err(Refused::Crashed(format!(
                "its admission process ended with {}{}",
                match (signal, out.status.code()) {
                    (Some(sig), _) => format!("signal {sig}"),
                    (None, Some(code)) => format!("exit code {code}"),
                    _ => "an unknown status".into(),
                },
                last.map(|l| format!(": {}", l.trim())).unwrap_or_default()
            )))
        }
    }
}

fn outcome(s: &Settings, a: Admission) -> Result<EvalReport, Refused> {
    match a {
        Admission::Qualified { report } => Ok(*report),
        Admission::Invalid { error } => Err(Refused::Invalid(error)),
        Admission::Failed { error } => Err(Refused::Failed(error)),
        Admission::OverMemory { error } => Err(Refused::OverMemory(s.admission_memory_mb, error)),
    }
}

/// Admits a trusted checkpoint (a built-in) of `arena`'s robot in this process, on the blocking
/// pool, in turn with the submissions.
async fn admit_builtin(
    state: &AppState,
    arena: &crate::arenas::Arena,
    text: String,
) -> anyhow::Result<Admission> {
    let eval = agents::eval::Evaluation {
        lead_in: false,
        model: arena.model.clone(),
        config: arena.config.clone(),
        preset: sim::arena::MYOCHALLENGE,
        kind: sim::serve::ServeKind::P2,
        episodes: state.settings.qualification_episodes,
        seed: 0,
    };
    let _turn = state
        .admit
        .acquire()
        .await
        .map_err(|e| anyhow::anyhow!("admission queue closed: {e}"))?;
    tokio::task::spawn_blocking(move || agents::admit::admit(&text, &eval))
        .await
        .map_err(|e| anyhow::anyhow!("admission panicked: {e}"))
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

/// Registers every checkpoint `settings.builtin_checkpoints` names that is not an agent yet, as a
/// built-in agent of `arena`'s robot named after its file ([`crate::arenas::builtin_name`]: the
/// default robot's from the directory itself, another robot's from its subdirectory of the robot's
/// name), qualified like a submission. A checkpoint that does not load or qualify is skipped with a
/// warning (the committed ones are held to loading by a test); a name already taken keeps its agent.
pub(crate) async fn register_builtin_checkpoints(
    state: &AppState,
    arena: &crate::arenas::Arena,
) -> anyhow::Result<()> {
    let root = &state.settings.builtin_checkpoints;
    let robot = arena.name.as_str();
    let named = |stem: &str| crate::arenas::builtin_name(robot, stem);
    // (name, where it comes from, its text or why it has none)
    let sources: Vec<(String, String, Result<String, String>)> = if root.as_os_str().is_empty() {
        return Ok(());
    } else if root.as_os_str() == EMBEDDED_BUILTINS {
        agents::builtins::of_robot(robot)
            .iter()
            .map(|(name, text)| {
                let from = format!("embedded {robot} {name}.json");
                (named(name), from, Ok(text.to_string()))
            })
            .collect()
    } else {
        let dir = if robot == sim::config::DEFAULT_ROBOT {
            root.clone()
        } else {
            root.join(robot)
        };
        let mut files: Vec<PathBuf> = match std::fs::read_dir(&dir) {
            Ok(entries) => entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "json"))
                .collect(),
            Err(e) => {
                tracing::warn!(dir = %dir.display(), "no built-in checkpoints of robot {robot}: {e}");
                return Ok(());
            }
        };
        files.sort();
        files
            .into_iter()
            .filter_map(|path| {
                let name = named(&path.file_stem()?.to_string_lossy());
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
        let text = match text {
            Ok(text) => text,
            Err(e) => {
                tracing::warn!(%path, "built-in checkpoint skipped: {e}");
                continue;
            }
        };
        let report = match admit_builtin(state, arena, text.clone()).await? {
            Admission::Qualified { report } => *report,
            other => {
                tracing::warn!(%path, "built-in checkpoint skipped: {other:?}");
                continue;
            }
        };
        if let Err(e) = admits(&state.settings, &report) {
            tracing::warn!(%name, "built-in checkpoint did not qualify: {e}");
            continue;
        }
        let qual = (
            report.episodes,
            report.hit_rate.value,
            report.success_rate.value,
            report.effort.value,
        );
        let id =
            db::insert_checkpoint_agent(&state.pool, &name, robot, &text, qual, true, None).await?;
        state.publish_agent(id);
        tracing::info!(%name, hit = qual.1, success = qual.2, "built-in checkpoint registered");
    }
    Ok(())
}
