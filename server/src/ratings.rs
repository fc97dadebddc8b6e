//! Ratings (DESIGN §8): Bradley–Terry over points, fitted by the MM algorithm (Hunter 2004) with a
//! weak prior — every agent is credited one point won and one lost against a virtual anchor of
//! strength 1 — and reported on the Elo scale, `1500 + 400·log10 γ`, so the anchor sits at 1500.
//! 95% intervals come from a seeded bootstrap over matches (deterministic: the same matches give the
//! same leaderboard). Glicko-2 (the `skillratings` crate, default configuration) is an online view
//! beside it: matches in the order they were queued, each one game won by the side with more points.

use serde::Serialize;

use crate::db::{Agent, Outcome};

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

/// One leaderboard row.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// 1-based rank by rating.
    pub rank: usize,
    /// Agent id.
    pub agent_id: i64,
    /// Agent name.
    pub agent: String,
    /// Built in.
    pub builtin: bool,
    /// Bradley–Terry rating (Elo scale).
    pub rating: f64,
    /// 95% bootstrap interval (null without a finished match).
    pub rating_low: Option<f64>,
    /// Upper end.
    pub rating_high: Option<f64>,
    /// Finished matches.
    pub matches: usize,
    /// Points won / points decided, in percent (null without points).
    pub points_won_pct: Option<f64>,
    /// Mean rally length over its matches' rallies.
    pub mean_rally_length: Option<f64>,
    /// Longest rally it played.
    pub max_rally_length: Option<i64>,
    /// Fraction of its matches' crossings inside the serve box (mean over matches).
    pub in_box_fraction: Option<f64>,
    /// Serve → return energy distance of its matches (mean over matches that have one).
    pub drift: Option<f64>,
    /// Glicko-2 rating (online, one game per match).
    pub glicko2: f64,
    /// Its rating deviation.
    pub glicko2_deviation: f64,
    /// Qualification hit rate (checkpoints).
    pub hit_rate: Option<f64>,
    /// Qualification success rate.
    pub success_rate: Option<f64>,
}

/// The leaderboard.
#[derive(Debug, Clone, Serialize)]
pub struct Leaderboard {
    /// Finished matches it is computed from.
    pub matches: usize,
    /// Rows, best first.
    pub rows: Vec<Row>,
}

fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    let k = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[k]
}

/// Computes the leaderboard of `agents` from the finished matches.
pub fn leaderboard(agents: &[Agent], outcomes: &[Outcome]) -> Leaderboard {
    let n = agents.len();
    let index = |id: i64| agents.iter().position(|a| a.id == id);
    let pairs: Vec<(usize, usize, f64, f64)> = outcomes
        .iter()
        .filter_map(|o| Some((index(o.0)?, index(o.1)?, o.2 as f64, o.3 as f64)))
        .collect();
    let fit = |sample: &mut dyn Iterator<Item = &(usize, usize, f64, f64)>,
               start: Option<&[f64]>| {
        let mut wins = vec![vec![0.0; n]; n];
        for &(a, b, pa, pb) in sample {
            if a != b {
                wins[a][b] += pa;
                wins[b][a] += pb;
            }
        }
        bradley_terry_from(&wins, start)
    };
    let rating = fit(&mut pairs.iter(), None);
    let mut boot = vec![Vec::with_capacity(BOOTSTRAP); n];
    if !pairs.is_empty() {
        let mut state = 0x5eed_u64;
        for _ in 0..BOOTSTRAP {
            let picks: Vec<usize> = (0..pairs.len())
                .map(|_| (splitmix(&mut state) % pairs.len() as u64) as usize)
                .collect();
            let r = fit(&mut picks.iter().map(|&k| &pairs[k]), Some(&rating));
            for (i, x) in r.into_iter().enumerate() {
                boot[i].push(x);
            }
        }
    }
    let glicko = glicko2(n, &pairs);
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
            let mean =
                |xs: Vec<f64>| (!xs.is_empty()).then(|| xs.iter().sum::<f64>() / xs.len() as f64);
            let interval = if mine.is_empty() || boot[i].is_empty() {
                (None, None)
            } else {
                let mut s = boot[i].clone();
                s.sort_by(f64::total_cmp);
                (Some(percentile(&s, 0.025)), Some(percentile(&s, 0.975)))
            };
            Row {
                rank: 0,
                agent_id: a.id,
                agent: a.name.clone(),
                builtin: a.builtin,
                rating: rating[i],
                rating_low: interval.0,
                rating_high: interval.1,
                matches: mine.len(),
                points_won_pct: (decided > 0).then(|| 100.0 * won as f64 / decided as f64),
                mean_rally_length: mean(mine.iter().map(|o| o.4).collect()),
                max_rally_length: mine.iter().map(|o| o.5).max(),
                in_box_fraction: mean(mine.iter().filter_map(|o| o.6).collect()),
                drift: mean(mine.iter().filter_map(|o| o.7).collect()),
                glicko2: glicko[i].rating,
                glicko2_deviation: glicko[i].deviation,
                hit_rate: a.hit_rate,
                success_rate: a.success_rate,
            }
        })
        .collect();
    rows.sort_by(|x, y| {
        y.rating
            .total_cmp(&x.rating)
            .then(x.agent_id.cmp(&y.agent_id))
    });
    for (k, r) in rows.iter_mut().enumerate() {
        r.rank = k + 1;
    }
    Leaderboard {
        matches: outcomes.len(),
        rows,
    }
}

/// Glicko-2 ratings of `n` agents after the matches `(a, b, points a, points b)` in order.
fn glicko2(
    n: usize,
    pairs: &[(usize, usize, f64, f64)],
) -> Vec<skillratings::glicko2::Glicko2Rating> {
    use skillratings::glicko2::{glicko2 as update, Glicko2Config, Glicko2Rating};
    use skillratings::Outcomes;
    let config = Glicko2Config::new();
    let mut r = vec![Glicko2Rating::new(); n];
    for &(a, b, pa, pb) in pairs {
        if a == b {
            continue;
        }
        let outcome = if pa > pb {
            Outcomes::WIN
        } else if pa < pb {
            Outcomes::LOSS
        } else {
            Outcomes::DRAW
        };
        let (x, y) = update(&r[a], &r[b], &outcome, &config);
        r[a] = x;
        r[b] = y;
    }
    r
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
        let g = glicko2(3, &[(0, 1, 12.0, 8.0), (1, 0, 9.0, 11.0)]);
        assert!(g[0].rating > 1500.0 && g[1].rating < 1500.0);
        assert!(g[0].deviation < 350.0 && g[1].deviation < 350.0);
        assert_eq!(
            (g[2].rating, g[2].deviation),
            (1500.0, 350.0),
            "an agent that never played is untouched"
        );
    }
}
