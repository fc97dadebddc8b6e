//! Ratings (docs/design.md §8): Bradley–Terry over points, fitted by the MM algorithm (Hunter 2004) with a
//! weak prior — every agent is credited one point won and one lost against a virtual anchor of
//! strength 1 — and reported on the Elo scale, `1500 + 400·log10 γ`, so the anchor sits at 1500.
//! 95% intervals come from a seeded bootstrap over matches (deterministic: the same matches give the
//! same leaderboard). Glicko-2 (the `skillratings` crate, default configuration) is an online view
//! beside it: each finished match one game won by the side with more points, applied in the order
//! matches finished and kept as the rating history (`rating_history`, written with the match). The
//! SPRT's log-likelihood ratio (fishtest's GSPRT) is here too.

use std::collections::HashMap;

pub use wire::{Leaderboard, LeaderboardRow as Row};

/// What the leaderboard knows of an agent (the store's agent row, minus what rating does not need).
#[derive(Debug, Clone, PartialEq)]
pub struct Entrant {
    /// Agent id.
    pub id: i64,
    /// Name.
    pub name: String,
    /// Registered by the server itself.
    pub builtin: bool,
    /// Qualification hit rate.
    pub hit_rate: Option<f64>,
    /// Qualification success rate.
    pub success_rate: Option<f64>,
}

/// Per finished match: (agent A, agent B, points A, points B, mean rally length, max rally length,
/// in-box fraction, energy distance, rallies).
pub type Outcome = (i64, i64, i64, i64, f64, i64, Option<f64>, Option<f64>, i64);

/// Bootstrap resamples.
pub const BOOTSTRAP: usize = 200;
const ITERATIONS: usize = 5000;

/// Bradley–Terry strengths of `n` agents from a `wins[i][j]` matrix (points i won against j), with the
/// prior; returns Elo-scale ratings.
pub fn bradley_terry(wins: &[Vec<f64>]) -> Vec<f64> {
    bradley_terry_from(wins, None)
}

/// [`bradley_terry`] started from `start` ratings (the bootstrap starts from the full fit).
pub fn bradley_terry_from(wins: &[Vec<f64>], start: Option<&[f64]>) -> Vec<f64> {
    let n = wins.len();
    let mut gamma: Vec<f64> = match start {
        Some(r) => r.iter().map(|x| 10f64.powf((x - 1500.0) / 400.0)).collect(),
        None => vec![1.0f64; n],
    };
    let total: Vec<f64> = (0..n).map(|i| wins[i].iter().sum::<f64>() + 1.0).collect();
    for _ in 0..ITERATIONS {
        let mut next = vec![0.0; n];
        let mut change = 0.0f64;
        for i in 0..n {
            // The prior: two games against the anchor (γ = 1).
            let mut denom = 2.0 / (gamma[i] + 1.0);
            for j in 0..n {
                let games = wins[i][j] + wins[j][i];
                if j != i && games > 0.0 {
                    denom += games / (gamma[i] + gamma[j]);
                }
            }
            next[i] = total[i] / denom;
            change = change.max((next[i].ln() - gamma[i].ln()).abs());
        }
        gamma = next;
        if change < 1e-12 {
            break;
        }
    }
    gamma.iter().map(|g| 1500.0 + 400.0 * g.log10()).collect()
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let k = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[k]
}

/// What the leaderboard takes from elsewhere than the match outcomes.
#[derive(Debug, Clone)]
pub struct Extras {
    /// Each agent's latest Glicko-2 (rating, deviation) from the rating history.
    pub glicko: HashMap<i64, (f64, f64)>,
    /// Each agent's own drift over its matches: (mean in-box fraction, mean energy distance).
    pub drift: HashMap<i64, (Option<f64>, Option<f64>)>,
    /// The reference agent and the rating it is held at: every rating (and every bootstrap
    /// resample) is shifted so that it sits there, so agents that play on unchanged do not move
    /// when others join. None (or an agent without a match against another): the fit's own scale.
    pub anchor: Option<(i64, f64)>,
    /// An agent whose 95% interval is wider than this (or that has none) is provisional: listed
    /// after the established ones, whatever its rating.
    pub provisional_width: f64,
}

impl Default for Extras {
    fn default() -> Extras {
        Extras {
            glicko: HashMap::new(),
            drift: HashMap::new(),
            anchor: None,
            provisional_width: f64::INFINITY,
        }
    }
}

/// Which agents are established: an interval no wider than `width`, and a rated match against the
/// anchor or another established agent (the anchor is established; without one, the interval
/// alone decides). Newcomers that only met each other stay provisional however narrow their
/// intervals: nothing ties their ratings to the others'.
fn established(
    pairs: &[(usize, usize, f64, f64)],
    intervals: &[(Option<f64>, Option<f64>)],
    anchor: Option<usize>,
    width: f64,
) -> Vec<bool> {
    let narrow: Vec<bool> = intervals
        .iter()
        .map(|iv| matches!(iv, (Some(low), Some(high)) if high - low <= width))
        .collect();
    let Some(anchor) = anchor else {
        return narrow;
    };
    let mut known = vec![false; intervals.len()];
    known[anchor] = true;
    loop {
        let mut grew = false;
        for &(x, y, _, _) in pairs {
            for (from, to) in [(x, y), (y, x)] {
                if from != to && known[from] && !known[to] && narrow[to] {
                    known[to] = true;
                    grew = true;
                }
            }
        }
        if !grew {
            return known;
        }
    }
}

/// Bradley–Terry ratings of `n` agents from (A, B, points A, points B) matches, started from `start`.
fn fit(
    n: usize,
    sample: &mut dyn Iterator<Item = &(usize, usize, f64, f64)>,
    start: Option<&[f64]>,
) -> Vec<f64> {
    let mut wins = vec![vec![0.0; n]; n];
    for &(a, b, pa, pb) in sample {
        if a != b {
            wins[a][b] += pa;
            wins[b][a] += pb;
        }
    }
    bradley_terry_from(&wins, start)
}

/// Each agent's 95% interval: percentiles of [`BOOTSTRAP`] seeded resamples of the matches, each
/// fitted from `rating` and put on the scale by `anchored`. Matches against itself rate nothing:
/// without another opponent an agent has none.
fn intervals(
    n: usize,
    pairs: &[(usize, usize, f64, f64)],
    rating: &[f64],
    anchored: &dyn Fn(Vec<f64>) -> Vec<f64>,
) -> Vec<(Option<f64>, Option<f64>)> {
    let mut boot = vec![Vec::with_capacity(BOOTSTRAP); n];
    if !pairs.is_empty() {
        let mut state = 0x5eed_u64;
        for _ in 0..BOOTSTRAP {
            let picks: Vec<usize> = (0..pairs.len())
                .map(|_| (agents::seeds::splitmix64(&mut state) % pairs.len() as u64) as usize)
                .collect();
            let r = anchored(fit(n, &mut picks.iter().map(|&k| &pairs[k]), Some(rating)));
            for (i, x) in r.into_iter().enumerate() {
                boot[i].push(x);
            }
        }
    }
    (0..n)
        .map(|i| {
            let rated = pairs.iter().any(|p| p.0 != p.1 && (p.0 == i || p.1 == i));
            if !rated || boot[i].is_empty() {
                return (None, None);
            }
            let mut s = boot[i].clone();
            s.sort_by(f64::total_cmp);
            (Some(percentile(&s, 0.025)), Some(percentile(&s, 0.975)))
        })
        .collect()
}

/// Computes the leaderboard of `agents` from the finished matches.
pub fn leaderboard(agents: &[Entrant], outcomes: &[Outcome], extras: &Extras) -> Leaderboard {
    let n = agents.len();
    let index = |id: i64| agents.iter().position(|a| a.id == id);
    let pairs: Vec<(usize, usize, f64, f64)> = outcomes
        .iter()
        .filter_map(|o| Some((index(o.0)?, index(o.1)?, o.2 as f64, o.3 as f64)))
        .collect();
    // The anchor, if it has played another agent: the scale is shifted to hold it at its value.
    let anchor = extras.anchor.and_then(|(id, value)| {
        let i = index(id)?;
        pairs
            .iter()
            .any(|p| p.0 != p.1 && (p.0 == i || p.1 == i))
            .then_some((i, value))
    });
    let anchored = |mut r: Vec<f64>| {
        if let Some((i, value)) = anchor {
            let shift = value - r[i];
            r.iter_mut().for_each(|x| *x += shift);
        }
        r
    };
    let rating = fit(n, &mut pairs.iter(), None);
    let intervals = intervals(n, &pairs, &rating, &anchored);
    let rating = anchored(rating);
    let established = established(
        &pairs,
        &intervals,
        anchor.map(|a| a.0),
        extras.provisional_width,
    );
    let glicko = |id: i64| {
        extras
            .glicko
            .get(&id)
            .copied()
            .unwrap_or_else(glicko2_initial)
    };
    let mut rows: Vec<Row> = agents
        .iter()
        .enumerate()
        .map(|(i, a)| {
            let mine: Vec<&Outcome> = outcomes
                .iter()
                .filter(|o| o.0 == a.id || o.1 == a.id)
                .collect();
            let (mut won, mut decided) = (0i64, 0i64);
            for o in &mine {
                if o.0 != o.1 {
                    let (w, l) = if o.0 == a.id { (o.2, o.3) } else { (o.3, o.2) };
                    won += w;
                    decided += w + l;
                }
            }
            // Over its rallies, as its page's histogram counts them (not a mean of match means).
            let rallies: i64 = mine.iter().map(|o| o.8).sum();
            let mean_rally_length = (rallies > 0)
                .then(|| mine.iter().map(|o| o.4 * o.8 as f64).sum::<f64>() / rallies as f64);
            let interval = intervals[i];
            let provisional = !established[i];
            Row {
                rank: 0,
                agent_id: a.id,
                agent: a.name.clone(),
                builtin: a.builtin,
                rating: rating[i],
                rating_low: interval.0,
                rating_high: interval.1,
                provisional,
                matches: mine.iter().filter(|o| o.0 != o.1).count(),
                self_play_matches: mine.iter().filter(|o| o.0 == o.1).count(),
                points_won_pct: (decided > 0).then(|| 100.0 * won as f64 / decided as f64),
                mean_rally_length,
                max_rally_length: mine.iter().map(|o| o.5).max(),
                in_box_fraction: extras.drift.get(&a.id).and_then(|d| d.0),
                drift: extras.drift.get(&a.id).and_then(|d| d.1),
                glicko2: glicko(a.id).0,
                glicko2_deviation: glicko(a.id).1,
                hit_rate: a.hit_rate,
                success_rate: a.success_rate,
            }
        })
        .collect();
    // The established first, then the provisional, each by rating.
    rows.sort_by(|x, y| {
        x.provisional
            .cmp(&y.provisional)
            .then(y.rating.total_cmp(&x.rating))
            .then(x.agent_id.cmp(&y.agent_id))
    });
    for (k, r) in rows.iter_mut().enumerate() {
        r.rank = k + 1;
    }
    Leaderboard {
        matches: outcomes.len(),
        anchor: anchor.map(|(i, rating)| wire::Anchor {
            agent: agents[i].name.clone(),
            rating,
        }),
        rows,
    }
}

/// One Glicko-2 update (default configuration) after a match: the sides' previous (rating,
/// deviation, volatility) — `None` for an agent that never played — and their points; one game won
/// by the side with more points.
pub fn glicko2_step(
    a: Option<(f64, f64, f64)>,
    b: Option<(f64, f64, f64)>,
    points_a: u32,
    points_b: u32,
) -> ((f64, f64, f64), (f64, f64, f64)) {
    use skillratings::glicko2::{glicko2 as update, Glicko2Config, Glicko2Rating};
    use skillratings::Outcomes;
    let rating = |r: Option<(f64, f64, f64)>| match r {
        Some((rating, deviation, volatility)) => Glicko2Rating {
            rating,
            deviation,
            volatility,
        },
        None => Glicko2Rating::new(),
    };
    let outcome = match points_a.cmp(&points_b) {
        std::cmp::Ordering::Greater => Outcomes::WIN,
        std::cmp::Ordering::Less => Outcomes::LOSS,
        std::cmp::Ordering::Equal => Outcomes::DRAW,
    };
    let (x, y) = update(&rating(a), &rating(b), &outcome, &Glicko2Config::new());
    (
        (x.rating, x.deviation, x.volatility),
        (y.rating, y.deviation, y.volatility),
    )
}

/// Glicko-2's starting rating and deviation (an agent that has not played).
pub fn glicko2_initial() -> (f64, f64) {
    let r = skillratings::glicko2::Glicko2Rating::new();
    (r.rating, r.deviation)
}

/// The expected point share of a side `elo` Elo points stronger (the Bradley–Terry scale above).
pub fn elo_to_score(elo: f64) -> f64 {
    1.0 / (1.0 + 10f64.powf(-elo / 400.0))
}

/// The share of a match's points won by `agent`, given who played side A and the points of A and
/// B; None when no point was decided.
pub fn share_of(agent: i64, side_a: i64, points_a: i64, points_b: i64) -> Option<f64> {
    let mine = if side_a == agent { points_a } else { points_b };
    (points_a + points_b > 0).then(|| mine as f64 / (points_a + points_b) as f64)
}

/// The SPRT's log-likelihood ratio of H1 (A's Elo advantage on points is `elo1`) against H0 (it is
/// `elo0`) after matches whose point shares for A are `scores`: the generalised SPRT of fishtest, a
/// normal model of the per-match share, LLR = N (s1 − s0)(2 x̄ − s0 − s1) / (2 σ²), with σ² the sample
/// variance but never below the binomial variance of a match of `points` independent points at the
/// hypotheses' midpoint (so a few identical scores cannot decide it alone). 0 before two matches.
pub fn sprt_llr(scores: &[f64], points: f64, elo0: f64, elo1: f64) -> f64 {
    let n = scores.len();
    if n < 2 {
        return 0.0;
    }
    let (s0, s1) = (elo_to_score(elo0), elo_to_score(elo1));
    let mean = scores.iter().sum::<f64>() / n as f64;
    let var = scores.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let mid = 0.5 * (s0 + s1);
    let floor = mid * (1.0 - mid) / points.max(1.0);
    let var = var.max(floor);
    n as f64 * (s1 - s0) * (2.0 * mean - s0 - s1) / (2.0 * var)
}

/// Wald's bounds (lower, upper) on the log-likelihood ratio for error rates α and β: accept H0 at or
/// below ln(β/(1−α)), H1 at or above ln((1−β)/α).
pub fn sprt_bounds(alpha: f64, beta: f64) -> (f64, f64) {
    ((beta / (1.0 - alpha)).ln(), ((1.0 - beta) / alpha).ln())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_players_match_the_closed_form() {
        // With the prior, player 0 has won w+1 of its games; the MM fixed point for two players and an
        // anchor is checked by the likelihood equations: W_i = Σ_j n_ij γ_i/(γ_i+γ_j).
        let wins = vec![vec![0.0, 30.0], vec![10.0, 0.0]];
        let r = bradley_terry(&wins);
        let g: Vec<f64> = r.iter().map(|x| 10f64.powf((x - 1500.0) / 400.0)).collect();
        for i in 0..2 {
            let j = 1 - i;
            let expected = 2.0 * g[i] / (g[i] + 1.0) + 40.0 * g[i] / (g[i] + g[j]);
            assert!((expected - (wins[i][j] + 1.0)).abs() < 1e-6, "{expected}");
        }
        assert!(r[0] > 1500.0 && r[1] < 1500.0);
    }

    #[test]
    fn no_games_means_the_anchor_rating() {
        let r = bradley_terry(&[vec![0.0, 0.0], vec![0.0, 0.0]]);
        assert!(r.iter().all(|x| (x - 1500.0).abs() < 1e-9));
    }

    #[test]
    fn glicko2_moves_the_winner_up_and_shrinks_deviations() {
        let (a, b) = glicko2_step(None, None, 12, 8);
        assert!(a.0 > 1500.0 && b.0 < 1500.0);
        assert!(a.1 < 350.0 && b.1 < 350.0);
        // Two equal new players: the update is symmetric about 1500.
        assert!((a.0 - 1500.0 + (b.0 - 1500.0)).abs() < 1e-9);
        let (a2, _) = glicko2_step(Some(a), Some(b), 11, 9);
        assert!(
            a2.0 > a.0 && a2.1 < a.1,
            "winning again raises it and narrows it"
        );
        let (d, _) = glicko2_step(None, None, 10, 10);
        assert!(
            (d.0 - 1500.0).abs() < 1e-9,
            "a draw between equals moves nothing"
        );
        assert_eq!(glicko2_initial(), (1500.0, 350.0));
    }

    #[test]
    fn sprt_llr_matches_the_normal_closed_form() {
        // Scores 0.6 and 0.7 alternating: mean 0.65, sample variance 0.005·(n/(n−1)).
        let scores: Vec<f64> = (0..10)
            .map(|k| if k % 2 == 0 { 0.6 } else { 0.7 })
            .collect();
        let (s0, s1) = (elo_to_score(0.0), elo_to_score(50.0));
        let var = 10.0 * 0.0025 / 9.0;
        let expected = 10.0 * (s1 - s0) * (2.0 * 0.65 - s0 - s1) / (2.0 * var);
        let llr = sprt_llr(&scores, 1000.0, 0.0, 50.0);
        assert!(
            (llr - expected).abs() < 1e-9 * expected.abs(),
            "{llr} vs {expected}"
        );
        assert!(llr > 0.0, "a mean above both hypotheses favours H1");
        // At the midpoint of the hypotheses the evidence is nil; below it, it favours H0.
        let mid = 0.5 * (s0 + s1);
        assert!(sprt_llr(&[mid - 0.05, mid + 0.05], 20.0, 0.0, 50.0).abs() < 1e-12);
        assert!(sprt_llr(&[0.4, 0.45, 0.42], 20.0, 0.0, 50.0) < 0.0);
        assert_eq!(
            sprt_llr(&[0.9], 20.0, 0.0, 50.0),
            0.0,
            "one match decides nothing"
        );
        // Identical scores use the binomial floor, not a zero variance.
        let same = sprt_llr(&[0.6, 0.6, 0.6], 20.0, 0.0, 50.0);
        let floor = mid * (1.0 - mid) / 20.0;
        let expected = 3.0 * (s1 - s0) * (1.2 - s0 - s1) / (2.0 * floor);
        assert!((same - expected).abs() < 1e-9);
        let (lo, hi) = sprt_bounds(0.05, 0.05);
        assert!((lo + 2.944_438_979).abs() < 1e-6 && (hi - 2.944_438_979).abs() < 1e-6);
    }

    #[test]
    fn a_match_against_itself_counts_its_rallies_but_rates_nothing() {
        let entrant = |id| Entrant {
            id,
            name: format!("a{id}"),
            builtin: true,
            hit_rate: None,
            success_rate: None,
        };
        let agents = [entrant(1), entrant(2), entrant(3)];
        let outcomes: Vec<Outcome> = vec![
            (1, 2, 12, 8, 1.0, 3, None, None, 20),
            (3, 3, 10, 10, 4.5, 21, None, None, 20),
            (3, 3, 1, 1, 1.5, 2, None, None, 2),
        ];
        let board = leaderboard(&agents, &outcomes, &Extras::default());
        let row = |id| board.rows.iter().find(|r| r.agent_id == id).unwrap();
        let (one, three) = (row(1), row(3));
        assert!(one.rating_low.is_some() && one.points_won_pct == Some(60.0));
        assert_eq!(
            (
                three.matches,
                three.self_play_matches,
                three.max_rally_length
            ),
            (0, 2, Some(21)),
            "its matches are against itself: not rated"
        );
        assert_eq!((one.matches, one.self_play_matches), (1, 0));
        // Over its 22 rallies: (4.5·20 + 1.5·2) / 22.
        assert_eq!(three.mean_rally_length, Some(93.0 / 22.0));
        assert_eq!((three.rating, three.points_won_pct), (1500.0, None));
        assert!(
            three.rating_low.is_none(),
            "no interval without a rated match: continuous mode still counts it most uncertain"
        );
    }

    /// Three established agents with many matches among them; then ten junk agents, as continuous
    /// mode once paired them: only against each other, one sweeping the others 20–0 again and again.
    #[test]
    fn ten_junk_agents_barely_move_the_anchored_scale_and_rank_below_the_established() {
        let entrant = |id: i64, name: &str| Entrant {
            id,
            name: name.into(),
            builtin: id <= 3,
            hit_rate: None,
            success_rate: None,
        };
        let mut agents = vec![
            entrant(1, "scripted"),
            entrant(2, "kmac"),
            entrant(3, "kmac-rally"),
        ];
        let outcome = |a: i64, b: i64, pa: i64, pb: i64| -> Outcome {
            (a, b, pa, pb, 3.0, 9, Some(0.9), Some(0.1), pa + pb)
        };
        let mut outcomes = Vec::new();
        for k in 0..40 {
            outcomes.push(outcome(2, 1, 12 + k % 3, 8 - k % 3));
            outcomes.push(outcome(3, 1, 13 - k % 2, 7 + k % 2));
            outcomes.push(outcome(3, 2, 11, 9));
        }
        let extras = Extras {
            anchor: Some((1, 1500.0)),
            provisional_width: 200.0,
            ..Extras::default()
        };
        let before = leaderboard(&agents, &outcomes, &extras);
        let anchor = before.anchor.clone().expect("anchored");
        assert_eq!((anchor.agent.as_str(), anchor.rating), ("scripted", 1500.0));
        assert!(before.rows.iter().all(|r| !r.provisional), "{before:?}");
        let rating =
            |b: &Leaderboard, id: i64| b.rows.iter().find(|r| r.agent_id == id).unwrap().clone();
        assert_eq!(rating(&before, 1).rating, 1500.0);
        for j in 0..10 {
            agents.push(entrant(10 + j, &format!("junk-{j}")));
        }
        for _ in 0..3 {
            for j in 1..10 {
                outcomes.push(outcome(10, 10 + j, 20, 0));
                outcomes.push(outcome(10 + j, 10 + (j % 9) + 1, 10, 10));
            }
        }
        let after = leaderboard(&agents, &outcomes, &extras);
        for id in 1..=3 {
            let moved = (rating(&after, id).rating - rating(&before, id).rating).abs();
            assert!(moved < 5.0, "agent {id} moved {moved:.1}");
        }
        let top = rating(&after, 3);
        assert!(!top.provisional);
        for j in 0..10 {
            let junk = rating(&after, 10 + j);
            assert!(junk.provisional, "{junk:?}");
            assert!(junk.rank > top.rank, "{junk:?} above {top:?}");
        }
        // Unanchored and without the provisional rule, the sweeping junk agent rose above kmac-rally:
        // what the two rules are for.
        let loose = leaderboard(&agents, &outcomes, &Extras::default());
        assert!(rating(&loose, 10).rating > rating(&loose, 3).rating);
    }
}
