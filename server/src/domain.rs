//! The server's rules that need no store: the ratings a finished match writes and an SPRT's next
//! step. The words they use (statuses, kinds) are the API's, in the `wire` crate.

pub use wire::{AgentKind, MatchStatus, SprtStatus, WorkerStatus};

/// A Glicko-2 rating: (rating, deviation, volatility).
pub type Glicko = (f64, f64, f64);

/// The ratings a finished match writes: both agents' Glicko-2 after it, from their last ratings
/// (none yet: the prior), one game won by the side with more points. A match of an agent against
/// itself rates nothing.
pub fn rating_update(
    agents: [i64; 2],
    last: [Option<Glicko>; 2],
    points: [u32; 2],
) -> Vec<(i64, Glicko)> {
    if agents[0] == agents[1] {
        return Vec::new();
    }
    let (a, b) = crate::ratings::glicko2_step(last[0], last[1], points[0], points[1]);
    vec![(agents[0], a), (agents[1], b)]
}

/// A match to queue: sides, rallies, seed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NextMatch {
    /// Side A's agent.
    pub a: i64,
    /// Side B's agent.
    pub b: i64,
    /// Rallies.
    pub rallies: u32,
    /// Seed.
    pub seed: u64,
}

/// An SPRT after one more of its matches finished.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SprtStep {
    /// Log-likelihood ratio over its finished matches.
    pub llr: f64,
    /// Its finished matches.
    pub matches_done: u64,
    /// Running, or the decision.
    pub status: SprtStatus,
    /// The match to queue when it goes on: sides swapped every match, the k-th with seed + k.
    pub next: Option<NextMatch>,
}

/// The SPRT's step (fishtest's GSPRT on per-match point shares, `ratings::sprt_llr`) from its
/// finished matches, as (side A's agent, points of A, points of B) in the order they were played:
/// accept H1 at or above the upper bound, H0 at or below the lower, stop undecided after
/// `max_matches`, else queue the next match. `s` is the SPRT's stored row: its settings.
pub fn sprt_step(s: &wire::Sprt, done: &[(i64, i64, i64)]) -> SprtStep {
    let scores: Vec<f64> = done
        .iter()
        .filter_map(|&(a, pa, pb)| crate::ratings::share_of(s.agent_a, a, pa, pb))
        .collect();
    let llr = crate::ratings::sprt_llr(&scores, s.rallies_per_match as f64, s.elo0, s.elo1);
    let (lower, upper) = crate::ratings::sprt_bounds(s.alpha, s.beta);
    let n = done.len() as u64;
    let status = if llr >= upper {
        SprtStatus::AcceptedH1
    } else if llr <= lower {
        SprtStatus::AcceptedH0
    } else if n >= s.max_matches.max(0) as u64 {
        SprtStatus::Inconclusive
    } else {
        SprtStatus::Running
    };
    let next = (status == SprtStatus::Running).then(|| {
        let (a, b) = if n.is_multiple_of(2) {
            (s.agent_a, s.agent_b)
        } else {
            (s.agent_b, s.agent_a)
        };
        NextMatch {
            a,
            b,
            rallies: s.rallies_per_match as u32,
            // Seeds are stored as SQL integers: keep them non-negative.
            seed: (s.seed as u64).wrapping_add(n) & (i64::MAX as u64),
        }
    });
    SprtStep {
        llr,
        matches_done: n,
        status,
        next,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn words_round_trip_through_strings_and_json() {
        for s in MatchStatus::ALL {
            assert_eq!(s.as_str().parse::<MatchStatus>(), Ok(*s));
            assert_eq!(serde_json::to_string(s).unwrap(), format!("\"{s}\""));
        }
        assert_eq!(
            serde_json::from_str::<SprtStatus>("\"accepted_h1\"").unwrap(),
            SprtStatus::AcceptedH1
        );
        let e = "finished".parse::<MatchStatus>().unwrap_err();
        assert_eq!(e, "must be one of queued, running, done, failed, cancelled");
    }

    fn spec() -> wire::Sprt {
        wire::Sprt {
            id: 1,
            agent_a: 1,
            agent_b: 2,
            elo0: 0.0,
            elo1: 50.0,
            alpha: 0.05,
            beta: 0.05,
            rallies_per_match: 10,
            max_matches: 6,
            seed: 40,
            status: SprtStatus::Running,
            llr: 0.0,
            matches_done: 0,
            created_by: None,
            created_at: String::new(),
            finished_at: None,
        }
    }

    #[test]
    fn an_sprt_swaps_sides_counts_seeds_and_decides() {
        // Nothing played: running, agent 1 on side A with the first seed.
        let s = sprt_step(&spec(), &[]);
        assert_eq!(s.status, SprtStatus::Running);
        assert_eq!(
            s.next,
            Some(NextMatch {
                a: 1,
                b: 2,
                rallies: 10,
                seed: 40
            })
        );
        // One played: sides swapped, seed + 1.
        let s = sprt_step(&spec(), &[(1, 6, 4)]);
        assert_eq!(s.next.map(|m| (m.a, m.b, m.seed)), Some((2, 1, 41)));
        // Agent 1 winning every point, whichever side it was on: H1 (a 95%/5% test needs few).
        let crushing: Vec<(i64, i64, i64)> = (0..6)
            .map(|k| if k % 2 == 0 { (1, 10, 0) } else { (2, 0, 10) })
            .collect();
        let won = (2..=6)
            .map(|n| sprt_step(&spec(), &crushing[..n]))
            .find(|s| s.status != SprtStatus::Running)
            .expect("decided");
        assert_eq!((won.status, won.next), (SprtStatus::AcceptedH1, None));
        assert!(won.llr >= crate::ratings::sprt_bounds(0.05, 0.05).1);
        // Even results for max_matches: undecided, nothing queued.
        let even: Vec<(i64, i64, i64)> =
            (0..6).map(|k| (1 + k % 2, 5 + k % 2, 5 - k % 2)).collect();
        let s = sprt_step(&spec(), &even);
        assert_eq!(
            (s.status, s.next, s.matches_done),
            (SprtStatus::Inconclusive, None, 6)
        );
    }

    #[test]
    fn a_match_against_itself_rates_nothing() {
        assert!(rating_update([3, 3], [None, None], [7, 3]).is_empty());
        let r = rating_update([3, 4], [None, None], [7, 3]);
        assert_eq!((r[0].0, r[1].0), (3, 4));
        assert!(
            r[0].1 .0 > r[1].1 .0,
            "the winner's rating is higher: {r:?}"
        );
    }

    #[test]
    fn the_migrations_check_the_same_words() {
        // The CHECK constraints are the database's copy of these enums.
        let sql = [
            include_str!("../../migrations/0001_init.sql"),
            include_str!("../../migrations/0003_tournaments_sprt_history.sql"),
            include_str!("../../migrations/0004_workers_leases.sql"),
        ]
        .join("\n");
        let quoted = |words: Vec<&str>| {
            words
                .iter()
                .map(|w| format!("'{w}'"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        for list in [
            quoted(MatchStatus::ALL.iter().map(|s| s.as_str()).collect()),
            quoted(AgentKind::ALL.iter().map(|s| s.as_str()).collect()),
            quoted(SprtStatus::ALL.iter().map(|s| s.as_str()).collect()),
            quoted(WorkerStatus::ALL.iter().map(|s| s.as_str()).collect()),
        ] {
            assert!(
                sql.contains(&format!("IN ({list})")),
                "no CHECK (… IN ({list}))"
            );
        }
    }
}
