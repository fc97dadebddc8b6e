//! A training run's directory:
//!
//! - `checkpoint.json` — the policy in the agents' checkpoint format, with its provenance;
//! - `curve.csv` — one row per iteration (the learning curve);
//! - `validation.csv` and `best.json` — the held-out validations and the best checkpoint, when the
//!   configuration asks for them (`[validation]`);
//! - `resume/` — what `--resume` needs: `state.json` (configuration, counters, statistics,
//!   normaliser, Adam's step count and learning rate) and `tensors.safetensors` (actor, critic,
//!   log σ and Adam's moments).
//!
//! Every file is written to a temporary name and renamed into place, and `resume/` is replaced as a
//! whole (`resume.new/` → `resume/`, the old one kept as `resume.old/` until then), so a run killed
//! at any instant leaves a complete state behind.

use std::collections::HashMap;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};
use sim::model::Model;

use super::adam::Adam;
use super::normalizer::RunningNormalizer;
use super::trainer::{CurveRow, Progress, Trainer, ValidationPoint};
use super::{Method, TrainConfig};

/// Version of the resumable state's layout.
pub const STATE_VERSION: u32 = 1;

/// `resume/state.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunState {
    /// [`STATE_VERSION`].
    pub version: u32,
    /// What is trained.
    pub method: Method,
    /// The run's seed.
    pub seed: u64,
    /// Its configuration.
    pub config: TrainConfig,
    /// The robot it trains (`default`, `myochallenge` or a model file); runs saved before the
    /// choice existed trained the built-in body.
    #[serde(default = "built_in_body")]
    pub model: String,
    /// Counters, statistics and the curve.
    pub progress: Progress,
    /// Observation statistics.
    pub normalizer: RunningNormalizer,
    /// Statistics of what only a privileged critic sees (absent: the critic sees the observation).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub critic_normalizer: Option<RunningNormalizer>,
    /// Adam's steps taken.
    pub adam_steps: u64,
    /// The steps each variable took part in, where they differ from `adam_steps` (a run that
    /// began with a critic warm-up); absent: all of them took part in every step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adam_var_steps: Option<Vec<u64>>,
    /// The learning rate now.
    pub learning_rate: f64,
}

fn built_in_body() -> String {
    "default".into()
}

fn io(path: &Path, e: impl std::fmt::Display) -> String {
    format!("{}: {e}", path.display())
}

/// Writes `bytes` to `path` through a temporary file and a rename.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), String> {
    let tmp = path.with_extension("tmp");
    let mut f = fs::File::create(&tmp).map_err(|e| io(&tmp, e))?;
    f.write_all(bytes).map_err(|e| io(&tmp, e))?;
    f.sync_all().map_err(|e| io(&tmp, e))?;
    fs::rename(&tmp, path).map_err(|e| io(path, e))
}

/// What a warm start does with the optimiser of the run it starts from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WarmOptimiser {
    /// Take its moments, step count and adaptive learning rate (rsl_rl's `load`; the default).
    #[default]
    Carry,
    /// A fresh Adam at the configured learning rate (how warm starts were made before 2026-12-02).
    Fresh,
}

/// The run directory `dir`.
pub struct RunDir {
    /// Its path.
    pub dir: PathBuf,
}

impl RunDir {
    /// The run directory at `dir` (created if missing).
    pub fn open(dir: &Path) -> Result<RunDir, String> {
        fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
        Ok(RunDir {
            dir: dir.to_path_buf(),
        })
    }

    /// `checkpoint.json`.
    pub fn checkpoint_path(&self) -> PathBuf {
        self.dir.join("checkpoint.json")
    }

    /// `curve.csv`.
    pub fn curve_path(&self) -> PathBuf {
        self.dir.join("curve.csv")
    }

    /// `best.json`: the checkpoint of the best validation so far.
    pub fn best_path(&self) -> PathBuf {
        self.dir.join("best.json")
    }

    /// Rewrites `validation.csv` from the run's validations.
    pub fn write_validations(&self, points: &[ValidationPoint]) -> Result<(), String> {
        let mut out = String::from("iteration,env_steps,score,episodes,longest\n");
        for v in points {
            out.push_str(&format!(
                "{},{},{:.5},{},{}\n",
                v.iteration, v.env_steps, v.score, v.episodes, v.longest
            ));
        }
        write_atomic(&self.dir.join("validation.csv"), out.as_bytes())
    }

    fn resume_dir(&self) -> PathBuf {
        self.dir.join("resume")
    }

    /// Whether a resumable state is there (a complete `resume/`, or `resume.old/` left by a kill
    /// between the two renames).
    pub fn has_state(&self) -> bool {
        self.state_dir().is_some()
    }

    fn state_dir(&self) -> Option<PathBuf> {
        [self.resume_dir(), self.dir.join("resume.old")]
            .into_iter()
            .find(|d| d.join("state.json").is_file() && d.join("tensors.safetensors").is_file())
    }

    /// Saves the trainer's whole state, replacing the previous one.
    pub fn save_state(&self, t: &Trainer) -> Result<(), String> {
        let new = self.dir.join("resume.new");
        let _ = fs::remove_dir_all(&new);
        fs::create_dir_all(&new).map_err(|e| io(&new, e))?;
        let state = RunState {
            version: STATE_VERSION,
            method: t.method,
            seed: t.seed,
            config: t.config.clone(),
            model: t.model_name.clone(),
            progress: t.progress.clone(),
            normalizer: t.normalizer.clone(),
            critic_normalizer: t.critic_normalizer.clone(),
            adam_steps: t.adam.t,
            adam_var_steps: t
                .adam
                .var_steps
                .iter()
                .any(|&n| n != t.adam.t)
                .then(|| t.adam.var_steps.clone()),
            learning_rate: t.adam.lr,
        };
        let mut tensors: HashMap<String, Tensor> = t.net.named().into_iter().collect();
        for (k, (m, v)) in t.adam.m.iter().zip(&t.adam.v).enumerate() {
            tensors.insert(format!("adam.m.{k}"), m.clone());
            tensors.insert(format!("adam.v.{k}"), v.clone());
        }
        let tensor_path = new.join("tensors.safetensors");
        candle_core::safetensors::save(&tensors, &tensor_path).map_err(|e| io(&tensor_path, e))?;
        if let Some(balls) = &t.bank {
            let bank = crate::env::BallBank::to_json(balls, serde_json::json!({"refreshed": true}));
            write_atomic(&new.join("bank.json"), bank.to_string().as_bytes())?;
        }
        let json = serde_json::to_vec(&state).map_err(|e| e.to_string())?;
        write_atomic(&new.join("state.json"), &json)?;
        let cur = self.resume_dir();
        let old = self.dir.join("resume.old");
        let _ = fs::remove_dir_all(&old);
        if cur.exists() {
            fs::rename(&cur, &old).map_err(|e| io(&cur, e))?;
        }
        fs::rename(&new, &cur).map_err(|e| io(&new, e))?;
        let _ = fs::remove_dir_all(&old);
        Ok(())
    }

    /// Reads the saved state's description (without building a trainer).
    pub fn read_state(&self) -> Result<RunState, String> {
        let dir = self
            .state_dir()
            .ok_or_else(|| format!("{}: no resumable state (resume/)", self.dir.display()))?;
        let path = dir.join("state.json");
        let text = fs::read_to_string(&path).map_err(|e| io(&path, e))?;
        let state: RunState = serde_json::from_str(&text).map_err(|e| io(&path, e))?;
        if state.version != STATE_VERSION {
            return Err(io(
                &path,
                format!(
                    "state version {}; this build reads {STATE_VERSION}",
                    state.version
                ),
            ));
        }
        Ok(state)
    }

    /// The saved state's tensors.
    fn read_tensors(&self) -> Result<(PathBuf, HashMap<String, Tensor>), String> {
        let dir = self
            .state_dir()
            .ok_or_else(|| format!("{}: no resumable state (resume/)", self.dir.display()))?;
        let path = dir.join("tensors.safetensors");
        let tensors =
            candle_core::safetensors::load(&path, &Device::Cpu).map_err(|e| io(&path, e))?;
        Ok((path, tensors))
    }

    /// Sets the trainer's network (actor, critic, log σ) to the saved one, shape by shape.
    fn set_net(
        t: &mut Trainer,
        path: &Path,
        tensors: &HashMap<String, Tensor>,
    ) -> Result<(), String> {
        for (name, var) in t
            .net
            .named()
            .iter()
            .map(|(n, _)| n.clone())
            .zip(t.net.vars())
        {
            let saved = tensors
                .get(&name)
                .ok_or_else(|| io(path, format!("no tensor '{name}'")))?;
            if saved.dims() != var.dims() {
                return Err(io(
                    path,
                    format!(
                        "'{name}' has shape {:?}, expected {:?}",
                        saved.dims(),
                        var.dims()
                    ),
                ));
            }
            var.set(saved).map_err(|e| io(path, e))?;
        }
        Ok(())
    }

    /// Rebuilds the trainer of a run on the built-in body from the saved state.
    pub fn load(&self, model: Arc<Model>) -> Result<Trainer, String> {
        self.load_on(model, sim::config::ArenaConfig::default(), "default")
    }

    /// Rebuilds the trainer from the saved state, on `model` (which must be the one the run
    /// recorded, `model_name`) in the arena `arena` configures.
    pub fn load_on(
        &self,
        model: Arc<Model>,
        arena: sim::config::ArenaConfig,
        model_name: &str,
    ) -> Result<Trainer, String> {
        let state = self.read_state()?;
        if state.model != model_name {
            return Err(format!(
                "{} trains the {} robot, not {model_name}",
                self.dir.display(),
                state.model
            ));
        }
        let (path, tensors) = self.read_tensors()?;
        let mut t = Trainer::on(
            model,
            arena,
            model_name,
            state.method,
            state.config.clone(),
            state.seed,
        )?;
        Self::set_net(&mut t, &path, &tensors)?;
        Self::set_adam(&mut t, &state, &path, &tensors)?;
        if state.critic_normalizer.as_ref().map(|n| n.mean.len())
            != t.critic_normalizer.as_ref().map(|n| n.mean.len())
        {
            return Err(io(
                &path,
                "the critic's privileged statistics do not fit the run's critic",
            ));
        }
        t.normalizer = state.normalizer;
        t.critic_normalizer = state.critic_normalizer;
        t.progress = state.progress;
        let bank = path.with_file_name("bank.json");
        if bank.is_file() {
            let text = fs::read_to_string(&bank).map_err(|e| io(&bank, e))?;
            let balls = crate::env::BallBank::parse(&text).map_err(|e| io(&bank, e))?;
            t.set_bank(balls.into());
        }
        Ok(t)
    }

    /// Puts the saved optimiser (moments, step count, the adaptive schedule's learning rate) into `t`.
    fn set_adam(
        t: &mut Trainer,
        state: &RunState,
        path: &Path,
        tensors: &HashMap<String, Tensor>,
    ) -> Result<(), String> {
        let mut adam = Adam::new(t.net.vars(), state.learning_rate).map_err(|e| io(path, e))?;
        for k in 0..adam.m.len() {
            let take = |name: String| {
                tensors
                    .get(&name)
                    .cloned()
                    .ok_or_else(|| io(path, format!("no tensor '{name}'")))
            };
            adam.m[k] = take(format!("adam.m.{k}"))?;
            adam.v[k] = take(format!("adam.v.{k}"))?;
        }
        adam.t = state.adam_steps;
        adam.var_steps = match &state.adam_var_steps {
            Some(steps) if steps.len() == adam.m.len() => steps.clone(),
            Some(steps) => {
                return Err(io(
                    path,
                    format!(
                        "adam_var_steps holds {} counts for {} variables",
                        steps.len(),
                        adam.m.len()
                    ),
                ))
            }
            None => vec![state.adam_steps; adam.m.len()],
        };
        t.adam = adam;
        Ok(())
    }

    /// Starts the fresh run `t` from this run's policy, critic, observation statistics and optimiser
    /// (a warm start): the method must be the same; the counters and the curve start fresh. The
    /// optimiser comes along as rsl_rl's `load` brings it (moments and the adaptive schedule's
    /// learning rate): with a fresh one the first update ran at the configured rate and threw the
    /// policy far from its start (KL 1.2–2.0 in the first iteration against ~0.013 after it);
    /// [`WarmOptimiser::Fresh`] keeps that behaviour, to re-make the runs made with it.
    pub fn warm_start(&self, t: &mut Trainer, optimiser: WarmOptimiser) -> Result<(), String> {
        let state = self.read_state()?;
        if state.method != t.method {
            return Err(format!(
                "{} holds a {} run, not {}",
                self.dir.display(),
                state.method.name(),
                t.method.name()
            ));
        }
        if state.normalizer.mean.len() != t.obs_dim() {
            return Err(format!(
                "{}: observations of {} entries, this run has {}",
                self.dir.display(),
                state.normalizer.mean.len(),
                t.obs_dim()
            ));
        }
        if state.config.ppo.critic != t.config.ppo.critic {
            return Err(format!(
                "{}: ppo.critic is \"{}\" there, \"{}\" here (a warm start keeps the critic)",
                self.dir.display(),
                state.config.ppo.critic.name(),
                t.config.ppo.critic.name()
            ));
        }
        let (path, tensors) = self.read_tensors()?;
        Self::set_net(t, &path, &tensors)?;
        if optimiser == WarmOptimiser::Carry {
            Self::set_adam(t, &state, &path, &tensors)?;
        }
        t.normalizer = state.normalizer;
        t.critic_normalizer = state.critic_normalizer;
        t.progress.warm_start = Some(format!(
            "{} ({} steps, iteration {}; optimiser {})",
            self.dir.display(),
            state.progress.env_steps,
            state.progress.iteration,
            match optimiser {
                WarmOptimiser::Carry => "carried",
                WarmOptimiser::Fresh => "fresh",
            }
        ));
        Ok(())
    }

    /// Rewrites `curve.csv` from the rows.
    pub fn write_curve(&self, rows: &[CurveRow]) -> Result<(), String> {
        let mut out = String::from(
            "iteration,env_steps,wall_s,episodes,reward,length,hit_rate,success_rate,mean_activation,tracking,learning_rate,kl,value_loss,surrogate_loss,entropy,std,rally_length,dual,skipped\n",
        );
        for r in rows {
            out.push_str(&format!(
                "{},{},{:.3},{},{:.4},{:.2},{:.4},{:.4},{:.5},{:.5},{:.3e},{:.3e},{:.5},{:.5},{:.4},{:.4},{:.4},{:.4},{}\n",
                r.iteration,
                r.env_steps,
                r.wall_s,
                r.episodes,
                r.reward,
                r.length,
                r.hit_rate,
                r.success_rate,
                r.mean_activation,
                r.tracking,
                r.learning_rate,
                r.kl,
                r.value_loss,
                r.surrogate_loss,
                r.entropy,
                r.std,
                r.rally_length,
                r.dual,
                r.skipped_steps
            ));
        }
        write_atomic(&self.curve_path(), out.as_bytes())
    }
}

/// Reads a `curve.csv` back (for `rally plot`).
pub fn read_curve(path: &Path) -> Result<Vec<CurveRow>, String> {
    let text = fs::read_to_string(path).map_err(|e| io(path, e))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .ok_or_else(|| io(path, "empty"))?
        .split(',')
        .collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .ok_or_else(|| io(path, format!("no column '{name}'")))
    };
    let ce = col("episodes")?;
    let (ci, cs, cw, cr, ch, cu) = (
        col("iteration")?,
        col("env_steps")?,
        col("wall_s")?,
        col("reward")?,
        col("hit_rate")?,
        col("success_rate")?,
    );
    // Runs written before the rally environment have no rally_length column.
    let cl = col("rally_length").ok();
    let mut rows = Vec::new();
    for (k, line) in lines.enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        let num = |c: usize| -> Result<f64, String> {
            f.get(c).and_then(|v| v.parse::<f64>().ok()).ok_or_else(|| {
                io(
                    path,
                    format!("line {}: column {} is not a number", k + 2, header[c]),
                )
            })
        };
        rows.push(CurveRow {
            iteration: num(ci)? as u64,
            env_steps: num(cs)? as u64,
            wall_s: num(cw)?,
            episodes: num(ce)? as u64,
            reward: num(cr)?,
            hit_rate: num(ch)?,
            success_rate: num(cu)?,
            rally_length: match cl {
                Some(c) => num(c)?,
                None => 0.0,
            },
            ..CurveRow::default()
        });
    }
    Ok(rows)
}
