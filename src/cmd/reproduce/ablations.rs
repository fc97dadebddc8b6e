//! `rally reproduce --ablations`: the paper's §V-C on our robots. Reads the checkpoints of
//! `CHECKPOINTS/ablations/` (any file names; each says in its provenance which ablation trained it
//! and from which seed), groups them by ablation, evaluates each on the report's serves, and writes
//! the learning curves (mean ± std over seeds) and a table of the end of training, with the paper's
//! three findings and whether each reproduces.

use std::fmt::Write as _;
use std::path::Path;
use std::sync::Arc;

use agents::checkpoint::Checkpoint;
use agents::env::Ablation;
use agents::eval::{evaluate, EvalReport, Evaluation};
use agents::factory::PlayerSpec;
use agents::observation::CommandVariant;
use anyhow::anyhow;
use indicatif::{ProgressBar, ProgressStyle};
use sim::model::Model;

use super::super::plot::{ablation_curves, SeedCurves};
use super::super::CliError;

/// The paper's variants: the ablation, its name, and what the paper found.
const VARIANTS: [(Ablation, &str, &str); 4] = [
    (
        Ablation {
            command: CommandVariant::Full,
            task_reward: true,
        },
        "Diff-Muscle",
        "the whole framework",
    ),
    (
        Ablation {
            command: CommandVariant::None,
            task_reward: true,
        },
        "Without-Planner",
        "fails: hit and success rates near zero",
    ),
    (
        Ablation {
            command: CommandVariant::Position,
            task_reward: true,
        },
        "Position-only",
        "hits almost every ball early, but its success rate plateaus near 40%",
    ),
    (
        Ablation {
            command: CommandVariant::Full,
            task_reward: false,
        },
        "Without-Task",
        "hits about 85% of the balls and succeeds only about 10%",
    ),
];

/// The name of an ablation: the paper's, else its settings.
fn label(a: &Ablation) -> String {
    VARIANTS
        .iter()
        .find(|(v, _, _)| v == a)
        .map_or_else(|| a.name(), |(_, name, _)| name.to_string())
}

/// One trained seed of a variant, evaluated.
struct Member {
    seed: u64,
    file: String,
    checkpoint: Checkpoint,
    report: EvalReport,
}

/// A variant's seeds.
struct Group {
    ablation: Ablation,
    members: Vec<Member>,
}

impl Group {
    fn rates(&self) -> (Vec<f64>, Vec<f64>) {
        self.members
            .iter()
            .map(|m| (m.report.hit_rate.value, m.report.success_rate.value))
            .unzip()
    }
}

/// Env steps in millions, as Table I prints them.
fn millions(steps: u64) -> String {
    format!("{:.2} M", steps as f64 / 1e6)
}

/// A rate as a percentage with its spread over seeds, `73.2 ± 4.8`; one seed has no spread to
/// print, so its value stands alone.
fn pct_sd((m, sd): (f64, f64), seeds: usize) -> String {
    if seeds > 1 {
        format!("{:.1} ± {:.1}", 100.0 * m, 100.0 * sd)
    } else {
        format!("{:.1}", 100.0 * m)
    }
}

/// Mean and sample standard deviation (0 for one value).
fn mean_sd(x: &[f64]) -> (f64, f64) {
    let n = x.len().max(1) as f64;
    let m = x.iter().sum::<f64>() / n;
    let var = if x.len() > 1 {
        x.iter().map(|v| (v - m) * (v - m)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    (m, var.sqrt())
}

/// Reads and evaluates the ablation checkpoints; the report's section and its figure (written to
/// `figure`), and, when Diff-Muscle has two seeds or more there, a line for Table I with its spread
/// over them. No directory or no checkpoint: a section that says so.
pub(super) fn section(
    dir: &Path,
    model: &Arc<Model>,
    evaluation: &Evaluation,
    figure: &Path,
) -> Result<(String, Option<String>), CliError> {
    let mut s = String::from("\n## Ablations (paper §V-C)\n\n");
    let mut files: Vec<_> = match std::fs::read_dir(dir) {
        Ok(entries) => entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "json"))
            .collect(),
        Err(_) => Vec::new(),
    };
    files.sort();
    if files.is_empty() {
        let _ = writeln!(
            s,
            "No ablation runs yet: `{}` holds no checkpoint. `tools/train_ablations.sh` trains the \
             variants and copies each checkpoint there (another robot: `MODEL=NAME CONFIG=FILE \
             tools/train_ablations.sh`); or train a variant with `[ablation]` in a `rally train \
             --config` file (docs/training.md) and copy its checkpoint there.",
            dir.display()
        );
        return Ok((s, None));
    }
    let bar = ProgressBar::new(files.len() as u64 * evaluation.episodes as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} episodes, eta {eta}  {msg}")
            .expect("valid template"),
    );
    let mut groups: Vec<Group> = Vec::new();
    for path in &files {
        let file = path
            .file_name()
            .map_or(String::new(), |f| f.to_string_lossy().to_string());
        let text = std::fs::read_to_string(path)?;
        let checkpoint = Checkpoint::from_json(&text, model)
            .map_err(|e| CliError::Failed(anyhow!("{}: {e}", path.display())))?;
        let Some(training) = &checkpoint.training else {
            return Err(CliError::Failed(anyhow!(
                "{}: no training provenance (its ablation and seed)",
                path.display()
            )));
        };
        if training.method != "kmac" {
            return Err(CliError::Failed(anyhow!(
                "{}: trained with method {}; the ablations are Diff-Muscle's (kmac)",
                path.display(),
                training.method
            )));
        }
        let (ablation, seed) = (training.ablation.unwrap_or_default(), training.seed);
        bar.set_message(format!("{} seed {seed}", label(&ablation)));
        let spec = PlayerSpec::Checkpoint(Arc::new(checkpoint.clone()));
        let report = evaluate(evaluation, &spec, &|| bar.inc(1))
            .map_err(|e| CliError::Failed(anyhow!("{}: {e}", path.display())))?;
        let member = Member {
            seed,
            file,
            checkpoint,
            report,
        };
        match groups.iter_mut().find(|g| g.ablation == ablation) {
            Some(g) => g.members.push(member),
            None => groups.push(Group {
                ablation,
                members: vec![member],
            }),
        }
    }
    bar.finish_and_clear();
    // The paper's order first, then anything else.
    groups.sort_by_key(|g| {
        VARIANTS
            .iter()
            .position(|(v, _, _)| *v == g.ablation)
            .unwrap_or(VARIANTS.len())
    });
    for g in &mut groups {
        g.members.sort_by_key(|m| m.seed);
    }

    let curves: Vec<SeedCurves> = groups
        .iter()
        .map(|g| SeedCurves {
            label: format!(
                "{} ({} seed{})",
                label(&g.ablation),
                g.members.len(),
                if g.members.len() == 1 { "" } else { "s" }
            ),
            seeds: g
                .members
                .iter()
                .filter_map(|m| {
                    let t = m.checkpoint.training.as_ref()?;
                    Some(
                        t.curve
                            .iter()
                            .map(|p| (p.env_steps as f64, p.hit_rate, p.success_rate))
                            .collect(),
                    )
                })
                .collect(),
        })
        .collect();
    ablation_curves(&curves, figure).map_err(|e| CliError::Failed(anyhow!(e)))?;

    let _ = writeln!(
        s,
        "Diff-Muscle with parts removed (`[ablation]` of the training configuration): Without-Planner \
         observes no command and is paid no command reward, Position-only observes and tracks the \
         strike position alone, Without-Task is paid no task terms. Every checkpoint of `{}` is \
         evaluated on the same {} P2 serves of seed {}, which no run trained on; rates are the mean \
         ± standard deviation over a variant's seeds (each run's seed is listed below).\n",
        dir.display(),
        evaluation.episodes,
        evaluation.seed
    );
    if let Some(name) = figure.file_name() {
        let _ = writeln!(
            s,
            "![training hit and success rates, mean ± std over seeds]({})\n",
            name.to_string_lossy()
        );
    }
    let _ = writeln!(
        s,
        "| Variant | Seeds | Hit % | Success % | Per seed (hit / success %) | Env steps | The paper |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    for g in &groups {
        let (hit, ok) = g.rates();
        let (hit, ok) = (mean_sd(&hit), mean_sd(&ok));
        let per: Vec<String> = g
            .members
            .iter()
            .map(|m| {
                format!(
                    "{}: {:.1} / {:.1}",
                    m.seed,
                    100.0 * m.report.hit_rate.value,
                    100.0 * m.report.success_rate.value
                )
            })
            .collect();
        let steps: Vec<u64> = g
            .members
            .iter()
            .filter_map(|m| m.checkpoint.training.as_ref().map(|t| t.env_steps))
            .collect();
        let steps = match (steps.iter().min(), steps.iter().max()) {
            (Some(a), Some(b)) if a == b => millions(*a),
            (Some(a), Some(b)) => format!("{}–{}", millions(*a), millions(*b)),
            _ => "—".into(),
        };
        let paper = VARIANTS
            .iter()
            .find(|(v, _, _)| *v == g.ablation)
            .map_or("—", |(_, _, p)| p);
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} |",
            label(&g.ablation),
            g.members.len(),
            pct_sd(hit, g.members.len()),
            pct_sd(ok, g.members.len()),
            per.join("; "),
            steps,
            paper
        );
    }
    let _ = writeln!(s, "\n### The paper's findings, here\n");
    let stats = |a: &Ablation| {
        groups.iter().find(|g| g.ablation == *a).map(|g| {
            let (hit, ok) = g.rates();
            (mean_sd(&hit), mean_sd(&ok), g.members.len())
        })
    };
    let dm = stats(&VARIANTS[0].0).map(|(h, o, _)| (h, o));
    let pct = |x: f64| format!("{:.1}%", 100.0 * x);
    for (a, name, paper) in &VARIANTS[1..] {
        let Some(((hm, hs), (sm, ss), seeds)) = stats(a) else {
            let _ = writeln!(s, "- **{name}** (paper: {paper}): not run.");
            continue;
        };
        let (verdict, rule) = match (*name, dm) {
            ("Without-Planner", _) => (
                hm < 0.10 && sm < 0.05,
                "hit below 10% and success below 5%".to_string(),
            ),
            (_, None) => (
                false,
                "needs Diff-Muscle's runs to compare with".to_string(),
            ),
            ("Position-only", Some(((dh, _), (ds, dss)))) => (
                hm >= dh - 0.10 && ds - sm > dss + ss,
                format!(
                    "hit within 10 points of Diff-Muscle's {} or above, success below its {} by \
                     more than the two spreads",
                    pct(dh),
                    pct(ds)
                ),
            ),
            (_, Some((_, (ds, _)))) => (
                hm >= 0.5 && sm < 0.5 * ds,
                format!(
                    "hit at least 50%, success below half of Diff-Muscle's {}",
                    pct(ds)
                ),
            ),
        };
        let said = if dm.is_none() && *name != "Without-Planner" {
            "cannot say"
        } else if verdict {
            "reproduces"
        } else {
            "does not reproduce"
        };
        let rates = if seeds > 1 {
            format!(
                "hit {} ± {}, success {} ± {} over {seeds} seeds",
                pct(hm),
                pct(hs),
                pct(sm),
                pct(ss)
            )
        } else {
            format!("hit {}, success {} (one seed)", pct(hm), pct(sm))
        };
        let _ = writeln!(
            s,
            "- **{name}** (paper: {paper}): {rates} — **{said}** (rule: {rule})."
        );
    }
    let _ = writeln!(s, "\nThe checkpoints:\n");
    for g in &groups {
        for m in &g.members {
            let t = m.checkpoint.training.as_ref();
            let _ = writeln!(
                s,
                "- `{}`: {}, seed {}, {} env steps, commit {}",
                m.file,
                label(&g.ablation),
                m.seed,
                t.map_or(0, |t| t.env_steps),
                t.map_or("unknown", |t| t.git_commit.as_str())
            );
        }
    }
    let spread = groups
        .iter()
        .find(|g| g.ablation == VARIANTS[0].0 && g.members.len() >= 2)
        .map(|g| {
            let (hit, ok) = g.rates();
            let ((hm, hs), (sm, ss)) = (mean_sd(&hit), mean_sd(&ok));
            let seeds: Vec<String> = g.members.iter().map(|m| m.seed.to_string()).collect();
            format!(
                "Diff-Muscle over its {} training seeds of the ablation runs (seeds {}; the same \
                 serves): hit {:.1} ± {:.1}%, success {:.1} ± {:.1}% (mean ± standard deviation \
                 over seeds; the ablations section below).",
                g.members.len(),
                seeds.join(", "),
                100.0 * hm,
                100.0 * hs,
                100.0 * sm,
                100.0 * ss
            )
        });
    Ok((s, spread))
}
