//! `rally checkpoint`: write a template checkpoint of the right shape, or validate one; name the
//! entries a method's network reads and writes, and wrap an ONNX network trained elsewhere ([`onnx`]).

mod onnx;

use std::path::{Path, PathBuf};

use agents::checkpoint::{Activation, Checkpoint};
use agents::controller::{ControllerKind, ControllerSpec, PdGains, Synergies};
use clap::{Args, Subcommand, ValueEnum};
use sim::model::Model;

use super::CliError;

/// Arguments of `rally checkpoint`.
#[derive(Args, Debug)]
pub struct CheckpointArgs {
    #[command(subcommand)]
    command: CheckpointCommand,
    #[command(flatten)]
    model: super::ModelArg,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Act {
    Elu,
    Tanh,
    Relu,
}

#[derive(Subcommand, Debug)]
enum CheckpointCommand {
    /// Print a zero-weight checkpoint for the robot (JSON; `--model`, default the built-in body), to
    /// fill with trained weights.
    Template {
        /// Controller the policy drives.
        #[arg(long, default_value = "kmac", value_parser = ["kmac", "muscle_pd", "direct", "dynsyn"])]
        controller: String,
        /// Hidden layer widths, comma-separated.
        #[arg(long, default_value = "256,256", value_delimiter = ',')]
        hidden: Vec<usize>,
        /// Hidden-layer activation.
        #[arg(long, value_enum, default_value = "elu")]
        activation: Act,
        /// Name stored in the checkpoint.
        #[arg(long, default_value = "template")]
        name: String,
    },
    /// Print a built-in checkpoint (kmac, kmac-rally, muscle-ppo, muscle-pd, dynsyn; with `--model
    /// myochallenge`, those of MyoSuite's robot: an unknown name lists them) as JSON: a trained
    /// policy to start from or to submit under another name.
    Builtin {
        /// Its name.
        name: String,
    },
    /// Name every entry of the observation a method's network reads (normalised first, with the
    /// checkpoint's observation.mean and observation.std) and of the action it writes (each clipped
    /// to [-1, 1]), in order, on the robot (`--model`). What a network trained elsewhere must
    /// match. Example: rally checkpoint spec --method kmac --json
    Spec {
        /// kmac (Diff-Muscle's joint targets), muscle (Muscle-PPO: every muscle's control),
        /// muscle-pd (muscle-length targets) or dynsyn (synergy weights).
        #[arg(long)]
        method: String,
        /// `rally train`'s configuration whose [controller] section the method uses (default: its
        /// built-in defaults, as `rally train` without --config).
        #[arg(long)]
        config: Option<PathBuf>,
        /// As JSON: {model, method, normalised, observation: [names], action: [names]}.
        #[arg(long)]
        json: bool,
    },
    /// Wrap an ONNX network trained elsewhere (observation batch -> action batch, float32, shapes
    /// as `rally checkpoint spec` names them) in a checkpoint the server and `rally eval` accept,
    /// validated first (graph, widths, what it may allocate). It plays the network's output as the
    /// mean action, without noise.
    /// Example: rally checkpoint from-onnx policy.onnx --method kmac --obs-norm norm.json --name mine --out mine.json
    FromOnnx {
        /// The ONNX file.
        file: PathBuf,
        /// The method whose controller turns its actions into muscle controls (see `spec`).
        #[arg(long)]
        method: String,
        /// `rally train`'s configuration whose [controller] section to use (gains, K-MAC's
        /// activation clamp and activation noise — a K-MAC trained with that noise draws it in play
        /// as training did; set it to 0 to play the activations as computed — and the grip floor),
        /// and its `replan` (how the command is made); default: the built-in defaults.
        #[arg(long)]
        config: Option<PathBuf>,
        /// JSON {"mean": [...], "std": [...]} applied to the observation before the network, as
        /// (x - mean) / std (default: none, mean 0 and std 1).
        #[arg(long)]
        obs_norm: Option<PathBuf>,
        /// The name stored in the checkpoint (and the agent's on the server).
        #[arg(long)]
        name: String,
        /// Where to write it (default: standard output).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Check a checkpoint against the robot (`--model`); prints its shape, or the field that is wrong.
    Validate {
        /// Checkpoint file.
        file: PathBuf,
    },
    /// Write a trained checkpoint that plays with FACTOR times the Gaussian action noise it was
    /// trained with (its `policy_std`): the same network, less (or more) exploration noise in play.
    /// The factor is kept in its provenance (`training.noise_scale`), so the trained σ is still known.
    /// Example: rally checkpoint scale-noise runs/x/best.json --factor 0.5 --out half.json
    ScaleNoise {
        /// Checkpoint file.
        file: PathBuf,
        /// Multiplies every entry of `policy_std` (0: play the mean action).
        #[arg(long)]
        factor: f64,
        /// Name stored in the new checkpoint (default: the old one's).
        #[arg(long)]
        name: Option<String>,
        /// Where to write it (not the input file).
        #[arg(long)]
        out: PathBuf,
        /// Appended to its provenance note: why this factor (e.g. how it was chosen).
        #[arg(long)]
        note: Option<String>,
    },
    /// The server's admission of a submitted checkpoint, in a process of its own: reads the
    /// checkpoint from standard input, sets its own CPU-time and memory limits, validates it against
    /// the robot (`--model`) and plays the qualification; prints the outcome as one JSON line
    /// (`agents::admit::Admission`). Past the CPU limit the kernel stops it (SIGXCPU); past the
    /// memory limit its allocations fail. `rally serve` runs it for every upload.
    #[command(hide = true)]
    Admit {
        /// Qualification episodes (P2 serves).
        #[arg(long, default_value_t = 100)]
        episodes: usize,
        /// Qualification seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// CPU time this process may use, all threads together, s (rounded up to whole seconds).
        #[arg(long)]
        cpu_s: f64,
        /// Memory it may allocate (its data segment and anonymous mappings), MiB.
        #[arg(long)]
        memory_mb: u64,
    },
}

/// Runs `rally checkpoint`.
pub fn run(args: &CheckpointArgs) -> Result<(), CliError> {
    // The admission loads its robot itself: a robot that does not load is the server's failure
    // (its setup), not the checkpoint's.
    if let CheckpointCommand::Admit {
        episodes,
        seed,
        cpu_s,
        memory_mb,
    } = &args.command
    {
        return admit(&args.model, *episodes, *seed, *cpu_s, *memory_mb);
    }
    let body = args.model.load()?;
    let model = body.model.clone();
    match &args.command {
        CheckpointCommand::Builtin { name } => builtin(sim::config::robot_name(&model), name),
        CheckpointCommand::Template {
            controller,
            hidden,
            activation,
            name,
        } => template(&model, controller, hidden, *activation, name),
        CheckpointCommand::Validate { file } => validate(&model, file),
        CheckpointCommand::Spec {
            method,
            config,
            json,
        } => onnx::spec(&model, method, config.as_deref(), *json),
        CheckpointCommand::FromOnnx {
            file,
            method,
            config,
            obs_norm,
            name,
            out,
        } => onnx::from_onnx(
            &model,
            &onnx::FromOnnx {
                file,
                method,
                config: config.as_deref(),
                obs_norm: obs_norm.as_deref(),
                name,
                out: out.as_ref(),
            },
        ),
        CheckpointCommand::ScaleNoise {
            file,
            factor,
            name,
            out,
            note,
        } => scale_noise(&model, file, *factor, name.as_deref(), out, note.as_deref()),
        CheckpointCommand::Admit { .. } => unreachable!("admitted above"),
    }
}

/// `rally checkpoint builtin NAME`: prints robot `robot`'s embedded checkpoint.
fn builtin(robot: &str, name: &str) -> Result<(), CliError> {
    let text = agents::builtins::checkpoint_of(robot, name).ok_or_else(|| {
        CliError::Usage(format!(
            "no built-in checkpoint '{name}' of the {robot} robot; there are: {}",
            agents::builtins::names_of(robot).join(", ")
        ))
    })?;
    println!("{}", text.trim_end());
    Ok(())
}

/// `rally checkpoint template`: prints a zero-weight checkpoint of the robot's shape.
fn template(
    model: &Model,
    controller: &str,
    hidden: &[usize],
    activation: Act,
    name: &str,
) -> Result<(), CliError> {
    let spec = match controller {
        "kmac" => ControllerSpec::Kmac {
            gains: PdGains { kp: 40.0, kd: 3.0 },
            activation_clamp: None,
            activation_noise: None,
            clamp_coupled: false,
        },
        "muscle_pd" => ControllerSpec::MusclePd {
            gains: PdGains::MUSCLE_PD,
        },
        "direct" => ControllerSpec::Direct,
        _ => ControllerSpec::Dynsyn {
            synergies: Synergies::derive(model, 16, 0),
        },
    };
    if hidden.contains(&0) {
        return Err(CliError::Usage(
            "--hidden: layer widths must be positive".into(),
        ));
    }
    let act = match activation {
        Act::Elu => Activation::Elu,
        Act::Tanh => Activation::Tanh,
        Act::Relu => Activation::Relu,
    };
    let c = Checkpoint::template(model, name, spec, hidden, act);
    c.validate(model)
        .map_err(|e| CliError::Usage(e.to_string()))?;
    println!(
        "{}",
        serde_json::to_string(&c).map_err(anyhow::Error::from)?
    );
    Ok(())
}

/// `rally checkpoint validate FILE`: checks it against the robot and prints its shape.
fn validate(model: &Model, file: &Path) -> Result<(), CliError> {
    let text = std::fs::read_to_string(file)
        .map_err(|e| CliError::Usage(format!("{}: {e}", file.display())))?;
    let c = Checkpoint::from_json(&text, model)
        .map_err(|e| CliError::Usage(format!("{}: {e}", file.display())))?;
    let kind: ControllerKind = c.controller.kind();
    println!(
        "{}: valid — '{}', {:?} controller, observation {} entries, {}",
        file.display(),
        c.name,
        kind,
        c.observation.mean.len(),
        match &c.policy {
            Some(p) => format!(
                "MLP of {} layers, {} parameters",
                p.layers.len(),
                p.parameters()
            ),
            None => "ONNX network".to_string(),
        }
    );
    Ok(())
}

/// The longest message an admission outcome carries, bytes: a hostile checkpoint's field names and
/// tract's words about its nodes come back to the server and into the 422.
const MAX_MESSAGE: usize = 2048;

/// `rally checkpoint admit`: limits itself, reads the checkpoint from standard input, prints the
/// admission's outcome.
fn admit(
    robot: &super::ModelArg,
    episodes: usize,
    seed: u64,
    cpu_s: f64,
    memory_mb: u64,
) -> Result<(), CliError> {
    if !(cpu_s.is_finite() && cpu_s > 0.0) || memory_mb == 0 {
        return Err(CliError::Usage(
            "--cpu-s and --memory-mb must be positive".into(),
        ));
    }
    if let Err(e) = limit_self(cpu_s, memory_mb) {
        eprintln!("rally checkpoint admit: {e}");
        std::process::exit(server::ADMIT_SETUP_FAILED);
    }
    let body = robot.load().unwrap_or_else(|e| {
        let why = match e {
            CliError::Usage(m) => m,
            CliError::Failed(e) => format!("{e:#}"),
        };
        eprintln!("rally checkpoint admit: loading the robot: {why}");
        std::process::exit(server::ADMIT_SETUP_FAILED);
    });
    // Panics are caught and become outcomes; their default report would only echo hostile text.
    std::panic::set_hook(Box::new(|_| {}));
    let mut text = String::new();
    if let Err(e) = std::io::Read::read_to_string(&mut std::io::stdin().lock(), &mut text) {
        eprintln!("rally checkpoint admit: reading the checkpoint: {e}");
        std::process::exit(server::ADMIT_SETUP_FAILED);
    }
    let eval = agents::eval::Evaluation {
        lead_in: false,
        model: body.model,
        config: body.config,
        preset: sim::arena::MYOCHALLENGE,
        kind: sim::serve::ServeKind::P2,
        episodes,
        seed,
    };
    let outcome = shortened(agents::admit::admit(&text, &eval));
    let line = serde_json::to_string(&outcome).map_err(|e| CliError::Failed(e.into()))?;
    println!("{line}");
    Ok(())
}

/// CPU time (the soft limit sends SIGXCPU, which ends the process; the hard one a second later
/// SIGKILL), memory (its data segment and private mappings: allocations past it fail), no core
/// dumps, and first in line for the kernel's out-of-memory killer. A limit above what this process
/// may have is lowered to that.
fn limit_self(cpu_s: f64, memory_mb: u64) -> Result<(), String> {
    use rlimit::Resource;
    let cpu = cpu_s.ceil() as u64;
    let bytes = memory_mb.saturating_mul(1 << 20);
    for (resource, name, soft, hard) in [
        (Resource::CPU, "CPU time", cpu, cpu + 1),
        (Resource::DATA, "memory", bytes, bytes),
        (Resource::CORE, "core dumps", 0, 0),
    ] {
        let (_, max) = resource
            .get()
            .map_err(|e| format!("reading the {name} limit: {e}"))?;
        resource
            .set(soft.min(max), hard.min(max))
            .map_err(|e| format!("setting the {name} limit: {e}"))?;
    }
    // Best effort: a kernel without it, or a sandbox that hides /proc, still has the limits above.
    let _ = std::fs::write("/proc/self/oom_score_adj", "1000");
    Ok(())
}

/// The outcome with its message cut to [`MAX_MESSAGE`] bytes.
fn shortened(outcome: agents::admit::Admission) -> agents::admit::Admission {
    use agents::admit::Admission;
    let cut = |mut s: String| {
        if s.len() > MAX_MESSAGE {
            let mut end = MAX_MESSAGE;
            while !s.is_char_boundary(end) {
                end -= 1;
            }
            s.truncate(end);
            s.push_str(" …");
        }
        s
    };
    match outcome {
        Admission::Invalid { error } => Admission::Invalid { error: cut(error) },
        Admission::Failed { error } => Admission::Failed { error: cut(error) },
        Admission::OverMemory { error } => Admission::OverMemory { error: cut(error) },
        qualified @ Admission::Qualified { .. } => qualified,
    }
}

/// `rally checkpoint scale-noise FILE`: writes it to `out` with `factor` times its action noise.
fn scale_noise(
    model: &Model,
    file: &Path,
    factor: f64,
    name: Option<&str>,
    out: &Path,
    note: Option<&str>,
) -> Result<(), CliError> {
    if !(factor.is_finite() && factor >= 0.0) {
        return Err(CliError::Usage(format!(
            "--factor {factor}: expected a finite number ≥ 0"
        )));
    }
    let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    };
    if same(file, out) {
        return Err(CliError::Usage(
            "--out: give another file than the input".into(),
        ));
    }
    let text = std::fs::read_to_string(file)
        .map_err(|e| CliError::Usage(format!("{}: {e}", file.display())))?;
    let mut c = Checkpoint::from_json(&text, model)
        .map_err(|e| CliError::Usage(format!("{}: {e}", file.display())))?;
    c.scale_noise(factor)
        .map_err(|e| CliError::Usage(format!("{}: {e}", file.display())))?;
    if let Some(n) = name {
        c.name = n.to_string();
    }
    if let (Some(t), Some(extra)) = (c.training.as_mut(), note) {
        t.note = Some(match t.note.take() {
            Some(old) => format!("{old} {extra}"),
            None => extra.to_string(),
        });
    }
    c.validate(model)
        .map_err(|e| CliError::Usage(e.to_string()))?;
    let json = serde_json::to_string(&c).map_err(anyhow::Error::from)?;
    std::fs::write(out, json).map_err(|e| CliError::Usage(format!("{}: {e}", out.display())))?;
    println!(
        "{}: '{}' plays with {} × its trained action noise",
        out.display(),
        c.name,
        c.training
            .as_ref()
            .and_then(|t| t.noise_scale)
            .unwrap_or(factor)
    );
    Ok(())
}
