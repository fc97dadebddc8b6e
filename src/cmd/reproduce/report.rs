//! The markdown `rally reproduce` writes: Table I beside the paper's, where the activation goes,
//! how the episodes ended, the checkpoints' provenance and the dual-rally section.

use agents::controller::ControllerSpec;
use std::fmt::Write as _;
use std::path::PathBuf;

use super::{paper_row, Pairing, ReproduceArgs, Row};

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

/// The dual-rally section: each pairing's rallies, the in-box fraction by exchange, the plots.
pub(super) fn rally_section(
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
         crossings of the receiver's hitting plane (docs/design.md §7). A rally that reaches the arena's cap of \
         legal returns (`[rally] cap`) or its time limit (`[rally] max_seconds`) ends CAPPED, lost by no side: a \
         longest marked *cap* ended so, and where rallies were capped the mean and implied p are lower bounds. The \
         paper's record: 14 consecutive exchanges.\n",
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
                let capped = m.rallies.iter().any(|r| {
                    r.end == sim::rules::EndReason::Capped.name() && r.length == m.max_rally_length
                });
                let longest = format!(
                    "{}{}",
                    m.max_rally_length,
                    if capped { " (cap)" } else { "" }
                );
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.2} | {} | {:.3} | {:.1}% | {} | {} |",
                    p.a,
                    p.b,
                    l,
                    longest,
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

/// The report's markdown: the method, Table I beside the paper's, where the activation goes, how
/// the episodes ended, the checkpoints' provenance and the learning curves.
pub(super) fn report(
    args: &ReproduceArgs,
    model: &sim::model::Model,
    rows: &[Row],
    curves: Option<&PathBuf>,
    spread: Option<&str>,
) -> String {
    let mut s = String::new();
    intro(&mut s, args, model);
    results_table(&mut s, rows);
    if let Some(line) = spread {
        let _ = writeln!(s, "\n{line}");
    }
    activation_table(&mut s, rows);
    episode_ends(&mut s, rows);
    provenance(&mut s, rows);
    if let Some(p) = curves {
        let name = p
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        let _ = writeln!(s, "\n## Learning curves\n\n![learning curves]({name})\n");
    }
    s
}

/// The title and how the numbers were made.
fn intro(s: &mut String, args: &ReproduceArgs, model: &sim::model::Model) {
    let robot = sim::config::robot_name(model);
    let default = robot == sim::config::DEFAULT_ROBOT;
    let muscles = model.muscles().count();
    if default {
        let _ = writeln!(s, "# Reproducing the paper's Table I\n");
    } else {
        let _ = writeln!(
            s,
            "# Reproducing the paper's Table I on the {robot} robot ({muscles} muscles)\n"
        );
    }
    let mut flag = if default {
        String::new()
    } else {
        format!(" --model {}", args.model.name)
    };
    if args.ablations {
        flag.push_str(" --ablations");
    }
    // An imported robot is a file written at set-up: its digest says which one played.
    let file = if default {
        String::new()
    } else {
        super::super::model::model_sha256(&args.model.name)
            .map(|d| format!("; model file sha256 `{d}`"))
            .unwrap_or_default()
    };
    let _ = writeln!(
        s,
        "Written by `rally reproduce{flag} --episodes {} --seed {} --rallies {}` (simulator {}{file}). Every agent plays the same {} \
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
    let (config, effort) = if default {
        (
            "config/train.toml".to_string(),
            format!(
                "comparable only at equal muscle counts: this robot has {muscles} muscles, the paper's \
                 273"
            ),
        )
    } else {
        (
            if robot == "myochallenge" {
                "config/train-myochallenge.toml".to_string()
            } else {
                "the run's configuration: its provenance below".to_string()
            },
            format!(
                "over this robot's {muscles} muscles{}",
                if muscles == 273 {
                    ", the paper's robot's: directly comparable with its figures"
                } else {
                    ""
                }
            ),
        )
    };
    let _ = writeln!(
        s,
        "Every method is trained from scratch with the same PPO, reward, network and hyperparameters \
         (`{config}`); only the action space differs (docs/design.md §6). Effort is MyoSuite's \
         mean ‖a‖₂/n_a ({effort}); mean activation ‖a‖₁/n_a is comparable across models.\n"
    );
    let _ = writeln!(
        s,
        "A trained checkpoint plays as it was trained: the Gaussian policy PPO trained (`policy_std`), \
         the action noise its training environment added after the clip where the configuration had \
         one (`action_noise`), and K-MAC's noise on its activation targets where it trained with it \
         (`controller.activation_noise`); that noise comes from the agent's seeded streams, so every \
         number here is a function of the seed. The rows marked *mean action* play the same network \
         drawing nothing, as rsl_rl's `act_inference` does (K-MAC's activation noise as its \
         expectation).\n"
    );
}

/// Table I: each agent's rates and effort beside the paper's, and its training.
fn results_table(s: &mut String, rows: &[Row]) {
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
                    "| {} | no checkpoint | | | | {} | {} | {} | | |",
                    r.label, paper.0, paper.1, paper.2
                );
            }
        }
    }
}

/// Mean activation up to the first contact and after it.
fn activation_table(s: &mut String, rows: &[Row]) {
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
}

/// How each agent's episodes ended.
fn episode_ends(s: &mut String, rows: &[Row]) {
    let _ = writeln!(s, "\n## How each episode ended\n");
    for r in rows {
        if let Some(e) = &r.report {
            let ends: Vec<String> = e.ends.iter().map(|(k, n)| format!("{k} {n}")).collect();
            let _ = writeln!(s, "- {}: {}", r.label, ends.join(", "));
        }
    }
}

/// Each checkpoint's training: command, seed, commit, steps, time, last episodes.
fn provenance(s: &mut String, rows: &[Row]) {
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
            if let Some(ControllerSpec::Kmac {
                activation_noise: Some(sigma),
                ..
            }) = r.checkpoint.as_ref().map(|c| &c.controller)
            {
                let _ = writeln!(
                    s,
                    "  (trained with Gaussian noise σ {sigma} on its activation targets: it draws \
                     that noise in play as in training; its mean action plays each control as the \
                     mean of the clamped noisy one, docs/design.md §6)"
                );
            }
        }
    }
}
