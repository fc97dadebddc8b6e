//! The leaderboard the API serves and continuous mode schedules by: computed from the agents and the
//! finished matches off the async threads, cached until an agent or a finished match is added.

use std::sync::Arc;

use crate::state::AppState;
use crate::{db, ratings};

/// The leaderboard (retired agents left out), recomputed when an agent was added or retired or a
/// match finished.
pub async fn current_board(s: &AppState) -> anyhow::Result<Arc<ratings::Leaderboard>> {
    let (agents_n, done) = db::board_key(&s.pool).await?;
    let mut cache = s.board.lock().await;
    if let Some((a, d, b)) = cache.as_ref() {
        if *a == agents_n as usize && *d == done {
            return Ok(b.clone());
        }
    }
    let agents = db::agents(&s.pool).await?;
    let outcomes = db::outcomes(&s.pool).await?;
    let extras = ratings::Extras {
        glicko: db::latest_glicko(&s.pool)
            .await?
            .into_iter()
            .map(|(id, r, d)| (id, (r, d)))
            .collect(),
        drift: db::agent_drift(&s.pool)
            .await?
            .into_iter()
            .map(|(id, b, e)| (id, (b, e)))
            .collect(),
        anchor: agents
            .iter()
            .find(|a| a.name.eq_ignore_ascii_case(&s.settings.rating_anchor))
            .map(|a| (a.id, s.settings.rating_anchor_value)),
        provisional_width: s.settings.provisional_interval,
    };
    let board = Arc::new(
        tokio::task::spawn_blocking(move || {
            let entrants: Vec<ratings::Entrant> = agents.iter().map(Into::into).collect();
            let mut board = ratings::leaderboard(&entrants, &outcomes, &extras);
            // Retired agents' matches still rate the others; their rows are not shown.
            let retired = |id: i64| agents.iter().any(|a| a.id == id && a.retired_at.is_some());
            board.rows.retain(|r| !retired(r.agent_id));
            for (i, r) in board.rows.iter_mut().enumerate() {
                r.rank = i + 1;
            }
            board
        })
        .await
        .map_err(|e| anyhow::anyhow!("{e}"))?,
    );
    *cache = Some((agents_n as usize, done, board.clone()));
    Ok(board)
}
