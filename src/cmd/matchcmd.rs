//! `rally match`: two agents play rallies in the dual arena; prints each rally, the points and the
//! trajectory drift, and optionally writes the replay.

use std::io::Write;
use std::path::PathBuf;

use agents::matchrun::{play_match, MatchRecord, MatchSpec};
use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;

use super::{parse_preset, CliError};

/// Arguments of `rally match`.
#[derive(Args, Debug)]
#[command(
    after_help = "Agents: scripted, scripted-drive, scripted-soft, a built-in checkpoint by name (kmac, kmac-rally, muscle-ppo, muscle-pd, dynsyn:\nbuilt into the binary) or a checkpoint file. A serves the even rallies, B the odd ones.\n\
                  The same agents, rallies, preset and seed give byte-identical output (and replay).\n\n\
                  Example:\n  rally match scripted scripted-drive --rallies 20 --seed 1 --replay replay.json"
)]
pub struct MatchArgs {
    /// Agent on side A (x > 0).
    a: String,
    /// Agent on side B (x < 0).
    b: String,
    /// Rallies to play.
    #[arg(long, default_value = "20", value_parser = clap::value_parser!(u32).range(1..=10_000))]
    rallies: u32,
    /// Match seed.
    #[arg(long, default_value = "0")]
    seed: u64,
    /// Write the replay (ball, paddles and joint positions at 50 Hz, per rally) to this JSON file.
    #[arg(long, value_name = "FILE")]
    replay: Option<PathBuf>,
    /// Arena preset.
    #[arg(long, default_value = "myochallenge", value_parser = parse_preset)]
    preset: sim::Preset,
    /// Print the match record as one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    /// Also write every legal return of the match, as its receiver met it, to this JSON file: a ball
    /// bank for training on the balls a rally brings (`[bank] file` in a training configuration).
    #[arg(long, value_name = "FILE")]
    returns: Option<PathBuf>,
    #[command(flatten)]
    model: super::ModelArg,
}

fn print_table(r: &MatchRecord) {
    println!(
        "{} (A) vs {} (B), {} rallies, seed {}:",
        r.a,
        r.b,
        r.rallies.len(),
        r.seed
    );
    for x in &r.rallies {
        println!(
            "  rally {:>3}  served by {}  length {:>3}  {:<14} {}",
            x.index,
            x.server,
            x.length,
            x.end,
            x.failing_side
                .map(|s| format!("failed: {s}"))
                .unwrap_or_default()
        );
    }
    println!("  points A {} – B {}", r.points[0], r.points[1]);
    println!(
        "  rally length mean {:.2}, max {}",
        r.mean_rally_length, r.max_rally_length
    );
    let d = &r.drift;
    let e = d
        .energy_distance
        .map(|e| format!("{e:.4}"))
        .unwrap_or_else(|| "n/a".into());
    println!(
        "  crossings {} ({:.0}% in the serve box), serve→return energy distance {e}",
        d.crossings,
        100.0 * d.in_box_fraction
    );
}

/// Runs `rally match`.
pub fn run(args: &MatchArgs) -> Result<(), CliError> {
    let super::Body {
        model,
        config,
        name,
    } = args.model.load()?;
    let (a, b) = (
        super::player(&args.a, &model, "A")?,
        super::player(&args.b, &model, "B")?,
    );
    let spec = MatchSpec {
        model,
        config,
        preset: args.preset,
        rallies: args.rallies,
        seed: args.seed,
        replay: args.replay.is_some(),
    };
    let bar = ProgressBar::new(args.rallies as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} rallies, eta {eta}")
            .expect("valid template"),
    );
    let (record, replay) = play_match(&spec, &a, &b, &mut |_| bar.inc(1))
        .map_err(|e| CliError::Failed(anyhow::anyhow!(e)))?;
    bar.finish_and_clear();
    if let Some(path) = &args.replay {
        let doc = json!({
            "sim_version": sim::SIM_VERSION,
            "a": record.a, "b": record.b, "seed": record.seed, "preset": record.preset,
            "model": name,
            "hz": agents::matchrun::REPLAY_HZ,
            "rallies": replay,
        });
        let mut f =
            std::fs::File::create(path).with_context(|| format!("--replay {}", path.display()))?;
        serde_json::to_writer(&mut f, &doc).context("writing the replay")?;
        f.flush().context("writing the replay")?;
    }
    if let Some(path) = &args.returns {
        let balls = agents::matchrun::record_returns(&spec, &a, &b)
            .map_err(|e| CliError::Failed(anyhow::anyhow!(e)))?;
        let doc = agents::env::BallBank::to_json(
            &balls,
            json!({
                "command": std::env::args().collect::<Vec<_>>().join(" "),
                "a": record.a, "b": record.b, "rallies": args.rallies, "seed": args.seed,
                "preset": record.preset, "sim_version": sim::SIM_VERSION,
            }),
        );
        std::fs::write(
            path,
            serde_json::to_string(&doc).map_err(anyhow::Error::from)?,
        )
        .with_context(|| format!("--returns {}", path.display()))?;
        eprintln!(
            "{} legal returns written to {}",
            balls.len(),
            path.display()
        );
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string(&record).map_err(anyhow::Error::from)?
        );
    } else {
        print_table(&record);
    }
    Ok(())
}
