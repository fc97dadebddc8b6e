//! `rally reproduce`: the paper's Table I in our simulator. Evaluates the committed checkpoints of
//! the four methods (`config/checkpoints/{kmac,muscle-ppo,muscle-pd,dynsyn}.json`) and the scripted
//! house agent on MyoChallenge P2 serves (seeds the training never drew: training serves come from
//! their own streams of the training seed), and writes a markdown report with 95% intervals, the
//! seeds, the paper's numbers beside ours, each checkpoint's provenance and the learning curves.

use std::fmt::Write as _;
use std::path::PathBuf;

use agents::checkpoint::Checkpoint;
use agents::eval::{evaluate, EvalReport, Evaluation};
use agents::factory::PlayerSpec;
use agents::ppo::trainer::CurveRow;
use agents::ppo::Method;
use anyhow::anyhow;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use sim::serve::ServeKind;

use super::plot::{learning_curves, Series};
use super::CliError;

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
    after_help = "Example:\n  rally reproduce --episodes 1000 --seed 2026 --rallies 200\n  \
                  (writes docs/reproduce.md, docs/reproduce_curves.png, docs/reproduce_rallies.png, docs/reproduce_returns.png)"
)]
pub struct ReproduceArgs {
    /// Episodes per agent.
    #[arg(long, default_value = "1000", value_parser = clap::value_parser!(u64).range(1..=100_000))]
    episodes: u64,
    /// Evaluation seed: episode i has the serve and agent seeds `episode_seeds(seed, i)`.
    #[arg(long, default_value = "2026")]
    seed: u64,
    /// Where the committed checkpoints are.
    #[arg(long, default_value = "config/checkpoints")]
    checkpoints: PathBuf,
    /// The report to write (the learning-curve PNG goes beside it).
    #[arg(long, default_value = "docs/reproduce.md")]
    out: PathBuf,
    /// Rallies per pairing in the dual-rally section (match seed: --seed); 0 skips the section.
    #[arg(long, default_value = "200")]
    rallies: u32,
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

fn play_pairings(args: &ReproduceArgs, model: &std::sync::Arc<sim::model::Model>) -> Vec<Pairing> {
    let spec = agents::matchrun::MatchSpec {
        model: model.clone(),
        config: sim::config::ArenaConfig::default(),
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
                let path = args.checkpoints.join(format!("{name}.json"));
                let text = std::fs::read_to_string(&path)
                    .map_err(|_| format!("not trained yet (no {})", path.display()))?;
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

/// Fraction of crossings inside the serve box by exchange index (0 = the serves), with counts.
fn in_box_by_exchange(m: &agents::matchrun::MatchRecord) -> Vec<(u32, usize, f64)> {
    let all: Vec<_> = m.rallies.iter().flat_map(|r| r.crossings.iter()).collect();
    let max = all.iter().map(|c| c.exchange).max().unwrap_or(0);
    (0..=max)
        .filter_map(|k| {
            let at: Vec<_> = all.iter().filter(|c| c.exchange == k).collect();
            (!at.is_empty()).then(|| {
                let inside = at.iter().filter(|c| c.in_box).count();
                (k, at.len(), inside as f64 / at.len() as f64)
            })
        })
        .collect()
}

fn rally_section(
    args: &ReproduceArgs,
    pairings: &[Pairing],
    hist: Option<&str>,
    returns: Option<&str>,
) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "\n## Dual-robot rallies (paper §IV-C, §V-D)\n");
    let _ = writeln!(
        s,
        "`rally match A B --rallies {} --seed {}` for each pairing (A serves the even rallies, B the odd ones; \
         the heuristic rally serve). A rally's length is its legal returns (the serve is not one). A geometric \
         rally with per-stroke success p has mean p/(1−p): the column *implied p* inverts that. The drift slope is \
         the least-squares slope over exchange index of the energy distance between the serves' and the returns' \
         crossings of the receiver's hitting plane (docs/design.md §7). The paper's record: 14 consecutive exchanges.\n",
        args.rallies, args.seed
    );
    let _ = writeln!(
        s,
        "| A | B | Mean rally | Longest | Implied p | In box (all crossings) | Drift slope | Ends |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|");
    for p in pairings {
        match &p.record {
            Ok(m) => {
                let mut ends = std::collections::BTreeMap::<&str, usize>::new();
                for r in &m.rallies {
                    *ends.entry(r.end).or_default() += 1;
                }
                let ends: Vec<String> = ends.iter().map(|(k, n)| format!("{k} {n}")).collect();
                let l = m.mean_rally_length;
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.2} | {} | {:.3} | {:.1}% | {} | {} |",
                    p.a,
                    p.b,
                    l,
                    m.max_rally_length,
                    l / (1.0 + l),
                    100.0 * m.drift.in_box_fraction,
                    m.drift
                        .drift_slope
                        .map_or("–".into(), |x| format!("{x:.4}")),
                    ends.join(", ")
                );
            }
            Err(e) => {
                let _ = writeln!(s, "| {} | {} | {e} | | | | | |", p.a, p.b);
            }
        }
    }
    let _ = writeln!(
        s,
        "\nIn-box fraction by exchange index (0 = the serves; crossings counted):\n"
    );
    for p in pairings {
        if let Ok(m) = &p.record {
            let cells: Vec<String> = in_box_by_exchange(m)
                .iter()
                .take(12)
                .map(|(k, n, f)| format!("{k}: {:.0}% ({n})", 100.0 * f))
                .collect();
            let _ = writeln!(s, "- {} vs {}: {}", p.a, p.b, cells.join(", "));
        }
    }
    if let Some(h) = hist {
        let _ = writeln!(s, "\n![rally lengths]({h})\n");
    }
    if let Some(r) = returns {
        let _ = writeln!(s, "![serves and returns at the hitting plane]({r})\n");
    }
    s
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

fn pct(r: &agents::eval::Rate) -> String {
    format!(
        "{:.1} [{:.1}, {:.1}]",
        100.0 * r.value,
        100.0 * r.low,
        100.0 * r.high
    )
}

fn mean(m: &agents::eval::Mean) -> String {
    format!("{:.4} [{:.4}, {:.4}]", m.value, m.low, m.high)
}

/// Runs `rally reproduce`.
pub fn run(args: &ReproduceArgs) -> Result<(), CliError> {
    let model = super::default_model()?;
    let config = sim::config::ArenaConfig::default();
    let mut rows: Vec<Row> = Vec::new();
    let evaluation = Evaluation {
        model: model.clone(),
        config,
        preset: sim::arena::MYOCHALLENGE,
        kind: ServeKind::P2,
        episodes: args.episodes as usize,
        seed: args.seed,
    };
    let mut agents: Vec<Entrant> = Vec::new();
    for m in Method::ALL {
        let path = args
            .checkpoints
            .join(format!("{}.json", m.checkpoint_name()));
        match std::fs::read_to_string(&path) {
            Ok(text) => {
                let c = Checkpoint::from_json(&text, &model)
                    .map_err(|e| CliError::Failed(anyhow!("{}: {e}", path.display())))?;
                let spec = PlayerSpec::Checkpoint(std::sync::Arc::new(c.clone()));
                if c.policy_std.is_some() {
                    agents.push(Entrant(
                        Some(m),
                        format!("{} (mean action)", m.paper_name()),
                        Some(super::eval::mean_action(spec.clone())),
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
    let total = agents.iter().filter(|a| a.2.is_some()).count() as u64 * args.episodes;
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} episodes, {per_sec}, eta {eta}  {msg}")
            .expect("valid template"),
    );
    for Entrant(method, label, spec, checkpoint) in agents {
        bar.set_message(label.clone());
        let report = match &spec {
            Some(s) => Some(
                evaluate(&evaluation, s, &|| bar.inc(1))
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
    let curves_png = args.out.with_file_name("reproduce_curves.png");
    let series: Vec<Series> = rows
        .iter()
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
        .collect();
    if let Some(dir) = args.out.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let plotted = !series.is_empty();
    if plotted {
        learning_curves(&series, &curves_png).map_err(|e| CliError::Failed(anyhow!(e)))?;
    }
    let mut md = report(args, &rows, plotted.then_some(&curves_png));
    if args.rallies > 0 {
        let pairings = play_pairings(args, &model);
        let played: Vec<&Pairing> = pairings.iter().filter(|p| p.record.is_ok()).collect();
        let file = |suffix: &str| args.out.with_file_name(format!("reproduce_{suffix}.png"));
        let name = |p: &std::path::Path| p.file_name().map(|n| n.to_string_lossy().to_string());
        let (hist, ret) = (file("rallies"), file("returns"));
        let mut hist_name = None;
        let mut ret_name = None;
        if !played.is_empty() {
            let series: Vec<(String, Vec<u32>)> = played
                .iter()
                .map(|p| {
                    let m = p.record.as_ref().expect("played");
                    (
                        format!("{} vs {}", p.a, p.b),
                        m.rallies.iter().map(|r| r.length).collect(),
                    )
                })
                .collect();
            super::plot::rally_histogram(&series, HISTOGRAM_MAX, &hist)
                .map_err(|e| CliError::Failed(anyhow!(e)))?;
            hist_name = name(&hist);
            let panels: Vec<super::plot::Crossings> = played
                .iter()
                .filter(|p| p.a.starts_with("kmac-rally"))
                .map(|p| {
                    let m = p.record.as_ref().expect("played");
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
            if !panels.is_empty() {
                super::plot::return_distribution(&panels, &ret)
                    .map_err(|e| CliError::Failed(anyhow!(e)))?;
                ret_name = name(&ret);
            }
        }
        md.push_str(&rally_section(
            args,
            &pairings,
            hist_name.as_deref(),
            ret_name.as_deref(),
        ));
    }
    std::fs::write(&args.out, &md)?;
    print!("{md}");
    eprintln!("wrote {}", args.out.display());
    Ok(())
}

fn report(args: &ReproduceArgs, rows: &[Row], curves: Option<&PathBuf>) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "# Reproducing the paper's Table I\n");
    let _ = writeln!(
        s,
        "Written by `rally reproduce --episodes {} --seed {} --rallies {}` (simulator {}). Every agent plays the same {} \
         MyoChallenge P2 serves in the single-serve environment: episode i uses the serve and agent seeds \
         `episode_seeds({}, i)`, i = 0…{}; training serves come from separate streams of each run's training \
         seed, so no evaluation serve was trained on. Rates are Wilson 95% intervals, means normal 95% intervals.\n",
        args.episodes,
        args.seed,
        args.rallies,
        sim::SIM_VERSION,
        args.episodes,
        args.seed,
        args.episodes - 1
    );
    let _ = writeln!(
        s,
        "Every method is trained from scratch with the same PPO, reward, network and hyperparameters \
         (`config/train.toml`); only the action space differs (docs/design.md §6). Effort is MyoSuite's \
         mean ‖a‖₂/n_a (comparable only at equal muscle counts: ours has 75 muscles, the paper's model \
         more); mean activation ‖a‖₁/n_a is comparable across models.\n"
    );
    let _ = writeln!(
        s,
        "A trained checkpoint plays the Gaussian policy PPO trained (`policy_std`: its action noise comes \
         from the agent's seeded stream, so every number here is a function of the seed); the rows marked \
         *mean action* play the same network without the noise, as rsl_rl's `act_inference` does.\n"
    );
    let _ = writeln!(
        s,
        "| Method | Hit % | Success % | Effort | Mean activation | Paper hit % | Paper success % | Paper effort | Training steps | Training time |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        let paper = r
            .method
            .map(|m| {
                let (h, u, e) = paper_row(m);
                (format!("{h:.1}"), format!("{u:.1}"), format!("{e:.4}"))
            })
            .unwrap_or(("–".into(), "–".into(), "–".into()));
        let train = r.checkpoint.as_ref().and_then(|c| c.training.as_ref());
        let (steps, wall) = train
            .map(|t| {
                (
                    format!("{:.2} M", t.env_steps as f64 / 1e6),
                    format!("{:.0} min", t.wall_seconds / 60.0),
                )
            })
            .unwrap_or(("–".into(), "–".into()));
        match &r.report {
            Some(e) => {
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
                    r.label,
                    pct(&e.hit_rate),
                    pct(&e.success_rate),
                    mean(&e.effort),
                    mean(&e.mean_activation),
                    paper.0,
                    paper.1,
                    paper.2,
                    steps,
                    wall
                );
            }
            None => {
                let _ = writeln!(
                    s,
                    "| {} | not trained yet (no checkpoint) | | | | {} | {} | {} | | |",
                    r.label, paper.0, paper.1, paper.2
                );
            }
        }
    }
    let _ = writeln!(s, "\n## Where the activation goes\n");
    let _ = writeln!(
        s,
        "Training episodes end 3 steps after the ball leaves the paddle (as in the official code), while \
         an evaluation plays every episode to its end by the rules: the steps after the first contact are \
         play no method was trained on. Mean activation ‖a‖₁/n_a up to and including the first contact \
         (every episode; all of it when there is none) and after it (the episodes that play on).\n"
    );
    let _ = writeln!(
        s,
        "| Method | Mean activation | To contact | After contact | Steps after contact |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|");
    for r in rows {
        if let Some(e) = &r.report {
            let opt = |m: &Option<agents::eval::Mean>| m.as_ref().map(mean).unwrap_or("–".into());
            let _ = writeln!(
                s,
                "| {} | {} | {} | {} | {} |",
                r.label,
                mean(&e.mean_activation),
                opt(&e.activation_to_contact),
                opt(&e.activation_after_contact),
                e.after_contact_steps
                    .map(|f| format!("{:.0}%", 100.0 * f))
                    .unwrap_or("–".into())
            );
        }
    }
    let _ = writeln!(s, "\n## How each episode ended\n");
    for r in rows {
        if let Some(e) = &r.report {
            let ends: Vec<String> = e.ends.iter().map(|(k, n)| format!("{k} {n}")).collect();
            let _ = writeln!(s, "- {}: {}", r.label, ends.join(", "));
        }
    }
    let _ = writeln!(s, "\n## Provenance of the checkpoints\n");
    for r in rows.iter().filter(|r| !r.label.ends_with("(mean action)")) {
        if let Some(t) = r.checkpoint.as_ref().and_then(|c| c.training.as_ref()) {
            let _ = writeln!(
                s,
                "- {}: `{}` — seed {}, commit {}, {} control steps in {} iterations, {:.0} s; last {} training \
                 episodes: hit {:.1}%, success {:.1}% (predicted landing)",
                r.label,
                t.command,
                t.seed,
                t.git_commit,
                t.env_steps,
                t.iterations,
                t.wall_seconds,
                t.episodes,
                100.0 * t.hit_rate,
                100.0 * t.success_rate
            );
        }
    }
    if let Some(p) = curves {
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        let _ = writeln!(s, "\n## Learning curves\n\n![learning curves]({name})\n");
    }
    s
}
