//! A tournament in progress as the API shows it: counts by status, standings, cross-table cells.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Whether a tournament still has matches to play.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ProgressState {
    /// Some of its matches are queued or running.
    #[default]
    Running,
    /// Every match ended (done, failed or cancelled).
    Finished,
}

/// How far a tournament has got.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct Progress {
    /// Matches in it.
    pub total: usize,
    /// Waiting for a worker.
    pub queued: usize,
    /// Being played.
    pub running: usize,
    /// Finished and stored.
    pub done: usize,
    /// Failed.
    pub failed: usize,
    /// Cancelled.
    pub cancelled: usize,
    /// Finished (done, failed or cancelled) / total.
    pub fraction: f64,
    /// "running" while any match is queued or running, else "finished".
    pub state: ProgressState,
}

/// One agent's line in the standings.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct Standing {
    /// 1-based place: by points won %, then points won, then id.
    pub place: usize,
    /// Agent id.
    pub agent_id: i64,
    /// Agent name.
    pub agent: String,
    /// Its matches, wins, draws, losses and points.
    #[serde(flatten)]
    pub record: Record,
    /// Points won / points decided, percent (null before a point).
    pub points_won_pct: Option<f64>,
}

/// One agent's record over finished matches (a tournament's standings, `rally batch`'s summary).
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq, Eq, JsonSchema)]
pub struct Record {
    /// Finished matches.
    pub matches: usize,
    /// Matches with more points than the opponent.
    pub wins: usize,
    /// Matches with as many.
    pub draws: usize,
    /// Matches with fewer.
    pub losses: usize,
    /// Points won.
    pub points_for: i64,
    /// Points lost.
    pub points_against: i64,
}

impl Record {
    /// Counts one finished match in which the agent won `won` points and lost `lost`.
    pub fn add(&mut self, won: i64, lost: i64) {
        self.matches += 1;
        self.points_for += won;
        self.points_against += lost;
        match won.cmp(&lost) {
            std::cmp::Ordering::Greater => self.wins += 1,
            std::cmp::Ordering::Equal => self.draws += 1,
            std::cmp::Ordering::Less => self.losses += 1,
        }
    }

    /// Points won / points decided, percent (none before a point).
    pub fn points_won_pct(&self) -> Option<f64> {
        let decided = self.points_for + self.points_against;
        (decided > 0).then(|| 100.0 * self.points_for as f64 / decided as f64)
    }
}

/// A cell of the cross-table: the row agent's record against the column agent.
#[derive(Debug, Clone, Default, Serialize, Deserialize, PartialEq, JsonSchema)]
pub struct Cell {
    /// Finished matches between the two.
    pub matches: usize,
    /// Points the row agent won.
    pub points_for: i64,
    /// Points it lost.
    pub points_against: i64,
}
