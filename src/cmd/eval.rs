//! `rally eval`: hit rate, success rate, effort and mean activation of an agent on seeded
//! single-serve episodes (paper §V-B), with 95% intervals, a progress bar and all cores.

use std::io::Write;
use std::path::PathBuf;

use agents::eval::{evaluate_traced, EvalReport, Evaluation};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use sim::serve::ServeKind;

use super::{parse_preset, CliError};

/// Arguments of `rally eval`.
#[derive(Args, Debug)]
#[command(
    after_help = "Agents: scripted, scripted-drive, scripted-soft, a built-in checkpoint by name (kmac, kmac-rally, muscle-ppo, muscle-pd, dynsyn:\nbuilt into the binary) or a checkpoint file (rally train writes OUT/checkpoint.json).\n\n\
                  Examples:\n  rally eval scripted --episodes 200 --seed 1 --serve p2\n  rally eval scripted --model myochallenge --episodes 1000 --seed 2026\n                    rally eval mine.json --episodes 2 --mean-action --trace steps.jsonl"
)]
pub struct EvalArgs {
    /// The agent: a scripted variant's name or a checkpoint file.
    agent: String,
    /// Episodes to play.
    #[arg(long, default_value = "100", value_parser = clap::value_parser!(u64).range(1..=100_000))]
    episodes: u64,
    /// Evaluation seed (each episode derives its own serve and agent seeds from it).
    #[arg(long, default_value = "0")]
    seed: u64,
    /// Serve distribution: MyoChallenge p1 or p2, the paper's heuristic rally serve (from the
    /// other robot's hitting plane, as a rally starts), or stroke (a robot's return as a rally brings
    /// it after the serve: the rally serve with a stroke's error, about half outside the serve box).
    #[arg(long, default_value = "p2", value_parser = ["p1", "p2", "rally", "stroke"])]
    serve: String,
    /// Arena preset.
    #[arg(long, default_value = "myochallenge", value_parser = parse_preset)]
    preset: sim::Preset,
    /// Play a trained checkpoint's mean action, without the Gaussian noise it was trained with
    /// (`policy_std`, `action_noise`; K-MAC's noise on the activations as its expectation):
    /// nothing drawn.
    #[arg(long)]
    mean_action: bool,
    /// Begin every episode with a lead-in: the robot's own return (a stroke ball struck by it)
    /// flies away to the other hitting plane first, then the serve comes to the robot as that left
    /// it, as between two strokes of a rally. The serves are the same as without; the figures count
    /// from the serve on.
    #[arg(long)]
    lead_in: bool,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    /// Also write every control step to FILE, one JSON object a line: `episode`, `step`, `time`,
    /// the `observation` the network was given (before the checkpoint's normalisation), its
    /// `action` (the mean, before noise and controller) and the muscle `controls` written (about
    /// 1.5 MB an episode on the built-in robot; at most 100 episodes).
    #[arg(long, value_name = "FILE")]
    trace: Option<PathBuf>,
    #[command(flatten)]
    model: super::ModelArg,
}

fn print_table(r: &EvalReport, model: &str) {
    println!(
        "{} on {} {} serves{} (seed {}, model {model}):",
        r.agent,
        r.episodes,
        r.serve,
        if r.lead_in { " after a lead-in" } else { "" },
        r.seed
    );
    let rate = |name: &str, x: &agents::eval::Rate| {
        println!(
            "  {name:<16} {:>6.1}%   95% CI [{:.1}%, {:.1}%]",
            100.0 * x.value,
            100.0 * x.low,
            100.0 * x.high
        );
    };
    rate("hit rate", &r.hit_rate);
    rate("success rate", &r.success_rate);
    let mean = |name: &str, x: &agents::eval::Mean| {
        println!(
            "  {name:<16} {:>8.4}   95% CI [{:.4}, {:.4}]",
            x.value, x.low, x.high
        );
    };
    mean("effort", &r.effort);
    mean("mean activation", &r.mean_activation);
    if let Some(m) = &r.activation_to_contact {
        mean("  to contact", m);
    }
    if let (Some(m), Some(share)) = (&r.activation_after_contact, r.after_contact_steps) {
        println!(
            "    after contact  {:>8.4}   95% CI [{:.4}, {:.4}]   ({:.0}% of the steps)",
            m.value,
            m.low,
            m.high,
            100.0 * share
        );
    }
    let ends: Vec<String> = r.ends.iter().map(|(e, n)| format!("{e} {n}")).collect();
    println!("  endings          {}", ends.join(", "));
}

/// Runs `rally eval`.
pub fn run(args: &EvalArgs) -> Result<(), CliError> {
    let super::Body {
        model,
        config,
        name,
    } = args.model.load()?;
    if args.trace.is_some() && args.episodes > 100 {
        return Err(CliError::Usage(format!(
            "--trace: at most 100 episodes ({} asked): a trace holds every step's observation",
            args.episodes
        )));
    }
    let mut spec = super::player(&args.agent, &model, "AGENT")?;
    if args.mean_action {
        spec = spec.mean_action();
    }
    let kind = ServeKind::parse(&args.serve).expect("clap checked the serve's name");
    let bar = ProgressBar::new(args.episodes);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} episodes, {per_sec}, eta {eta}")
            .expect("valid template"),
    );
    let tick = || bar.inc(1);
    let evaluation = Evaluation {
        lead_in: args.lead_in,
        model,
        config,
        preset: args.preset,
        kind,
        episodes: args.episodes as usize,
        seed: args.seed,
    };
    let (report, trace) = evaluate_traced(&evaluation, &spec, &tick, args.trace.is_some())
        .map_err(|e| CliError::Failed(anyhow::anyhow!(e)))?;
    bar.finish_and_clear();
    if let Some(path) = &args.trace {
        write_trace(path, &trace)
            .map_err(|e| CliError::Failed(anyhow::anyhow!("--trace {}: {e}", path.display())))?;
    }
    if args.json {
        let mut v = serde_json::to_value(&report).map_err(anyhow::Error::from)?;
        v["model"] = name.into();
        println!("{v}");
    } else {
        print_table(&report, &name);
    }
    Ok(())
}

/// Writes `trace` to `path`, one JSON object a line (through a temporary file: a failed write
/// leaves no half-written trace).
fn write_trace(path: &std::path::Path, trace: &[agents::eval::TraceStep]) -> anyhow::Result<()> {
    let tmp = path.with_extension("partial");
    let mut out = std::io::BufWriter::new(std::fs::File::create(&tmp)?);
    for step in trace {
        serde_json::to_writer(&mut out, step)?;
        out.write_all(b"\n")?;
    }
    out.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    std::fs::rename(&tmp, path)?;
    Ok(())
}
