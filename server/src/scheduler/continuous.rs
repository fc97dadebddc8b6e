//! Continuous mode: which match to queue, for each robot whose queue is empty: the agent whose
//! rating is least certain, against the opponent it met least — an established one first if it is
//! provisional. Each robot's agents meet only each other.

use crate::db;
use crate::state::AppState;

/// Queues one continuous-mode match for each robot this server plays whose queue is empty; true if
/// it queued any.
pub(super) async fn queue_continuous(state: &AppState) -> anyhow::Result<bool> {
    let mut queued = false;
    for arena in state.arenas.iter() {
        // One robot's failure (its store's answer, its board) leaves the others' matches coming.
        match queue_continuous_of(state, &arena.name).await {
            Ok(q) => queued |= q,
            Err(e) => tracing::error!(robot = %arena.name, error = %e, "continuous mode failed"),
        }
    }
    Ok(queued)
}

/// Queues one continuous-mode match of robot `model` if none of its matches is queued.
async fn queue_continuous_of(state: &AppState, model: &str) -> anyhow::Result<bool> {
    let queued = db::matches(
        &state.pool,
        db::MatchFilter {
            status: Some(db::MatchStatus::Queued),
            model: Some(model.to_string()),
            ..db::MatchFilter::default()
        },
        1,
    )
    .await?;
    if !queued.is_empty() {
        return Ok(false);
    }
    let mut agents = db::agents_of(&state.pool, model).await?;
    agents.retain(|a| a.retired_at.is_none());
    let every = i64::from(state.settings.continuous_self_play_every);
    if every > 0 && !agents.is_empty() && cooperative_turn(state, model, every).await? {
        let self_played = db::self_play_counts(&state.pool, model).await?;
        let agent = cooperative_pick(&agents, &self_played).expect("an agent");
        return queue_continuous_match(state, agent, agent).await;
    }
    if agents.len() < 2 {
        return Ok(false);
    }
    let outcomes = db::outcomes(&state.pool, model).await?;
    // The leaderboard the API serves (cached; recomputed off the async threads when it changed).
    let board = crate::board::current_board(state, model)
        .await
        .map_err(|e| anyhow::anyhow!("computing the leaderboard: {e:?}"))?;
    let row = |id: i64| board.rows.iter().find(|r| r.agent_id == id);
    let width = |id: i64| {
        row(id)
            .and_then(|r| Some(r.rating_high? - r.rating_low?))
            .unwrap_or(f64::INFINITY)
    };
    let provisional = |id: i64| row(id).is_none_or(|r| r.provisional);
    // Matches being played count as met, and their agents are picked last: the leaderboard does
    // not know their results yet.
    let pending = db::running_pairs(&state.pool, model).await?;
    let met = |x: i64, y: i64| {
        let pair = |a: i64, b: i64| (a == x && b == y) || (a == y && b == x);
        outcomes.iter().filter(|o| pair(o.0, o.1)).count()
            + pending.iter().filter(|p| pair(p.0, p.1)).count()
    };
    let busy = |id: i64| pending.iter().any(|p| p.0 == id || p.1 == id);
    let first = agents
        .iter()
        .max_by(|p, q| {
            busy(q.id)
                .cmp(&busy(p.id))
                .then(width(p.id).total_cmp(&width(q.id)))
                .then(q.id.cmp(&p.id))
        })
        .expect("two agents");
    // A provisional agent meets the established first: its rating then says where it stands among
    // them, not only among other newcomers.
    let newcomer = provisional(first.id);
    let second = agents
        .iter()
        .filter(|o| o.id != first.id)
        .min_by(|p, q| {
            (newcomer && provisional(p.id))
                .cmp(&(newcomer && provisional(q.id)))
                .then(met(first.id, p.id).cmp(&met(first.id, q.id)))
                .then(p.id.cmp(&q.id))
        })
        .expect("two agents");
    // Alternate sides so neither agent always serves first.
    let n = met(first.id, second.id);
    let (a, b) = if n % 2 == 0 {
        (first, second)
    } else {
        (second, first)
    };
    queue_continuous_match(state, a, b).await
}

/// Whether continuous mode's next match of robot `model` is cooperative: every `every`-th of its
/// matches, the first included.
async fn cooperative_turn(state: &AppState, model: &str, every: i64) -> anyhow::Result<bool> {
    Ok(db::match_count(&state.pool, model).await? % every == 0)
}

/// The agent of continuous mode's next cooperative match: the fewest such matches so far
/// (`self_played`: agent id, count), then the highest qualification success rate (none: last), then
/// the lowest id — so a fresh server shows its best rally player's rallies first.
fn cooperative_pick<'a>(
    agents: &'a [db::Agent],
    self_played: &[(i64, i64)],
) -> Option<&'a db::Agent> {
    let count = |id: i64| {
        self_played
            .iter()
            .find(|(a, _)| *a == id)
            .map_or(0, |(_, n)| *n)
    };
    agents.iter().min_by(|p, q| {
        count(p.id)
            .cmp(&count(q.id))
            .then(
                q.success_rate
                    .unwrap_or(-1.0)
                    .total_cmp(&p.success_rate.unwrap_or(-1.0)),
            )
            .then(p.id.cmp(&q.id))
    })
}

/// Queues continuous mode's match of `a` against `b`, without replay frames.
async fn queue_continuous_match(
    state: &AppState,
    a: &db::Agent,
    b: &db::Agent,
) -> anyhow::Result<bool> {
    // Distinct seeds for distinct matches (the next id; results not yet known do not repeat it).
    let seed = db::last_match_id(&state.pool).await? as u64 + 1;
    let id = db::queue_match(
        &state.pool,
        a,
        b,
        state.settings.continuous_rallies,
        seed,
        false,
        db::Origin::default(),
    )
    .await?;
    tracing::debug!(id, a = %a.name, b = %b.name, "continuous mode queued a match");
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn agent(id: i64, success_rate: Option<f64>) -> db::Agent {
        db::Agent {
            id,
            name: format!("a{id}"),
            kind: crate::domain::AgentKind::Checkpoint,
            model: "default".into(),
            spec_hash: String::new(),
            builtin: true,
            created_at: String::new(),
            qual_episodes: success_rate.map(|_| 100),
            hit_rate: success_rate,
            success_rate,
            effort: None,
            retired_at: None,
        }
    }

    #[test]
    fn the_cooperative_pick_takes_the_fewest_then_the_best_qualified() {
        let agents = [agent(1, None), agent(2, Some(0.4)), agent(3, Some(0.78))];
        let pick = |played: &[(i64, i64)]| cooperative_pick(&agents, played).unwrap().id;
        assert_eq!(pick(&[]), 3, "the best qualified first");
        assert_eq!(pick(&[(3, 1)]), 2);
        assert_eq!(pick(&[(3, 1), (2, 1)]), 1, "then the unqualified");
        assert_eq!(pick(&[(3, 1), (2, 1), (1, 1)]), 3, "and round again");
        assert!(cooperative_pick(&[], &[]).is_none());
    }
}
