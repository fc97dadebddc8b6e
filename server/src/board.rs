//! The leaderboards the API serves and continuous mode schedules by, one per robot: computed from
//! the robot's agents and finished matches off the async threads, cached until an agent or a
//! finished match of that robot is added.

use std::sync::Arc;

use crate::state::AppState;
use crate::{db, ratings};

/// Robot `model`'s leaderboard (retired agents left out), recomputed when one of its agents was
/// added or retired or one of its matches finished. Its ratings are anchored on its own scripted
/// built-in (`rating_anchor`, prefixed with the robot's name off the default robot).
pub async fn current_board(s: &AppState, model: &str) -> anyhow::Result<Arc<ratings::Leaderboard>> {
    let (agents_n, done) = db::board_key(&s.pool, model).await?;
    let mut cache = s.board.lock().await;
    if let Some((a, d, b)) = cache.get(model) {
        if *a == agents_n as usize && *d == done {
            return Ok(b.clone());
        }
    }
    let agents = db::agents_of(&s.pool, model).await?;
    let outcomes = db::outcomes(&s.pool, model).await?;
    let anchor = crate::arenas::builtin_name(model, &s.settings.rating_anchor);
    let extras = ratings::Extras {
        glicko: db::latest_glicko(&s.pool, model)
            .await?
            .into_iter()
            .map(|(id, r, d)| (id, (r, d)))
            .collect(),
        drift: db::agent_drift(&s.pool, model)
            .await?
            .into_iter()
            .map(|(id, b, e)| (id, (b, e)))
            .collect(),
        anchor: agents
            .iter()
            .find(|a| a.name.eq_ignore_ascii_case(&anchor))
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
    cache.insert(model.to_string(), (agents_n as usize, done, board.clone()));
    Ok(board)
}
