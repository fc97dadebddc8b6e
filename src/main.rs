//! `rally`: the one binary of muscle-rally, a thin clap front over the crates.
//!
//! Each subcommand lives in `cmd/` and does its I/O there; the physics stays in `sim`.
#![forbid(unsafe_code)]

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod cmd;

/// Self-play tournament server for musculoskeletal table-tennis robots (Diff-Muscle).
#[derive(Parser)]
#[command(name = "rally", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Simulate a free ball (a serve, or a state you give) and print its flight as JSON lines.
    Ball(Box<cmd::ball::BallArgs>),
    /// Submit a plan of matches and tournaments to a server, follow them, summarise, write CSV.
    Batch(cmd::batch::BatchArgs),
    /// Measure speed: the physics against MuJoCo on the same work, agents, training, the server.
    Bench(cmd::bench::BenchArgs),
    /// Policy checkpoints: template, built-in, observation/action spec, from ONNX, validate, scale noise.
    Checkpoint(cmd::checkpoint::CheckpointArgs),
    /// Evaluate an agent on seeded single-serve episodes: hit and success rates, effort.
    Eval(cmd::eval::EvalArgs),
    /// Play a match of dual-robot rallies between two agents: rallies, points, drift, replay.
    Match(cmd::matchcmd::MatchArgs),
    /// Inspect an MJCF model, or print its muscle lengths and moment arms at a configuration.
    Model(cmd::model::ModelArgs),
    /// The physics-based planner's racket command for a ball (paper §IV-B), as JSON.
    Plan(cmd::plan::PlanArgs),
    /// Draw the learning curves of training runs (reward, hit and success rate) as a PNG.
    Plot(cmd::plot::PlotArgs),
    /// Evaluate the committed checkpoints of the four methods: the paper's Table I, as markdown.
    Reproduce(cmd::reproduce::ReproduceArgs),
    /// Run the tournament server: REST API, match workers, leaderboard page, SQLite or PostgreSQL.
    Serve(cmd::serve::ServeArgs),
    /// Train a policy with PPO (Diff-Muscle or a baseline), resumable, with learning curves.
    Train(cmd::train::TrainArgs),
    /// Play queued matches from the server's database, without the HTTP server (scale-out).
    Worker(cmd::worker::WorkerArgs),
}

/// The exit status of a command whose reader went away (`rally … | head`): what a shell reports for
/// a process that SIGPIPE ended, 128 + 13.
const CLOSED_STDOUT: u8 = 141;

/// A closed stdout ends a command quietly, as in any shell pipeline, instead of the panic with which
/// `println!` meets it (Rust ignores SIGPIPE, so a write to a closed pipe is an error, not a signal).
fn quiet_on_closed_stdout() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let payload = info.payload();
        let msg = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or("");
        if msg.starts_with("failed printing to stdout") && msg.contains("Broken pipe") {
            std::process::exit(CLOSED_STDOUT.into());
        }
        default(info);
    }));
}

/// Whether a command failed only because its output's reader went away.
fn closed_stdout(err: &anyhow::Error) -> bool {
    err.chain().any(|e| {
        e.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

fn main() -> ExitCode {
    quiet_on_closed_stdout();
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Ball(args) => cmd::ball::run(&args),
        Command::Batch(args) => cmd::batch::run(&args),
        Command::Bench(args) => cmd::bench::run(&args),
        Command::Model(args) => cmd::model::run(&args),
        Command::Eval(args) => cmd::eval::run(&args),
        Command::Checkpoint(args) => cmd::checkpoint::run(&args),
        Command::Match(args) => cmd::matchcmd::run(&args),
        Command::Plan(args) => cmd::plan::run(&args),
        Command::Serve(args) => cmd::serve::run(&args),
        Command::Train(args) => cmd::train::run(&args),
        Command::Plot(args) => cmd::plot::run(&args),
        Command::Reproduce(args) => cmd::reproduce::run(&args),
        Command::Worker(args) => cmd::worker::run(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(cmd::CliError::Usage(msg)) => {
            eprintln!("error: {msg}");
            ExitCode::from(2)
        }
        Err(cmd::CliError::Failed(err)) if closed_stdout(&err) => ExitCode::from(CLOSED_STDOUT),
        Err(cmd::CliError::Failed(err)) => {
            eprintln!("error: {err:#}");
            ExitCode::FAILURE
        }
    }
}
