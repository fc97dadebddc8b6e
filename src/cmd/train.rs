//! `rally train`: PPO on one of the paper's methods in the single-serve or the rally environment, with a progress
//! bar, a checkpoint and resumable state every `checkpoint_every` iterations, and the learning curve
//! as CSV and PNG. A run killed at any moment continues with `--resume` as the same run (the same
//! numbers as if it had never stopped).

use std::path::{Path, PathBuf};

use agents::ppo::store::{write_atomic, RunDir};
use agents::ppo::trainer::{CurveRow, Trainer, ValidationPoint};
use agents::ppo::{Method, TrainConfig, TrainEnv, TrainServe};
use anyhow::anyhow;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use super::CliError;

/// Arguments of `rally train`.
#[derive(Args, Debug)]
#[command(after_help = "Examples:\n  \
    rally train --method kmac --steps 2000000 --seed 1 --out runs/kmac\n  \
    rally train --method kmac --steps 4000000 --seed 1 --out runs/kmac --resume   (continue, or extend)\n  \
    rally train --method kmac --env rally --init runs/kmac --steps 4000000 --seed 2 --out runs/kmac-rally\n  \
    rally train --method kmac --init config/checkpoints/kmac.json --critic-warmup 20 --steps 2e6 --seed 3 --out runs/kmac-more\n  \
    rally plot runs/kmac runs/muscle --out curves.png\n\n\
    Writes OUT/checkpoint.json (the agents' checkpoint format: rally eval OUT/checkpoint.json),\n\
    OUT/curve.csv, OUT/curve.png and OUT/resume/ (what --resume reads). With [validation] every = K\n\
    in the configuration, every K iterations the policy plays held-out episodes (self-play rallies in\n\
    the rally environment): OUT/validation.csv, and OUT/best.json is the best so far (OUT/best/ its resumable state:\n--init OUT/best starts a run from it).")]
pub struct TrainArgs {
    /// The method: kmac (Diff-Muscle), muscle (Muscle-PPO), muscle-pd or dynsyn.
    #[arg(long, value_parser = parse_method)]
    method: Method,
    /// The environment: single (single serves) or rally (the dual arena, the policy on both robots);
    /// default: the configuration's `env` (config/train.toml: single).
    #[arg(long, value_parser = parse_env)]
    env: Option<TrainEnv>,
    /// Training serves of the single-serve environment: p2 (MyoChallenge P2), p1 (MyoChallenge P1:
    /// a jittered position, a fixed velocity), rally (the paper's
    /// heuristic rally serve, the official code's training serve) or stroke (a robot's return: the
    /// rally serve with a stroke's error, half of them outside the serve box; ours); default: the
    /// configuration's.
    #[arg(long, value_parser = parse_serve)]
    serve: Option<TrainServe>,
    /// Start from the weights, observation statistics and optimiser (its adaptive learning rate too)
    /// of the run in this directory (a warm start, e.g. --env rally --init runs/kmac); the counters
    /// and the curve start fresh. What it reads is the run's resumable state (DIR/resume/), saved
    /// every `checkpoint_every` iterations: a run that ended between two is taken from the last.
    /// Or start from a checkpoint file (a committed one, say) of the same method, controller and
    /// observation: its policy, σ and observation statistics; critic and optimiser fresh, so give
    /// --critic-warmup too.
    #[arg(long, conflicts_with = "resume")]
    init: Option<PathBuf>,
    /// With --init DIR: carry the start's optimiser (moments and learning rate, as rsl_rl loads
    /// one; the default) or start a fresh one at the configured learning rate, whose first update
    /// moves a trained policy far (how the committed runs before 2026-12-02 were made; re-make
    /// them with `fresh`). A checkpoint file holds no optimiser: its runs start a fresh one.
    #[arg(long, value_enum, requires = "init")]
    init_optimizer: Option<InitOptimizer>,
    /// Iterations at the run's start in which only the critic learns (the policy keeps still):
    /// ppo.critic_warmup laid over the configuration. Needed with --init FILE, whose critic is
    /// fresh (e.g. 20; 0 to start the policy's updates at once).
    #[arg(long)]
    critic_warmup: Option<u64>,
    /// Control steps to simulate in all (every environment's steps count), e.g. 2000000 or 2e6.
    #[arg(long, value_parser = parse_steps)]
    steps: u64,
    /// Training seed: the initial weights, every training serve and the action noise derive from it.
    #[arg(long, default_value = "1")]
    seed: u64,
    /// Run directory.
    #[arg(long)]
    out: PathBuf,
    /// Continue the run saved in OUT (its method, seed and configuration must match).
    #[arg(long)]
    resume: bool,
    /// Hyperparameters, reward weights and controller gains (TOML); default config/train.toml's values.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Name written into the checkpoint (default: the method's checkpoint name).
    #[arg(long)]
    name: Option<String>,
    /// No progress bar; one line per checkpoint instead.
    #[arg(long)]
    quiet: bool,
    #[command(flatten)]
    model: super::ModelArg,
}

fn parse_method(s: &str) -> Result<Method, String> {
    s.parse()
}

fn parse_serve(s: &str) -> Result<TrainServe, String> {
    match s {
        "p2" => Ok(TrainServe::P2),
        "p1" => Ok(TrainServe::P1),
        "rally" => Ok(TrainServe::Rally),
        "stroke" => Ok(TrainServe::Stroke),
        _ => Err(format!(
            "'{s}': the training serves are p2, p1, rally and stroke"
        )),
    }
}

fn parse_env(s: &str) -> Result<TrainEnv, String> {
    match s {
        "single" => Ok(TrainEnv::Single),
        "rally" => Ok(TrainEnv::Rally),
        _ => Err(format!("'{s}': the environments are single and rally")),
    }
}

/// Parses a positive step count, plain or in e-notation (clap value parser).
pub fn parse_steps(s: &str) -> Result<u64, String> {
    let x: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a number"))?;
    if !(1.0..=1e12).contains(&x) {
        return Err("must be between 1 and 1e12 control steps".into());
    }
    Ok(x as u64)
}

/// Reads a training configuration file (TOML); unknown keys are refused with their name.
pub fn read_config(path: &Path) -> Result<TrainConfig, CliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| CliError::Usage(format!("--config {}: {e}", path.display())))?;
    let c: TrainConfig = toml::from_str(&text)
        .map_err(|e| CliError::Usage(format!("--config {}: {e}", path.display())))?;
    c.validate()
        .map_err(|e| CliError::Usage(format!("--config {}: {e}", path.display())))?;
    Ok(c)
}

/// The git commit this binary was built from (`-dirty` when tracked files differed from it at build
/// time), or "unknown" outside a checkout; recorded by `build.rs`.
pub fn git_commit() -> String {
    env!("RALLY_GIT_COMMIT").to_string()
}

/// One progress line; `follow_ons` adds a single-serve run's legal returns per episode.
fn status_line(r: &CurveRow, steps_per_s: f64, env: TrainEnv, follow_ons: bool) -> String {
    let rally = match env {
        TrainEnv::Single if follow_ons => format!("  returns {:.2}", r.rally_length),
        TrainEnv::Single => String::new(),
        TrainEnv::Rally => format!("  rally {:.2}  in box {:.2}", r.rally_length, r.dual),
    };
    let skipped = match r.skipped_steps {
        0 => String::new(),
        n => format!("  ({n} non-finite steps skipped)"),
    };
    format!(
        "{:>7.0} steps/s  reward {:>7.1}  hit {:>5.1}%  success {:>5.1}%{rally}  lr {:.1e}  kl {:.4}{skipped}",
        steps_per_s,
        r.reward,
        100.0 * r.hit_rate,
        100.0 * r.success_rate,
        r.learning_rate,
        r.kl
    )
}

/// Saves the checkpoint, the curve (CSV and PNG) and, at a segment boundary, the resumable state.
fn save(out: &Outputs, t: &Trainer, with_state: bool) -> Result<(), CliError> {
    let dir = &out.dir;
    let ck = t
        .checkpoint(&out.name, &out.command, &out.commit)
        .map_err(|e| anyhow!(e))?;
    let json = serde_json::to_vec(&ck).map_err(anyhow::Error::from)?;
    write_atomic(&dir.checkpoint_path(), &json).map_err(|e| anyhow!(e))?;
    dir.write_curve(&t.progress.curve).map_err(|e| anyhow!(e))?;
    let series = [super::plot::Series {
        label: t.method.paper_name().to_string(),
        rows: t.progress.curve.clone(),
    }];
    if let Err(e) = super::plot::learning_curves(&series, &dir.dir.join("curve.png")) {
        eprintln!("warning: curve.png not written: {e}");
    }
    if with_state {
        dir.save_state(t).map_err(|e| anyhow!(e))?;
    }
    Ok(())
}

/// What a validation measured, in words.
fn validation_words(env: TrainEnv, v: &ValidationPoint) -> String {
    match env {
        TrainEnv::Rally => format!(
            "mean rally {:.3} (longest {}) over {} self-play rallies",
            v.score, v.longest, v.episodes
        ),
        TrainEnv::Single => format!(
            "success {:.1}% over {} episodes",
            100.0 * v.score,
            v.episodes
        ),
    }
}

/// Validates the policy (`[validation]` of the configuration), records it in the run's
/// `validation.csv` and, when it is the best so far, writes it to `best.json` with a note that says
/// how it was chosen.
fn validate(out: &Outputs, t: &mut Trainer, bar: &ProgressBar) -> Result<(), CliError> {
    let dir = &out.dir;
    let point = t.validate().map_err(|e| anyhow!(e))?;
    let best_before = t.progress.best_validation().map(|b| b.score);
    t.progress.validations.push(point);
    let words = validation_words(t.config.validation_env(), &point);
    let is_best = best_before.is_none_or(|b| point.score > b);
    if is_best {
        let mut ck = t
            .validation_checkpoint(&out.name, &out.command, &out.commit)
            .map_err(|e| anyhow!(e))?;
        if let Some(tr) = ck.training.as_mut() {
            tr.note = Some(format!(
                "The best of the run's validations so far: iteration {} ({} steps), {words}, validation seed {} (the same serves at every validation; report figures on other seeds){}.",
                point.iteration,
                point.env_steps,
                t.config.validation.seed,
                match t.config.validation.noise_scale {
                    1.0 => String::new(),
                    s => format!("; validated, and kept, at {s} × its trained action noise"),
                }
            ));
        }
        let json = serde_json::to_vec(&ck).map_err(anyhow::Error::from)?;
        write_atomic(&dir.best_path(), &json).map_err(|e| anyhow!(e))?;
        // Its whole state too, so that a warm start can begin from the best (`--init OUT/best`).
        RunDir::open(&dir.dir.join("best"))
            .and_then(|b| b.save_state(t))
            .map_err(|e| anyhow!(e))?;
    }
    dir.write_validations(&t.progress.validations)
        .map_err(|e| anyhow!(e))?;
    let line = format!(
        "validation at iteration {} ({} steps): {words}{}",
        point.iteration,
        point.env_steps,
        if is_best {
            "  (best so far: best.json)"
        } else {
            ""
        }
    );
    say(bar, line);
    Ok(())
}

/// Runs `rally train`.
pub fn run(args: &TrainArgs) -> Result<(), CliError> {
    agents::ppo::tune_candle_threads();
    let body = args.model.load()?;
    let config = configuration(args)?;
    let dir = RunDir::open(&args.out).map_err(|e| CliError::Usage(format!("--out: {e}")))?;
    let mut trainer = if args.resume {
        resume(args, &dir, &config, body)?
    } else {
        start(args, &dir, config, body)?
    };
    trainer.steps_target = args.steps;
    let out = Outputs {
        dir,
        name: args
            .name
            .clone()
            .unwrap_or_else(|| match trainer.config.env {
                TrainEnv::Single => args.method.checkpoint_name().to_string(),
                TrainEnv::Rally => format!("{}-rally", args.method.checkpoint_name()),
            }),
        command: std::env::args()
            .map(|a| if a.contains(' ') { format!("'{a}'") } else { a })
            .collect::<Vec<_>>()
            .join(" "),
        commit: git_commit(),
    };
    let every = trainer.config.ppo.checkpoint_every as u64;
    let bar = progress_bar(args, &trainer);
    let started = std::time::Instant::now();
    train(args, &mut trainer, &out, &bar, started)?;
    let at_boundary = trainer.progress.iteration.is_multiple_of(every);
    save(&out, &trainer, at_boundary)?;
    bar.finish_and_clear();
    report(args, &trainer, &out.dir, started);
    if !at_boundary {
        let last = trainer.progress.iteration - trainer.progress.iteration % every;
        if last == 0 {
            println!(
                "(no resumable state: the run ended before its first {every} iterations \
                 (checkpoint_every); run it again without --resume to start over; --init cannot start from it)"
            );
        } else {
            println!(
                "(the resumable state is from iteration {last}; --resume continues from there, \
                 and --init starts from it)"
            );
        }
    }
    Ok(())
}

/// Where and as what the run's checkpoints are written.
struct Outputs {
    dir: RunDir,
    /// The checkpoints' name.
    name: String,
    /// The command line, recorded in the checkpoints.
    command: String,
    /// The binary's commit, recorded too.
    commit: String,
}

/// The configuration: `--config`'s (else the default), with `--env` and `--serve` laid over it.
fn configuration(args: &TrainArgs) -> Result<TrainConfig, CliError> {
    let mut config = match &args.config {
        Some(p) => read_config(p)?,
        None => TrainConfig::default(),
    };
    if let Some(env) = args.env {
        config.env = env;
    }
    if let Some(serve) = args.serve {
        config.serve = serve;
    }
    if let Some(n) = args.critic_warmup {
        config.ppo.critic_warmup = n;
    }
    Ok(config)
}

/// The run saved in `dir`, refused unless the arguments describe the same run.
fn resume(
    args: &TrainArgs,
    dir: &RunDir,
    config: &TrainConfig,
    body: super::Body,
) -> Result<Trainer, CliError> {
    let state = dir
        .read_state()
        .map_err(|e| CliError::Usage(format!("--resume: {e}")))?;
    if state.method != args.method || state.seed != args.seed {
        return Err(CliError::Usage(format!(
            "--resume: {} holds a {} run with seed {}, not {} with seed {}",
            args.out.display(),
            state.method.name(),
            state.seed,
            args.method.name(),
            args.seed
        )));
    }
    if let Some(env) = args.env.filter(|&e| e != state.config.env) {
        return Err(CliError::Usage(format!(
            "--resume: {} was trained in the {} environment, not {}",
            args.out.display(),
            state.config.env.name(),
            env.name()
        )));
    }
    if let Some(serve) = args.serve.filter(|&s| s != state.config.serve) {
        return Err(CliError::Usage(format!(
            "--resume: {} was trained on {:?} serves, not {serve:?}",
            args.out.display(),
            state.config.serve
        )));
    }
    if let Some(n) = args
        .critic_warmup
        .filter(|&n| n != state.config.ppo.critic_warmup)
    {
        return Err(CliError::Usage(format!(
            "--resume: {} was started with --critic-warmup {}, not {n}",
            args.out.display(),
            state.config.ppo.critic_warmup
        )));
    }
    // What the flags lay over the configuration file was checked above; where a flag is left
    // out, the run's own value stands (so a resume needs only the file it started with).
    let mut config = config.clone();
    config.env = state.config.env;
    config.serve = state.config.serve;
    config.ppo.critic_warmup = state.config.ppo.critic_warmup;
    if args.config.is_some() && state.config != config {
        return Err(CliError::Usage(format!(
            "--resume: --config differs from the configuration {} was started with",
            args.out.display()
        )));
    }
    if state.model != body.name {
        return Err(CliError::Usage(format!(
            "--resume: {} trains the {} robot, not {} (--model)",
            args.out.display(),
            state.model,
            body.name
        )));
    }
    Ok(dir
        .load_on(body.model, body.config, &body.name)
        .map_err(|e| anyhow!(e))?)
}

/// A fresh run in `dir` (which must not hold one), warm-started from `--init` if given.
fn start(
    args: &TrainArgs,
    dir: &RunDir,
    config: TrainConfig,
    body: super::Body,
) -> Result<Trainer, CliError> {
    if dir.has_state() {
        return Err(CliError::Usage(format!(
            "--out {} already holds a run: pass --resume to continue it, or choose another directory",
            args.out.display()
        )));
    }
    let model = body.model.clone();
    let mut t = Trainer::on(
        body.model,
        body.config,
        &body.name,
        args.method,
        config,
        args.seed,
    )
    .map_err(|e| anyhow!(e))?;
    if let Some(init) = args.init.as_ref().filter(|p| !p.exists()) {
        return Err(CliError::Usage(format!(
            "--init {}: no such file or directory (a run directory or a checkpoint file)",
            init.display()
        )));
    }
    match &args.init {
        Some(init) if init.is_file() => {
            if args.init_optimizer == Some(InitOptimizer::Carry) {
                return Err(CliError::Usage(format!(
                    "--init-optimizer carry: {} is a checkpoint file, which holds no optimiser",
                    init.display()
                )));
            }
            if args.critic_warmup.is_none() && t.config.ppo.critic_warmup == 0 {
                return Err(CliError::Usage(format!(
                    "--init {}: a checkpoint brings a policy but no critic; give --critic-warmup N \
                     (or ppo.critic_warmup: iterations in which only the fresh critic learns, e.g. \
                     20; 0 for none)",
                    init.display()
                )));
            }
            let text = std::fs::read_to_string(init)
                .map_err(|e| CliError::Usage(format!("--init {}: {e}", init.display())))?;
            let ck = agents::checkpoint::Checkpoint::from_json(&text, &model)
                .map_err(|e| CliError::Usage(format!("--init {}: {e}", init.display())))?;
            t.warm_start_from_checkpoint(&ck, &init.display().to_string())
                .map_err(|e| CliError::Usage(format!("--init: {e}")))?;
        }
        Some(init) => {
            let optimiser = args.init_optimizer.unwrap_or(InitOptimizer::Carry);
            RunDir::open(init)
                .and_then(|d| d.warm_start(&mut t, optimiser.into()))
                .map_err(|e| CliError::Usage(format!("--init: {e}")))?;
        }
        None => {}
    }
    Ok(t)
}

/// The bar of the steps to `--steps` (hidden with `--quiet`), at the run's steps so far.
fn progress_bar(args: &TrainArgs, trainer: &Trainer) -> ProgressBar {
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(args.steps)
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {human_pos}/{human_len} steps, eta {eta}  {msg}")
            .expect("valid template"),
    );
    bar.set_position(trainer.progress.env_steps.min(args.steps));
    bar
}

/// A line above the bar, or on stderr when it is hidden.
fn say(bar: &ProgressBar, line: String) {
    if bar.is_hidden() {
        eprintln!("{line}");
    } else {
        bar.println(line);
    }
}

/// Iterates until `--steps`, validating, refreshing the bank and saving at their intervals.
fn train(
    args: &TrainArgs,
    trainer: &mut Trainer,
    out: &Outputs,
    bar: &ProgressBar,
    started: std::time::Instant,
) -> Result<(), CliError> {
    let every = trainer.config.ppo.checkpoint_every as u64;
    let first_steps = trainer.progress.env_steps;
    while trainer.progress.env_steps < args.steps {
        let row = trainer.iterate().map_err(|e| anyhow!(e))?;
        let rate = (row.env_steps - first_steps) as f64 / started.elapsed().as_secs_f64();
        bar.set_position(row.env_steps.min(args.steps));
        bar.set_message(status_line(
            &row,
            rate,
            trainer.config.env,
            trainer.config.follow_on > 0.0,
        ));
        let v_every = trainer.config.validation.every as u64;
        if v_every > 0 && row.iteration.is_multiple_of(v_every) {
            validate(out, trainer, bar)?;
        }
        let r_every = trainer.config.bank.refresh_every as u64;
        if r_every > 0 && row.iteration.is_multiple_of(r_every) {
            let n = trainer.refresh_bank().map_err(|e| anyhow!(e))?;
            let line = format!(
                "bank at iteration {}: {n} returns of the policy in {} self-play rallies",
                row.iteration, trainer.config.bank.refresh_rallies
            );
            say(bar, line);
        }
        let boundary = row.iteration.is_multiple_of(every);
        if boundary {
            save(out, trainer, true)?;
            if args.quiet {
                eprintln!(
                    "iteration {} ({} steps): {}",
                    row.iteration,
                    row.env_steps,
                    status_line(
                        &row,
                        rate,
                        trainer.config.env,
                        trainer.config.follow_on > 0.0
                    )
                );
            }
        }
    }
    Ok(())
}

/// What the run did: its steps and time split, the last episodes, where the checkpoint and the best
/// validation are.
fn report(args: &TrainArgs, trainer: &Trainer, dir: &RunDir, started: std::time::Instant) {
    let last = trainer.progress.curve.last().copied().unwrap_or_default();
    let t = trainer.timing;
    let session = if t.env_steps == 0 {
        // A resumed run that had already reached --steps.
        "nothing left to train this session: the run had reached --steps".to_string()
    } else {
        let all = (t.simulation + t.policy + t.update).max(1e-9);
        format!(
            "{:.0} steps/s this session: simulation {:.0}%, policy {:.0}%, update {:.0}%",
            t.env_steps as f64 / started.elapsed().as_secs_f64(),
            100.0 * t.simulation / all,
            100.0 * t.policy / all,
            100.0 * t.update / all,
        )
    };
    println!(
        "{}: {} steps in {} iterations, {:.0} s of training ({session})",
        args.method.paper_name(),
        last.env_steps,
        last.iteration,
        last.wall_s,
    );
    println!(
        "last {} training episodes: reward {:.1}, hit {:.1}%, success {:.1}% (predicted landing)",
        trainer.progress.recent.len(),
        last.reward,
        100.0 * last.hit_rate,
        100.0 * last.success_rate
    );
    println!("checkpoint: {}", dir.checkpoint_path().display());
    if let Some(b) = trainer.progress.best_validation() {
        println!(
            "best on validation: iteration {} ({} steps), {}: {}",
            b.iteration,
            b.env_steps,
            validation_words(trainer.config.validation_env(), b),
            dir.best_path().display()
        );
    }
}

/// `--init-optimizer`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum InitOptimizer {
    /// The start's moments and learning rate.
    Carry,
    /// A fresh optimiser at the configured learning rate.
    Fresh,
}

impl From<InitOptimizer> for agents::ppo::store::WarmOptimiser {
    fn from(o: InitOptimizer) -> Self {
        match o {
            InitOptimizer::Carry => Self::Carry,
            InitOptimizer::Fresh => Self::Fresh,
        }
    }
}
