//! `rally batch PLAN.toml --server URL --token T`: submits the matches, tournaments and SPRTs of a plan to a
//! running server, follows them with progress bars, prints a summary table and writes every match
//! to CSV. Everything in the plan is checked (agent names resolved on the server) before the first
//! submission, so a bad plan submits nothing.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context};
use clap::Args;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::{json, Value};
use server::tournament::ProgressState;
use server::{db, wire};

use super::CliError;

mod plan;
mod report;
use plan::{jobs, Job};
use report::*;

/// Arguments of `rally batch`.
#[derive(Args, Debug)]
#[command(
    after_help = "PLAN.toml lists [[match]], [[tournament]] and [[sprt]] entries; agents are names or ids:\n\n\
  rallies = 20                # default rallies per match\n\
  seed = 1                    # first seed: entry k without a seed gets seed + k\n\n\
  [[match]]\n\
  a = \"scripted\"\n\
  b = \"scripted-drive\"\n\
  repeat = 2                  # optional: sides swap on odd repeats, seeds go up by one\n\n\
  [[tournament]]\n\
  kind = \"round_robin\"        # or \"gauntlet\": the first agent against each other one\n\
  agents = [\"scripted\", \"scripted-drive\", \"scripted-soft\"]\n\
  rallies_per_match = 10\n\
  rounds = 2\n\n\
  [[sprt]]                    # plays until the test decides; fields as POST /sprt\n\
  a = \"scripted-drive\"\n\
  b = \"scripted\"\n\
  elo0 = 0\n\
  elo1 = 50\n\n\
The token may also come from RALLY_TOKEN. Exit status: 0 when every match finished, 1 when one\n\
failed or was cancelled or the server refused a submission, 2 for a bad plan or arguments.\n\
See examples/batch_plan.toml."
)]
pub struct BatchArgs {
    /// The plan (TOML).
    plan: PathBuf,
    /// The server's base URL.
    #[arg(long, default_value = "http://127.0.0.1:8080")]
    server: String,
    /// Bearer token (admin or submitter); default: the RALLY_TOKEN environment variable.
    #[arg(long, env = "RALLY_TOKEN", hide_env_values = true)]
    token: Option<String>,
    /// Where to write one CSV row per match (default: the plan's path with .csv).
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Submit and print the ids, without following the matches.
    #[arg(long)]
    no_wait: bool,
    /// Seconds between two polls of the server.
    #[arg(long, default_value_t = 1.0, value_parser = super::parse_seconds)]
    poll: f64,
    /// Give up following after this many seconds (the matches go on on the server).
    #[arg(long, default_value_t = 3600.0, value_parser = parse_timeout)]
    timeout: f64,
}

fn parse_timeout(s: &str) -> Result<f64, String> {
    let x: f64 = s.parse().map_err(|_| format!("'{s}' is not a number"))?;
    if !(x.is_finite() && x > 0.0) {
        return Err("must be a positive number of seconds".into());
    }
    Ok(x)
}

/// The HTTP side: JSON requests with the bearer token, 4xx/5xx turned into the server's message.
struct Client {
    base: String,
    token: String,
    http: ureq::Agent,
}

/// A refused request: status and the server's `error.message` (and field).
#[derive(Debug)]
struct Refused {
    status: u16,
    message: String,
    retry_after: Option<u64>,
}

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "HTTP {}: {}", self.status, self.message)
    }
}

impl std::error::Error for Refused {}

impl Client {
    fn new(base: &str, token: String) -> Client {
        let http: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(Duration::from_secs(300)))
            .build()
            .into();
        Client {
            base: base.trim_end_matches('/').to_string(),
            token,
            http,
        }
    }

    /// One request; Ok(body) on 2xx, Err(Refused) on a refusal (the server's `wire::ErrorBody`),
    /// Err(other) when the server could not be reached or answered something that is not the
    /// expected body.
    fn call<T: DeserializeOwned>(
        &self,
        method: &str,
        path: &str,
        body: Option<&Value>,
    ) -> anyhow::Result<T> {
        let url = format!("{}/api/v1{path}", self.base);
        let auth = format!("Bearer {}", self.token);
        let resp = match (method, body) {
            ("GET", _) => self.http.get(&url).header("Authorization", &auth).call(),
            ("POST", Some(b)) => self
                .http
                .post(&url)
                .header("Authorization", &auth)
                .send_json(b),
            ("DELETE", _) => self.http.delete(&url).header("Authorization", &auth).call(),
            _ => return Err(anyhow!("unsupported request {method} {path}")),
        };
        let mut resp = resp.map_err(|e| anyhow!("could not reach the server at {url}: {e}"))?;
        let status = resp.status().as_u16();
        let retry_after = resp
            .headers()
            .get("retry-after")
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.trim().parse().ok());
        let v: Value = resp
            .body_mut()
            .read_json()
            .map_err(|e| anyhow!("{method} {url}: HTTP {status}, the answer is not JSON: {e}"))?;
        if (200..300).contains(&status) {
            return serde_json::from_value(v)
                .map_err(|e| anyhow!("{method} {url}: an unexpected answer: {e}"));
        }
        let message = match serde_json::from_value::<wire::ErrorBody>(v.clone()) {
            Ok(wire::ErrorBody { error }) => match error.field {
                Some(field) => format!("{} (field '{field}')", error.message),
                None => error.message,
            },
            Err(_) => v.to_string(),
        };
        Err(Refused {
            status,
            message,
            retry_after,
        }
        .into())
    }

    /// A POST of `body` that waits out rate limits (429 + Retry-After), telling `say` why it waits.
    fn post_patiently<B: Serialize, T: DeserializeOwned>(
        &self,
        path: &str,
        body: &B,
        say: &dyn Fn(String),
    ) -> anyhow::Result<T> {
        let body = serde_json::to_value(body)?;
        let mut waited = 0u64;
        loop {
            match self.call("POST", path, Some(&body)) {
                Err(e) => match e.downcast_ref::<Refused>() {
                    Some(r) if r.status == 429 && waited < 600 => {
                        let secs = r.retry_after.unwrap_or(5).clamp(1, 60);
                        say(format!("rate limited; waiting {secs} s ({})", r.message));
                        std::thread::sleep(Duration::from_secs(secs));
                        waited += secs;
                    }
                    _ => return Err(e),
                },
                ok => return ok,
            }
        }
    }
}

/// Runs `rally batch`.
pub fn run(args: &BatchArgs) -> Result<(), CliError> {
    let text = std::fs::read_to_string(&args.plan).map_err(|e| {
        CliError::Usage(format!("cannot read the plan {}: {e}", args.plan.display()))
    })?;
    let plan =
        plan::parse(&text).map_err(|e| CliError::Usage(format!("{}: {e}", args.plan.display())))?;
    let token = args.token.clone().ok_or_else(|| {
        CliError::Usage(
            "no token: pass --token or set RALLY_TOKEN (a submitter or admin token)".into(),
        )
    })?;
    if !(args.server.starts_with("http://") || args.server.starts_with("https://")) {
        return Err(CliError::Usage(format!(
            "--server must be an http:// URL, not '{}'",
            args.server
        )));
    }
    if args.server.starts_with("https://") {
        return Err(CliError::Usage(
            "https is not built into this client: reach the server over http (e.g. an SSH tunnel)"
                .into(),
        ));
    }
    let client = Client::new(&args.server, token);
    let health: wire::Health = client.call("GET", "/healthz", None)?;
    let listed: wire::AgentList = client.call("GET", "/agents", None)?;
    let mut by_name = HashMap::new();
    let mut names = HashMap::new();
    for a in listed.agents {
        by_name.insert(a.name.clone(), a.id);
        names.insert(a.id, a.name);
    }
    let ids: Vec<i64> = names.keys().copied().collect();
    let jobs = jobs(&plan, &by_name, &ids)
        .map_err(|e| CliError::Usage(format!("{}: {e}", args.plan.display())))?;
    eprintln!(
        "server {} (simulator {}), {} agents; submitting {} entries",
        args.server,
        health.sim_version,
        names.len(),
        jobs.len()
    );

    // Submit everything, remembering what went in so a refusal can say what to cancel.
    let bars = MultiProgress::new();
    let say = |m: String| {
        let _ = bars.println(m);
    };
    let mut plain: Vec<i64> = Vec::new();
    let mut tournaments: Vec<(i64, String, usize)> = Vec::new();
    let mut sprts: Vec<(i64, String, usize)> = Vec::new();
    for job in &jobs {
        let submitted = match job {
            Job::Match {
                a,
                b,
                rallies,
                seed,
            } => {
                let q = wire::QueueMatch {
                    a: (*a).into(),
                    b: (*b).into(),
                    rallies: *rallies,
                    seed: Some(*seed),
                };
                client
                    .post_patiently::<_, db::Match>("/matches", &q, &say)
                    .map(|m| plain.push(m.id))
            }
            Job::Tournament {
                kind,
                agents,
                rallies_per_match,
                rounds,
                seed,
                label,
            } => {
                let q = wire::NewTournament {
                    kind: *kind,
                    agents: agents.iter().map(|&id| id.into()).collect(),
                    rallies_per_match: *rallies_per_match,
                    rounds: *rounds,
                    seed: Some(*seed),
                };
                client
                    .post_patiently::<_, wire::TournamentView>("/tournaments", &q, &say)
                    .map(|t| {
                        let s = t.summary;
                        tournaments.push((s.id, label.clone(), s.progress.total));
                    })
            }
            Job::Sprt {
                a,
                b,
                elo0,
                elo1,
                alpha,
                beta,
                rallies_per_match,
                max_matches,
                seed,
                label,
            } => {
                let d = wire::NewSprt::new((*a).into(), (*b).into());
                let q = wire::NewSprt {
                    elo0: elo0.unwrap_or(d.elo0),
                    elo1: elo1.unwrap_or(d.elo1),
                    alpha: alpha.unwrap_or(d.alpha),
                    beta: beta.unwrap_or(d.beta),
                    rallies_per_match: *rallies_per_match,
                    max_matches: max_matches.unwrap_or(d.max_matches),
                    seed: Some(*seed),
                    ..d
                };
                client
                    .post_patiently::<_, wire::SprtView>("/sprt", &q, &say)
                    .map(|t| {
                        sprts.push((t.row.id, label.clone(), t.row.max_matches.max(0) as usize))
                    })
            }
        };
        if let Err(e) = submitted {
            let done = if plain.is_empty() && tournaments.is_empty() && sprts.is_empty() {
                "nothing was submitted".to_string()
            } else {
                format!(
                    "already submitted: matches {:?}, tournaments {:?}, SPRTs {:?} (DELETE them to cancel)",
                    plain,
                    tournaments.iter().map(|t| t.0).collect::<Vec<_>>(),
                    sprts.iter().map(|t| t.0).collect::<Vec<_>>()
                )
            };
            return Err(CliError::Failed(
                e.context(format!("a submission was refused; {done}")),
            ));
        }
    }
    let ids = |v: &[(i64, String, usize)]| {
        v.iter()
            .map(|t| t.0.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    eprintln!(
        "submitted {} matches{}{}",
        plain.len(),
        if tournaments.is_empty() {
            String::new()
        } else {
            format!(", tournaments {}", ids(&tournaments))
        },
        if sprts.is_empty() {
            String::new()
        } else {
            format!(", SPRTs {}", ids(&sprts))
        }
    );
    if args.no_wait {
        println!(
            "{}",
            json!({"matches": plain, "tournaments": tournaments.iter().map(|t| t.0).collect::<Vec<_>>(),
                   "sprts": sprts.iter().map(|t| t.0).collect::<Vec<_>>()})
        );
        return Ok(());
    }

    // Follow: one bar for the plain matches, one per tournament.
    let style = ProgressStyle::with_template("{prefix:<34} {bar:30} {pos}/{len} matches {msg}")
        .expect("valid template");
    let bar = |len: usize, prefix: String| {
        let b = bars.add(ProgressBar::new(len as u64));
        b.set_style(style.clone());
        b.set_prefix(prefix);
        b
    };
    let plain_bar = (!plain.is_empty()).then(|| bar(plain.len(), "matches".into()));
    let t_bars: Vec<ProgressBar> = tournaments
        .iter()
        .map(|(id, label, total)| bar(*total, format!("tournament {id}: {label}")))
        .collect();
    let finished = |s: db::MatchStatus| {
        matches!(
            s,
            db::MatchStatus::Done | db::MatchStatus::Failed | db::MatchStatus::Cancelled
        )
    };
    let started = Instant::now();
    let mut rows: HashMap<i64, db::Match> = HashMap::new();
    let mut views: Vec<Option<wire::TournamentView>> = vec![None; tournaments.len()];
    let s_bars: Vec<ProgressBar> = sprts
        .iter()
        .map(|(id, label, most)| bar(*most, format!("sprt {id}: {label}")))
        .collect();
    let mut sprt_views: Vec<Option<wire::SprtView>> = vec![None; sprts.len()];
    let sprt_running = |v: &Option<wire::SprtView>| {
        v.as_ref()
            .is_none_or(|v| v.row.status == db::SprtStatus::Running)
    };
    loop {
        for &id in &plain {
            if rows.get(&id).is_some_and(|m| finished(m.status)) {
                continue;
            }
            let m: wire::MatchDetail = client.call("GET", &format!("/matches/{id}"), None)?;
            rows.insert(id, m.row);
        }
        let plain_done = plain
            .iter()
            .filter(|id| rows.get(id).is_some_and(|m| finished(m.status)))
            .count();
        if let Some(b) = &plain_bar {
            b.set_position(plain_done as u64);
            let running = plain
                .iter()
                .filter(|id| {
                    rows.get(id)
                        .is_some_and(|m| m.status == db::MatchStatus::Running)
                })
                .count();
            b.set_message(format!("({running} running)"));
        }
        let mut all_done = plain_done == plain.len();
        for (k, (id, _, _)) in tournaments.iter().enumerate() {
            if views[k]
                .as_ref()
                .is_some_and(|v| v.summary.progress.state == ProgressState::Finished)
            {
                continue;
            }
            let v: wire::TournamentView =
                client.call("GET", &format!("/tournaments/{id}"), None)?;
            let p = &v.summary.progress;
            t_bars[k].set_position((p.done + p.failed + p.cancelled) as u64);
            t_bars[k].set_message(format!("({} running)", p.running));
            all_done &= p.state == ProgressState::Finished;
            views[k] = Some(v);
        }
        for (k, (id, _, _)) in sprts.iter().enumerate() {
            if !sprt_running(&sprt_views[k]) {
                continue;
            }
            let v: wire::SprtView = client.call("GET", &format!("/sprt/{id}"), None)?;
            s_bars[k].set_position(v.row.matches_done.max(0) as u64);
            s_bars[k].set_message(format!(
                "LLR {:+.2} in [{:.2}, {:.2}]",
                v.row.llr, v.bounds.lower, v.bounds.upper
            ));
            all_done &= v.row.status != db::SprtStatus::Running;
            sprt_views[k] = Some(v);
        }
        if all_done {
            break;
        }
        if started.elapsed().as_secs_f64() > args.timeout {
            bars.clear().ok();
            return Err(CliError::Failed(anyhow!(
                "gave up following after {} s; the matches go on on the server",
                args.timeout
            )));
        }
        std::thread::sleep(Duration::from_secs_f64(args.poll));
    }
    for b in t_bars.iter().chain(s_bars.iter()).chain(plain_bar.iter()) {
        b.finish();
    }
    let views: Vec<wire::TournamentView> = views.into_iter().flatten().collect();
    let sprt_views: Vec<wire::SprtView> = sprt_views.into_iter().flatten().collect();
    // Full rows of the tournaments' and SPRTs' matches, for the CSV and the summary.
    let contest_ids: Vec<i64> = views
        .iter()
        .flat_map(|v| v.matches.iter().map(|m| m.id))
        .chain(
            sprt_views
                .iter()
                .flat_map(|v| v.matches.iter().map(|m| m.m.id)),
        )
        .collect();
    for &id in &contest_ids {
        let full: wire::MatchDetail = client.call("GET", &format!("/matches/{id}"), None)?;
        rows.insert(id, full.row);
    }
    let mut order: Vec<i64> = plain.clone();
    order.extend(&contest_ids);
    let csv_path = args
        .csv
        .clone()
        .unwrap_or_else(|| args.plan.with_extension("csv"));
    write_csv(&csv_path, &order, &rows, &names)
        .with_context(|| format!("writing {}", csv_path.display()))?;
    print_summary(&order, &rows, &names);
    for (v, (id, label, _)) in views.iter().zip(&tournaments) {
        print_standings(*id, label, v);
    }
    for (v, (id, label, _)) in sprt_views.iter().zip(&sprts) {
        println!();
        println!(
            "sprt {id}: {label}, H0 {} / H1 {} Elo: {} after {} matches, LLR {:+.3} in [{:.3}, {:.3}], Elo estimate {}",
            v.row.elo0,
            v.row.elo1,
            v.row.status,
            v.row.matches_done,
            v.row.llr,
            v.bounds.lower,
            v.bounds.upper,
            v.elo_estimate.map_or("–".into(), |e| format!("{e:+.1}"))
        );
    }
    println!("wrote {} ({} matches)", csv_path.display(), order.len());
    let broken: Vec<String> = sprt_views
        .iter()
        .filter(|v| {
            matches!(
                v.row.status,
                db::SprtStatus::Failed | db::SprtStatus::Cancelled
            )
        })
        .map(|v| format!("SPRT {} {}", v.row.id, v.row.status))
        .collect();
    if !broken.is_empty() {
        return Err(CliError::Failed(anyhow!("{}", broken.join(", "))));
    }
    let bad: Vec<String> = order
        .iter()
        .filter_map(|id| {
            let s = rows.get(id)?.status;
            (s != db::MatchStatus::Done).then(|| format!("{id} {s}"))
        })
        .collect();
    if !bad.is_empty() {
        return Err(CliError::Failed(anyhow!(
            "{} of {} matches did not finish: {}",
            bad.len(),
            order.len(),
            bad.join(", ")
        )));
    }
    Ok(())
}
