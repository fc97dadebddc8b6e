//! Following a submitted batch: the server polled until every match, tournament and SPRT has
//! finished, with one progress bar for the plain matches and one per tournament and SPRT.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use anyhow::anyhow;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use wire::ProgressState;

use super::client::Client;
use super::{CliError, Contest, Submitted};

/// What following gave: the rows of the plain matches (by id), the last views of the tournaments
/// and SPRTs (in submission order).
pub(super) struct Followed {
    pub(super) rows: HashMap<i64, wire::Match>,
    pub(super) tournaments: Vec<wire::TournamentView>,
    pub(super) sprts: Vec<wire::SprtView>,
}

/// The bars and the last answers of the server while following.
struct Follower {
    plain_bar: Option<ProgressBar>,
    t_bars: Vec<ProgressBar>,
    s_bars: Vec<ProgressBar>,
    rows: HashMap<i64, wire::Match>,
    views: Vec<Option<wire::TournamentView>>,
    sprt_views: Vec<Option<wire::SprtView>>,
}

fn finished(s: wire::MatchStatus) -> bool {
    matches!(
        s,
        wire::MatchStatus::Done | wire::MatchStatus::Failed | wire::MatchStatus::Cancelled
    )
}

/// Polls the server every `poll` seconds until everything `submitted` has finished; gives up after
/// `timeout` seconds (the matches go on on the server).
pub(super) fn follow(
    client: &Client,
    submitted: &Submitted,
    bars: &MultiProgress,
    poll: f64,
    timeout: f64,
) -> Result<Followed, CliError> {
    let mut f = Follower::new(submitted, bars);
    let started = Instant::now();
    loop {
        let mut all_done = f.poll_matches(client, &submitted.matches)?;
        all_done &= f.poll_tournaments(client, &submitted.tournaments)?;
        all_done &= f.poll_sprts(client, &submitted.sprts)?;
        if all_done {
            break;
        }
        if started.elapsed().as_secs_f64() > timeout {
            bars.clear().ok();
            return Err(CliError::Failed(anyhow!(
                "gave up following after {timeout} s; the matches go on on the server"
            )));
        }
        std::thread::sleep(Duration::from_secs_f64(poll));
    }
    for b in f
        .t_bars
        .iter()
        .chain(f.s_bars.iter())
        .chain(f.plain_bar.iter())
    {
        b.finish();
    }
    Ok(Followed {
        rows: f.rows,
        tournaments: f.views.into_iter().flatten().collect(),
        sprts: f.sprt_views.into_iter().flatten().collect(),
    })
}

impl Follower {
    /// One bar for the plain matches (if any), then one per tournament, then one per SPRT.
    fn new(submitted: &Submitted, bars: &MultiProgress) -> Follower {
        let style = ProgressStyle::with_template("{prefix:<34} {bar:30} {pos}/{len} matches {msg}")
            .expect("valid template");
        let bar = |len: usize, prefix: String| {
            let b = bars.add(ProgressBar::new(len as u64));
            b.set_style(style.clone());
            b.set_prefix(prefix);
            b
        };
        let plain = &submitted.matches;
        let plain_bar = (!plain.is_empty()).then(|| bar(plain.len(), "matches".into()));
        let t_bars: Vec<ProgressBar> = submitted
            .tournaments
            .iter()
            .map(|c| bar(c.len, format!("tournament {}: {}", c.id, c.label)))
            .collect();
        let s_bars: Vec<ProgressBar> = submitted
            .sprts
            .iter()
            .map(|c| bar(c.len, format!("sprt {}: {}", c.id, c.label)))
            .collect();
        Follower {
            plain_bar,
            t_bars,
            s_bars,
            rows: HashMap::new(),
            views: vec![None; submitted.tournaments.len()],
            sprt_views: vec![None; submitted.sprts.len()],
        }
    }

    /// Polls the plain matches not yet finished; true when all have.
    fn poll_matches(&mut self, client: &Client, plain: &[i64]) -> Result<bool, CliError> {
        for &id in plain {
            if self.rows.get(&id).is_some_and(|m| finished(m.status)) {
                continue;
            }
            let m: wire::MatchDetail = client.call("GET", &format!("/matches/{id}"), None)?;
            self.rows.insert(id, m.row);
        }
        let rows = &self.rows;
        let plain_done = plain
            .iter()
            .filter(|id| rows.get(id).is_some_and(|m| finished(m.status)))
            .count();
        if let Some(b) = &self.plain_bar {
            b.set_position(plain_done as u64);
            let running = plain
                .iter()
                .filter(|id| {
                    rows.get(id)
                        .is_some_and(|m| m.status == wire::MatchStatus::Running)
                })
                .count();
            b.set_message(format!("({running} running)"));
        }
        Ok(plain_done == plain.len())
    }

    /// Polls the tournaments not yet finished; true when all have.
    fn poll_tournaments(
        &mut self,
        client: &Client,
        tournaments: &[Contest],
    ) -> Result<bool, CliError> {
        let mut all_done = true;
        for (k, c) in tournaments.iter().enumerate() {
            if self.views[k]
                .as_ref()
                .is_some_and(|v| v.summary.progress.state == ProgressState::Finished)
            {
                continue;
            }
            let v: wire::TournamentView =
                client.call("GET", &format!("/tournaments/{}", c.id), None)?;
            let p = &v.summary.progress;
            self.t_bars[k].set_position((p.done + p.failed + p.cancelled) as u64);
            self.t_bars[k].set_message(format!("({} running)", p.running));
            all_done &= p.state == ProgressState::Finished;
            self.views[k] = Some(v);
        }
        Ok(all_done)
    }

    /// Polls the SPRTs still running; true when none is.
    fn poll_sprts(&mut self, client: &Client, sprts: &[Contest]) -> Result<bool, CliError> {
        let mut all_done = true;
        for (k, c) in sprts.iter().enumerate() {
            if self.sprt_views[k]
                .as_ref()
                .is_some_and(|v| v.row.status != wire::SprtStatus::Running)
            {
                continue;
            }
            let v: wire::SprtView = client.call("GET", &format!("/sprt/{}", c.id), None)?;
            self.s_bars[k].set_position(v.row.matches_done.max(0) as u64);
            self.s_bars[k].set_message(format!(
                "LLR {:+.2} in [{:.2}, {:.2}]",
                v.row.llr, v.bounds.lower, v.bounds.upper
            ));
            all_done &= v.row.status != wire::SprtStatus::Running;
            self.sprt_views[k] = Some(v);
        }
        Ok(all_done)
    }
}
