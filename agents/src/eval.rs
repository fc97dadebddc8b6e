//! Evaluation in the single-serve environment (paper §V-B, docs/design.md §7): hit rate, success rate,
//! effort and mean activation over seeded episodes, each with a 95% interval. Episodes run in
//! parallel (rayon), each with its own seeds derived from the evaluation seed and its index, and are
//! aggregated in index order, so the numbers depend only on the seed — never on the thread count.

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use sim::arena::Preset;
use sim::config::ArenaConfig;
use sim::episode::SingleServe;
use sim::model::Model;
use sim::rng::Rng;
use sim::serve::ServeKind;

use crate::factory::PlayerSpec;
use crate::player::Player;
use crate::seeds::episode_seeds;

/// One episode's outcome.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct EpisodeResult {
    /// The paddle touched the ball.
    pub hit: bool,
    /// The return was legal.
    pub success: bool,
    /// Mean over control steps of ‖a‖₂ / n_a (MyoSuite's effort).
    pub effort: f64,
    /// Mean over control steps of ‖a‖₁ / n_a.
    pub mean_activation: f64,
    /// Mean ‖a‖₁ / n_a over the steps up to and including the first paddle contact (the whole
    /// episode when there is none): the part of an episode a training episode also plays.
    pub activation_to_contact: f64,
    /// Mean ‖a‖₁ / n_a over the steps after the first paddle contact (none without a contact or
    /// when the episode ends on it): play no training episode reaches, as training episodes end
    /// 3 steps after the ball leaves the paddle (docs/design.md §11).
    pub activation_after_contact: Option<f64>,
    /// Control steps played.
    pub steps: usize,
    /// Control steps after the first paddle contact.
    pub steps_after_contact: usize,
    /// How it ended: a failure's name, "SUCCESS", or "TIME_LIMIT".
    pub end: &'static str,
}

/// A rate with its Wilson 95% interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Rate {
    /// Successes / trials.
    pub value: f64,
    /// Lower end of the interval.
    pub low: f64,
    /// Upper end of the interval.
    pub high: f64,
}

/// A mean with its normal-approximation 95% interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Mean {
    /// The mean.
    pub value: f64,
    /// Lower end of the interval.
    pub low: f64,
    /// Upper end of the interval.
    pub high: f64,
}

/// Wilson score interval at 95% (z = 1.96) for `k` of `n`.
pub fn wilson(k: usize, n: usize) -> Rate {
    if n == 0 {
        return Rate {
            value: 0.0,
            low: 0.0,
            high: 1.0,
        };
    }
    let (k, n, z) = (k as f64, n as f64, 1.959_963_984_540_054);
    let p = k / n;
    let denom = 1.0 + z * z / n;
    let centre = (p + z * z / (2.0 * n)) / denom;
    let half = z * ((p * (1.0 - p) + z * z / (4.0 * n)) / n).sqrt() / denom;
    Rate {
        value: p,
        low: (centre - half).max(0.0),
        high: (centre + half).min(1.0),
    }
}

/// Mean and 95% interval (1.96 standard errors) of `xs`.
pub fn mean_interval(xs: &[f64]) -> Mean {
    let n = xs.len() as f64;
    if xs.is_empty() {
        return Mean {
            value: 0.0,
            low: 0.0,
            high: 0.0,
        };
    }
    let m = xs.iter().sum::<f64>() / n;
    let var = if xs.len() > 1 {
        xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    let half = 1.959_963_984_540_054 * (var / n).sqrt();
    Mean {
        value: m,
        low: m - half,
        high: m + half,
    }
}

/// An evaluation's summary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    /// Who was evaluated.
    pub agent: String,
    /// Serve kind ("p1" or "p2").
    pub serve: String,
    /// Evaluation seed.
    pub seed: u64,
    /// Episodes played.
    pub episodes: usize,
    /// Hit rate.
    pub hit_rate: Rate,
    /// Success rate.
    pub success_rate: Rate,
    /// Effort (‖a‖₂ / n_a).
    pub effort: Mean,
    /// Mean activation (‖a‖₁ / n_a).
    pub mean_activation: Mean,
    /// Mean activation up to and including the first contact (every episode).
    #[serde(default)]
    pub activation_to_contact: Option<Mean>,
    /// Mean activation after the first contact (the episodes that play on after one).
    #[serde(default)]
    pub activation_after_contact: Option<Mean>,
    /// Share of all control steps played after a first contact.
    #[serde(default)]
    pub after_contact_steps: Option<f64>,
    /// How many episodes ended each way.
    pub ends: Vec<(String, usize)>,
    /// Every episode began with a lead-in ([`Evaluation::lead_in`]).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub lead_in: bool,
}

/// How a finished single-serve episode ended: SUCCESS, the referee's reason, or TIME_LIMIT.
pub fn end_name(env: &SingleServe) -> &'static str {
    if env.success {
        "SUCCESS"
    } else {
        env.referee
            .end()
            .map(|e| e.reason.name())
            .unwrap_or("TIME_LIMIT")
    }
}

/// Plays one single-serve episode with `player`.
pub fn play_episode(
    env: &mut SingleServe,
    player: &mut dyn Player,
    kind: ServeKind,
    serve_seed: u64,
) -> EpisodeResult {
    env.reset(kind, &mut Rng::seeded(serve_seed), None);
    play_reset_episode(env, player)
}

/// One control step of a traced episode: what the player saw and decided.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TraceStep {
    /// The episode's index in the evaluation.
    pub episode: usize,
    /// The control step's index in the episode.
    pub step: usize,
    /// The arena's time at the decision, s.
    pub time: f64,
    /// The observation the network was given, before the checkpoint's normalisation (empty for a
    /// player without a network).
    pub observation: Vec<f64>,
    /// The network's output: the mean action, before any noise and the controller (empty for a
    /// player without a network).
    pub action: Vec<f64>,
    /// The muscle controls the player wrote (every actuator of the robot).
    pub controls: Vec<f64>,
    /// The step was in the episode's lead-in (`rally eval --lead-in`); left out when not.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub lead_in: bool,
}

/// Plays the episode `env` was just reset to (any serve, e.g. a bank ball) with `player`.
pub fn play_reset_episode(env: &mut SingleServe, player: &mut dyn Player) -> EpisodeResult {
    play_traced(env, player, None)
}

/// [`play_reset_episode`], appending every control step to `trace` when given (episode index 0:
/// the caller renumbers).
pub fn play_traced(
    env: &mut SingleServe,
    player: &mut dyn Player,
    mut trace: Option<&mut Vec<TraceStep>>,
) -> EpisodeResult {
    player.reset();
    let model = env.robot.held_model().clone();
    let muscles: Vec<usize> = model.muscles().map(|(i, _)| i).collect();
    let na = muscles.len().max(1) as f64;
    let mut ctrl = vec![0.0; model.actuators.len()];
    let (mut effort, mut l1, mut steps) = (0.0, 0.0, 0usize);
    // Activation summed up to and including the first contact, and the step count there.
    let mut to_contact: Option<(f64, usize)> = None;
    let mut k = 0;
    loop {
        let lead_in = env.in_lead_in();
        ctrl.copy_from_slice(&env.robot.state.ctrl);
        let ok = player
            .act(&env.robot, &env.world.ball, env.world.time, &mut ctrl)
            .is_ok()
            && ctrl.iter().all(|c| c.is_finite());
        if let Some(t) = trace.as_deref_mut() {
            let (observation, action) = player
                .last_decision()
                .map(|(o, a)| (o.to_vec(), a.to_vec()))
                .unwrap_or_default();
            t.push(TraceStep {
                episode: 0,
                step: k,
                lead_in,
                time: env.world.time,
                observation,
                action,
                controls: ctrl.clone(),
            });
        }
        if !ok {
            env.invalid_action();
            break;
        }
        env.robot.state.ctrl.copy_from_slice(&ctrl);
        let done = env.step().done;
        k += 1;
        if lead_in {
            // The figures count from the serve on.
            if done {
                break;
            }
            continue;
        }
        let act = &env.robot.state.act;
        effort += muscles.iter().map(|&a| act[a] * act[a]).sum::<f64>().sqrt() / na;
        l1 += muscles.iter().map(|&a| act[a].abs()).sum::<f64>() / na;
        steps += 1;
        if env.hit && to_contact.is_none() {
            to_contact = Some((l1, steps));
        }
        if done {
            break;
        }
    }
    let end = end_name(env);
    let (l1_to, steps_to) = to_contact.unwrap_or((l1, steps));
    let steps_after = steps - steps_to;
    EpisodeResult {
        hit: env.hit,
        success: env.success,
        effort: effort / steps.max(1) as f64,
        mean_activation: l1 / steps.max(1) as f64,
        activation_to_contact: l1_to / steps_to.max(1) as f64,
        activation_after_contact: (steps_after > 0).then(|| (l1 - l1_to) / steps_after as f64),
        steps,
        steps_after_contact: steps_after,
        end,
    }
}

/// What an evaluation plays: the arena, the serve distribution, how many episodes, the seed.
#[derive(Debug, Clone)]
pub struct Evaluation {
    /// The robot model.
    pub model: Arc<Model>,
    /// Arena constants.
    pub config: ArenaConfig,
    /// Contact laws.
    pub preset: Preset,
    /// Serve distribution (P1 or P2).
    pub kind: ServeKind,
    /// Episodes to play.
    pub episodes: usize,
    /// Evaluation seed.
    pub seed: u64,
    /// Every episode begins with a lead-in (see [`SingleServe::start_lead_in`]): the robot's own
    /// return, a stroke ball it struck, flies away first, so the serve finds the robot as it is
    /// between two strokes of a rally; drawn after the serve, so the serves are the same as
    /// without. The figures count from the serve on.
    pub lead_in: bool,
}

/// Evaluates `spec` as `e` says; `progress` is called after each episode.
pub fn evaluate(
    e: &Evaluation,
    spec: &PlayerSpec,
    progress: &(dyn Fn() + Sync),
) -> Result<EvalReport, String> {
    evaluate_traced(e, spec, progress, false).map(|(report, _)| report)
}

/// [`evaluate`], with every episode's control steps when `trace` (in episode order; empty
/// otherwise). A step's trace holds the observation, so a trace takes about 1.5 MB an episode on the
/// built-in robot and 5 MB on MyoSuite's.
pub fn evaluate_traced(
    e: &Evaluation,
    spec: &PlayerSpec,
    progress: &(dyn Fn() + Sync),
    trace: bool,
) -> Result<(EvalReport, Vec<TraceStep>), String> {
    let (model, config, preset, kind, episodes, seed, lead_in) = (
        e.model.clone(),
        &e.config,
        e.preset,
        e.kind,
        e.episodes,
        e.seed,
        e.lead_in,
    );
    // Fail early, once, on anything wrong with the player or the arena.
    SingleServe::new(model.clone(), config, preset)?;
    spec.build(&model, &preset, 0)?;
    // One environment and one player per worker (an ONNX player prepares its network once), the
    // workers taking the next episode index as they finish one; each episode reseeds the player, so
    // results do not depend on which worker played it.
    let played: Vec<(EpisodeResult, Vec<TraceStep>)> = crate::seeds::par_indexed(
        episodes,
        || {
            (
                SingleServe::new(model.clone(), config, preset).expect("checked above"),
                spec.build(&model, &preset, 0).expect("checked above"),
            )
        },
        |(env, player), i| {
            let (serve_seed, agent_seed) = episode_seeds(seed, i);
            player.reseed(agent_seed);
            let mut rng = Rng::seeded(serve_seed);
            env.reset(kind, &mut rng, None);
            if lead_in {
                env.draw_lead_in(&mut rng, false);
            }
            let mut steps = Vec::new();
            let r = play_traced(env, player.as_mut(), trace.then_some(&mut steps));
            for s in &mut steps {
                s.episode = i;
            }
            progress();
            (r, steps)
        },
    );
    let (results, traces): (Vec<EpisodeResult>, Vec<Vec<TraceStep>>) = played.into_iter().unzip();
    let hits = results.iter().filter(|r| r.hit).count();
    let wins = results.iter().filter(|r| r.success).count();
    let mut ends: Vec<(String, usize)> = Vec::new();
    for r in &results {
        match ends.iter_mut().find(|(e, _)| e == r.end) {
            Some((_, n)) => *n += 1,
            None => ends.push((r.end.to_string(), 1)),
        }
    }
    ends.sort();
    let report = EvalReport {
        agent: spec.name(),
        serve: match kind {
            ServeKind::P0 => "p0",
            ServeKind::P1 => "p1",
            ServeKind::P2 => "p2",
            ServeKind::Rally { .. } => "rally",
            ServeKind::Stroke { .. } => "stroke",
        }
        .to_string(),
        seed,
        episodes,
        hit_rate: wilson(hits, episodes),
        success_rate: wilson(wins, episodes),
        effort: mean_interval(&results.iter().map(|r| r.effort).collect::<Vec<_>>()),
        mean_activation: mean_interval(
            &results
                .iter()
                .map(|r| r.mean_activation)
                .collect::<Vec<_>>(),
        ),
        activation_to_contact: Some(mean_interval(
            &results
                .iter()
                .map(|r| r.activation_to_contact)
                .collect::<Vec<_>>(),
        )),
        activation_after_contact: Some(mean_interval(
            &results
                .iter()
                .filter_map(|r| r.activation_after_contact)
                .collect::<Vec<_>>(),
        )),
        after_contact_steps: Some(
            results.iter().map(|r| r.steps_after_contact).sum::<usize>() as f64
                / results.iter().map(|r| r.steps).sum::<usize>().max(1) as f64,
        ),
        ends,
        lead_in,
    };
    Ok((report, traces.into_iter().flatten().collect()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_matches_known_values() {
        // 8 of 10: Wilson 95% interval (0.490, 0.943).
        let r = wilson(8, 10);
        assert!(
            (r.low - 0.4902).abs() < 1e-3 && (r.high - 0.9433).abs() < 1e-3,
            "{r:?}"
        );
        let r = wilson(0, 20);
        assert_eq!(r.low, 0.0);
        assert!((r.high - 0.1611).abs() < 1e-3);
    }
}
