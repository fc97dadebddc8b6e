//! `rally reproduce`: the paper's Table I in our simulator, on the default robot or (`--model
//! myochallenge`) MyoSuite's. Evaluates the committed checkpoints of the four methods
//! (`config/checkpoints/{kmac,muscle-ppo,muscle-pd,dynsyn}.json`, `config/checkpoints/ROBOT/` for
//! another robot) and the scripted house agent on MyoChallenge P2 serves (seeds the training never drew: training serves come from
//! their own streams of the training seed), and writes a markdown report with 95% intervals, the
//! seeds, the paper's numbers beside ours, each checkpoint's provenance and the learning curves.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use agents::checkpoint::Checkpoint;
use agents::eval::{evaluate, EvalReport, Evaluation};
use agents::factory::PlayerSpec;
use agents::ppo::trainer::CurveRow;
use agents::ppo::Method;
use anyhow::anyhow;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use sim::model::Model;
use sim::serve::ServeKind;

use super::plot::{learning_curves, Series};
use super::CliError;

mod ablations;
mod report;
use report::{rally_section, report};

/// The paper's Table I: hit %, success %, effort.
pub fn paper_row(m: Method) -> (f64, f64, f64) {
    match m {
        Method::Muscle => (76.4, 43.0, 0.035),
        Method::Dynsyn => (84.5, 62.6, 0.0310),
        Method::MusclePd => (90.5, 72.9, 0.0365),
        Method::Kmac => (95.1, 80.3, 0.0278),
    }
}

/// Arguments of `rally reproduce`.
#[derive(Args, Debug)]
#[command(
    after_help = "Examples:\n  rally reproduce --episodes 1000 --seed 2026 --rallies 200\n  \
                  (writes docs/reproduce.md, docs/reproduce_curves.png, docs/reproduce_rallies.png, docs/reproduce_returns.png)\n  \
                  rally reproduce --model myochallenge --seed 2027\n  \
                  (MyoSuite's robot: config/checkpoints/myochallenge/ to docs/reproduce-myochallenge.md and its PNGs)\n  \
                  rally reproduce --ablations --rallies 0\n  \
                  (also the ablations of config/checkpoints/ablations/: docs/reproduce_ablations.png)"
)]
pub struct ReproduceArgs {
    /// Episodes per agent.
    #[arg(long, default_value = "1000", value_parser = clap::value_parser!(u64).range(1..=100_000))]
    episodes: u64,
    /// Evaluation seed: episode i has the serve and agent seeds `episode_seeds(seed, i)`.
    #[arg(long, default_value = "2026")]
    seed: u64,
    /// Where the committed checkpoints are (default: config/checkpoints, or config/checkpoints/ROBOT
    /// for another robot than the default).
    #[arg(long)]
    checkpoints: Option<PathBuf>,
    /// The report to write, its PNGs beside it named after it (default: docs/reproduce.md, or
    /// docs/reproduce-ROBOT.md for another robot than the default).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Rallies per pairing in the dual-rally section (match seed: --seed); 0 skips the section.
    #[arg(long, default_value = "200")]
    rallies: u32,
    /// Add the ablations section (paper §V-C): every checkpoint of CHECKPOINTS/ablations/ (each
    /// names its ablation and seed), evaluated on the same serves, grouped by variant: curves with
    /// their spread over seeds, a table, and whether the paper's three findings reproduce.
    #[arg(long)]
    ablations: bool,
    #[command(flatten)]
    model: super::ModelArg,
}

impl ReproduceArgs {
    /// Whether the robot is the default one.
    fn default_robot(&self) -> bool {
        self.model.name == sim::config::DEFAULT_ROBOT
    }

    /// The checkpoints' directory.
    fn checkpoints(&self) -> PathBuf {
        match &self.checkpoints {
            Some(dir) => dir.clone(),
            None if self.default_robot() => PathBuf::from("config/checkpoints"),
            None => Path::new("config/checkpoints").join(robot_file(&self.model.name)),
        }
    }

    /// The report's path.
    fn out(&self) -> PathBuf {
        match &self.out {
            Some(out) => out.clone(),
            None if self.default_robot() => PathBuf::from("docs/reproduce.md"),
            None => PathBuf::from(format!(
                "docs/reproduce-{}.md",
                robot_file(&self.model.name)
            )),
        }
    }

    /// A figure beside the report: `STEM_what.png`.
    fn figure(&self, what: &str) -> PathBuf {
        let out = self.out();
        let stem = out
            .file_stem()
            .map_or("reproduce".into(), |s| s.to_string_lossy().to_string());
        out.with_file_name(format!("{stem}_{what}.png"))
    }
}

/// A `--model` as a file name: the robot's name, or an MJCF file's stem.
fn robot_file(model: &str) -> String {
    Path::new(model)
        .file_stem()
        .map_or(model.to_string(), |s| s.to_string_lossy().to_string())
}

/// The dual-rally pairings: the rally-trained agent against itself and the scripted agent, and the
/// single-serve agent and the scripted agent against themselves for reference.
const PAIRINGS: [(&str, &str); 4] = [
    ("kmac-rally", "kmac-rally"),
    ("kmac-rally", "scripted"),
    ("kmac", "kmac"),
    ("scripted", "scripted"),
];

/// Longest rally the histogram bins one by one.
const HISTOGRAM_MAX: u32 = 20;

/// One pairing's match, or why it was not played.
struct Pairing {
    a: String,
    b: String,
    record: Result<agents::matchrun::MatchRecord, String>,
}

fn play_pairings(args: &ReproduceArgs, body: &super::Body) -> Vec<Pairing> {
    let model = &body.model;
    let spec = agents::matchrun::MatchSpec {
        model: model.clone(),
        config: body.config.clone(),
        preset: sim::arena::MYOCHALLENGE,
        rallies: args.rallies,
        seed: args.seed,
        replay: false,
    };
    let bar = ProgressBar::new(PAIRINGS.len() as u64 * args.rallies as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} rallies, eta {eta}  {msg}")
            .expect("valid template"),
    );
    let resolve = |name: &str| -> Result<PlayerSpec, String> {
        match PlayerSpec::scripted(name) {
            Some(s) => Ok(s),
            None => {
                let path = args.checkpoints().join(format!("{name}.json"));
                let text = std::fs::read_to_string(&path)
                    .map_err(|_| format!("no checkpoint ({} is absent)", path.display()))?;
                Checkpoint::from_json(&text, model)
                    .map(|c| PlayerSpec::Checkpoint(std::sync::Arc::new(c)))
                    .map_err(|e| format!("{}: {e}", path.display()))
            }
        }
    };
    let out = PAIRINGS
        .iter()
        .map(|&(a, b)| {
            bar.set_message(format!("{a} vs {b}"));
            let record = resolve(a).and_then(|pa| {
                let pb = resolve(b)?;
                agents::matchrun::play_match(&spec, &pa, &pb, &mut |_| bar.inc(1)).map(|r| r.0)
            });
            Pairing {
                a: a.into(),
                b: b.into(),
                record,
            }
        })
        .collect();
    bar.finish_and_clear();
    out
}

/// Who plays in the report: the method it stands for, its label, how to build it, its checkpoint.
struct Entrant(
    Option<Method>,
    String,
    Option<PlayerSpec>,
    Option<Checkpoint>,
);

struct Row {
    method: Option<Method>,
    label: String,
    report: Option<EvalReport>,
    checkpoint: Option<Checkpoint>,
}

/// Runs `rally reproduce`.
pub fn run(args: &ReproduceArgs) -> Result<(), CliError> {
    let body = args.model.load()?;
    let model = body.model.clone();
    let evaluation = Evaluation {
        lead_in: false,
        model: model.clone(),
        config: body.config.clone(),
        preset: sim::arena::MYOCHALLENGE,
        kind: ServeKind::P2,
        episodes: args.episodes as usize,
        seed: args.seed,
    };
    let entrants = entrants(args, &model)?;
    let rows = evaluate_all(&evaluation, entrants, args.episodes)?;
    let out = args.out();
    let curves_png = args.figure("curves");
    let series = training_curves(&rows);
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let plotted = !series.is_empty();
    if plotted {
        learning_curves(&series, &curves_png).map_err(|e| CliError::Failed(anyhow!(e)))?;
    }
    let (ablation_md, spread) = if args.ablations {
        let dir = args.checkpoints().join("ablations");
        ablations::section(&dir, &model, &evaluation, &args.figure("ablations"))?
    } else {
        (String::new(), None)
    };
    let mut md = report(
        args,
        &model,
        &rows,
        plotted.then_some(&curves_png),
        spread.as_deref(),
    );
    if args.rallies > 0 {
        md.push_str(&rallies(args, &body)?);
    }
    md.push_str(&ablation_md);
    std::fs::write(&out, &md)?;
    print!("{md}");
    eprintln!("wrote {}", out.display());
    Ok(())
}

/// Who plays: each method's committed checkpoint (and its mean action, when it has a policy noise),
/// then the scripted agent; a method without a checkpoint is listed unplayed.
fn entrants(args: &ReproduceArgs, model: &Arc<Model>) -> Result<Vec<Entrant>, CliError> {
    let mut agents: Vec<Entrant> = Vec::new();
    for m in Method::ALL {
        let path = args
            .checkpoints()
            .join(format!("{}.json", m.checkpoint_name()));
        match std::fs::read_to_string(&path) {
            Ok(text) => {
                let c = Checkpoint::from_json(&text, model)
                    .map_err(|e| CliError::Failed(anyhow!("{}: {e}", path.display())))?;
                let spec = PlayerSpec::Checkpoint(Arc::new(c.clone()));
                if c.policy_std.is_some() {
                    agents.push(Entrant(
                        Some(m),
                        format!("{} (mean action)", m.paper_name()),
                        Some(spec.clone().mean_action()),
                        Some(c.clone()),
                    ));
                }
                agents.push(Entrant(Some(m), m.paper_name().into(), Some(spec), Some(c)));
            }
            Err(_) => agents.push(Entrant(Some(m), m.paper_name().into(), None, None)),
        }
    }
    agents.push(Entrant(
        None,
        "scripted (house agent, no learning)".into(),
        PlayerSpec::scripted("scripted"),
        None,
    ));
    Ok(agents)
}

/// Evaluates every entrant that can play, in order, with a bar of the episodes.
fn evaluate_all(
    evaluation: &Evaluation,
    entrants: Vec<Entrant>,
    episodes: u64,
) -> Result<Vec<Row>, CliError> {
    let total = entrants.iter().filter(|a| a.2.is_some()).count() as u64 * episodes;
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} episodes, {per_sec}, eta {eta}  {msg}")
            .expect("valid template"),
    );
    let mut rows: Vec<Row> = Vec::new();
    for Entrant(method, label, spec, checkpoint) in entrants {
        bar.set_message(label.clone());
        let report = match &spec {
            Some(s) => Some(
                evaluate(evaluation, s, &|| bar.inc(1))
                    .map_err(|e| CliError::Failed(anyhow!("{label}: {e}")))?,
            ),
            None => None,
        };
        rows.push(Row {
            method,
            label,
            report,
            checkpoint,
        });
    }
    bar.finish_and_clear();
    Ok(rows)
}

/// The learning curves the checkpoints carry (not repeated for their mean-action rows).
fn training_curves(rows: &[Row]) -> Vec<Series> {
    rows.iter()
        .filter(|r| !r.label.ends_with("(mean action)"))
        .filter_map(|r| {
            let t = r.checkpoint.as_ref()?.training.as_ref()?;
            Some(Series {
                label: r.label.clone(),
                rows: t
                    .curve
                    .iter()
                    .map(|p| CurveRow {
                        env_steps: p.env_steps,
                        episodes: 1,
                        reward: p.reward,
                        hit_rate: p.hit_rate,
                        success_rate: p.success_rate,
                        ..CurveRow::default()
                    })
                    .collect(),
            })
        })
        .collect()
}

/// The dual-rally section: the pairings played, the rally-length histogram and (for the
/// rally-trained agent) the serves and returns at the hitting plane, beside the report.
fn rallies(args: &ReproduceArgs, body: &super::Body) -> Result<String, CliError> {
    let pairings = play_pairings(args, body);
    let played: Vec<&Pairing> = pairings.iter().filter(|p| p.record.is_ok()).collect();
    let file = |suffix: &str| args.figure(suffix);
    let name = |p: &std::path::Path| p.file_name().map(|n| n.to_string_lossy().to_string());
    let (hist, ret) = (file("rallies"), file("returns"));
    let mut hist_name = None;
    let mut ret_name = None;
    if !played.is_empty() {
        plot_rally_lengths(&played, &hist)?;
        hist_name = name(&hist);
        if plot_returns(&played, &ret)? {
            ret_name = name(&ret);
        }
    }
    Ok(rally_section(
        args,
        &pairings,
        hist_name.as_deref(),
        ret_name.as_deref(),
    ))
}

fn record(p: &Pairing) -> &agents::matchrun::MatchRecord {
    p.record.as_ref().expect("played")
}

/// The histogram of the played pairings' rally lengths.
fn plot_rally_lengths(played: &[&Pairing], path: &Path) -> Result<(), CliError> {
    let series: Vec<(String, Vec<u32>)> = played
        .iter()
        .map(|p| {
            (
                format!("{} vs {}", p.a, p.b),
                record(p).rallies.iter().map(|r| r.length).collect(),
            )
        })
        .collect();
    super::plot::rally_histogram(&series, HISTOGRAM_MAX, path)
        .map_err(|e| CliError::Failed(anyhow!(e)))
}

/// Where the serves and the returns of the rally-trained agent's pairings cross the hitting
/// plane; false (nothing written) when it played none.
fn plot_returns(played: &[&Pairing], path: &Path) -> Result<bool, CliError> {
    let panels: Vec<super::plot::Crossings> = played
        .iter()
        .filter(|p| p.a.starts_with("kmac-rally"))
        .map(|p| {
            let m = record(p);
            let pick = |ret: bool| {
                m.rallies
                    .iter()
                    .flat_map(|r| r.crossings.iter())
                    .filter(|c| (c.exchange > 0) == ret)
                    .map(|c| (c.y_r, c.z))
                    .collect()
            };
            super::plot::Crossings {
                title: format!("{} vs {}", p.a, p.b),
                serves: pick(false),
                returns: pick(true),
            }
        })
        .collect();
    if panels.is_empty() {
        return Ok(false);
    }
    super::plot::return_distribution(&panels, path).map_err(|e| CliError::Failed(anyhow!(e)))?;
    Ok(true)
}
