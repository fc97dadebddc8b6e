//! Tournaments: which matches a round robin or a gauntlet queues, and the view of one in progress —
//! counts by status, standings and a cross-table of points between every two agents.

use std::collections::HashMap;

use serde::Serialize;

use crate::db::{Match, MatchStatus};
pub use wire::{Cell, Progress, ProgressState, Record, Standing, TournamentKind as Kind};

/// The matches of a tournament of `n` agents as (side A, side B) indices, round after round; sides
/// are swapped in every other round so that over two rounds each agent serves first equally often.
pub fn pairs(kind: Kind, n: usize, rounds: u32) -> Vec<(usize, usize)> {
    let once: Vec<(usize, usize)> = match kind {
        Kind::RoundRobin => (0..n)
            .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
            .collect(),
        Kind::Gauntlet => (1..n).map(|j| (0, j)).collect(),
    };
    (0..rounds)
        .flat_map(|r| {
            once.iter()
                .map(move |&(i, j)| if r % 2 == 0 { (i, j) } else { (j, i) })
        })
        .collect()
}

/// A tournament's state.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct View {
    /// Counts by status.
    pub progress: Progress,
    /// Standings, best first.
    pub standings: Vec<Standing>,
    /// Agent names in the order given (rows and columns of `cross_table`).
    pub cross_table_agents: Vec<String>,
    /// `cross_table[i][j]`: agent i against agent j (null on the diagonal and for pairs that do not
    /// meet, e.g. two challengers of a gauntlet).
    pub cross_table: Vec<Vec<Option<Cell>>>,
}

/// The view of a tournament among `agents` (id, name), from its matches.
pub fn view(kind: Kind, agents: &[(i64, String)], matches: &[Match]) -> View {
    let n = agents.len();
    let index: HashMap<i64, usize> = agents.iter().enumerate().map(|(k, a)| (a.0, k)).collect();
    let mut progress = Progress {
        total: matches.len(),
        ..Progress::default()
    };
    let mut table: Vec<Vec<Option<Cell>>> = vec![vec![None; n]; n];
    for (i, j) in pairs(kind, n, 1) {
        table[i][j] = Some(Cell::default());
        table[j][i] = Some(Cell::default());
    }
    let mut standings: Vec<Standing> = agents
        .iter()
        .map(|(id, name)| Standing {
            place: 0,
            agent_id: *id,
            agent: name.clone(),
            record: Record::default(),
            points_won_pct: None,
        })
        .collect();
    for m in matches {
        match m.status {
            MatchStatus::Queued => progress.queued += 1,
            MatchStatus::Running => progress.running += 1,
            MatchStatus::Failed => progress.failed += 1,
            MatchStatus::Cancelled => progress.cancelled += 1,
            MatchStatus::Done => progress.done += 1,
        }
        let (Some(pa), Some(pb)) = (m.points_a, m.points_b) else {
            continue;
        };
        let (Some(&i), Some(&j)) = (index.get(&m.agent_a), index.get(&m.agent_b)) else {
            continue;
        };
        for (me, them, won, lost) in [(i, j, pa, pb), (j, i, pb, pa)] {
            standings[me].record.add(won, lost);
            let cell = table[me][them].get_or_insert_with(Cell::default);
            cell.matches += 1;
            cell.points_for += won;
            cell.points_against += lost;
        }
    }
    let finished = progress.done + progress.failed + progress.cancelled;
    progress.fraction = if progress.total == 0 {
        1.0
    } else {
        finished as f64 / progress.total as f64
    };
    progress.state = if progress.queued + progress.running > 0 {
        ProgressState::Running
    } else {
        ProgressState::Finished
    };
    for s in &mut standings {
        s.points_won_pct = s.record.points_won_pct();
    }
    standings.sort_by(|x, y| {
        y.points_won_pct
            .unwrap_or(-1.0)
            .total_cmp(&x.points_won_pct.unwrap_or(-1.0))
            .then(y.record.points_for.cmp(&x.record.points_for))
            .then(x.agent_id.cmp(&y.agent_id))
    });
    for (k, s) in standings.iter_mut().enumerate() {
        s.place = k + 1;
    }
    View {
        progress,
        standings,
        cross_table_agents: agents.iter().map(|a| a.1.clone()).collect(),
        cross_table: table,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_robin_meets_every_pair_once_a_round_with_sides_swapped() {
        let p = pairs(Kind::RoundRobin, 4, 2);
        assert_eq!(p.len(), 12);
        let (r0, r1) = p.split_at(6);
        for (x, y) in r0.iter().zip(r1) {
            assert_eq!((x.0, x.1), (y.1, y.0));
        }
        let mut unordered: Vec<(usize, usize)> =
            r0.iter().map(|&(a, b)| (a.min(b), a.max(b))).collect();
        unordered.sort();
        unordered.dedup();
        assert_eq!(unordered.len(), 6, "every pair once");
        assert_eq!(pairs(Kind::Gauntlet, 4, 1), vec![(0, 1), (0, 2), (0, 3)]);
        assert_eq!(
            pairs(Kind::Gauntlet, 3, 2),
            vec![(0, 1), (0, 2), (1, 0), (2, 0)]
        );
    }

    fn m(id: i64, a: i64, b: i64, status: &str, points: Option<(i64, i64)>) -> Match {
        Match {
            status: status.parse().unwrap(),
            points_a: points.map(|p| p.0),
            points_b: points.map(|p| p.1),
            tournament_id: Some(1),
            ..crate::db::example_match(id, a, b)
        }
    }

    #[test]
    fn view_counts_standings_and_cross_table() {
        let agents = vec![
            (10, "x".to_string()),
            (20, "y".to_string()),
            (30, "z".to_string()),
        ];
        let matches = vec![
            m(1, 10, 20, "done", Some((7, 3))),
            m(2, 10, 30, "done", Some((4, 6))),
            m(3, 20, 30, "running", None),
            m(4, 20, 10, "done", Some((5, 5))),
            m(5, 30, 20, "cancelled", None),
        ];
        let v = view(Kind::RoundRobin, &agents, &matches);
        assert_eq!(
            (
                v.progress.total,
                v.progress.done,
                v.progress.running,
                v.progress.cancelled
            ),
            (5, 3, 1, 1)
        );
        assert!((v.progress.fraction - 0.8).abs() < 1e-12);
        assert_eq!(v.progress.state, ProgressState::Running);
        // x: 7+4+5 = 16 for, 3+6+5 = 14 against; y: 3+5 = 8 for, 12 against; z: 6 for, 4 against.
        let x = &v.standings.iter().find(|s| s.agent == "x").unwrap().record;
        assert_eq!((x.matches, x.wins, x.draws, x.losses), (3, 1, 1, 1));
        assert_eq!((x.points_for, x.points_against), (16, 14));
        assert_eq!(v.standings[0].agent, "z", "60% beats 53%");
        assert_eq!(v.standings[2].agent, "y");
        let xy = v.cross_table[0][1].as_ref().unwrap();
        assert_eq!((xy.matches, xy.points_for, xy.points_against), (2, 12, 8));
        let yx = v.cross_table[1][0].as_ref().unwrap();
        assert_eq!((yx.points_for, yx.points_against), (8, 12));
        assert!(v.cross_table[0][0].is_none());
        assert_eq!(v.cross_table[1][2].as_ref().unwrap().matches, 0);
        // A gauntlet's challengers never meet.
        let g = view(Kind::Gauntlet, &agents, &[]);
        assert!(g.cross_table[1][2].is_none() && g.cross_table[0][2].is_some());
        assert_eq!(g.progress.state, ProgressState::Finished);
    }
}
