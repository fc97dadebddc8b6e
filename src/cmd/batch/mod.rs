//! `rally batch PLAN.toml --server URL --token T`: submits the matches, tournaments and SPRTs of a plan to a
//! running server, follows them with progress bars, prints a summary table and writes every match
//! to CSV. Everything in the plan is checked (agent names resolved on the server) before the first
//! submission, so a bad plan submits nothing.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context};
use clap::Args;
use indicatif::MultiProgress;
use serde_json::{json, Value};

use super::CliError;

mod client;
mod follow;
mod plan;
mod report;
use client::Client;
use follow::{follow, Followed};
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

/// Runs `rally batch`.
pub fn run(args: &BatchArgs) -> Result<(), CliError> {
    let plan = read_plan(&args.plan)?;
    let client = connect(args)?;
    let (jobs, names) = resolve(&client, args, &plan)?;
    let bars = MultiProgress::new();
    let submitted = submit(&client, &jobs, &bars)?;
    submitted.announce();
    if args.no_wait {
        println!("{}", submitted.ids_json());
        return Ok(());
    }
    let mut followed = follow(&client, &submitted, &bars, args.poll, args.timeout)?;
    let order = fetch_contest_rows(&client, &submitted, &mut followed)?;
    let csv_path = args
        .csv
        .clone()
        .unwrap_or_else(|| args.plan.with_extension("csv"));
    write_csv(&csv_path, &order, &followed.rows, &names)
        .with_context(|| format!("writing {}", csv_path.display()))?;
    print_summary(&order, &followed.rows, &names);
    for (v, c) in followed.tournaments.iter().zip(&submitted.tournaments) {
        print_standings(c.id, &c.label, v);
    }
    for (v, c) in followed.sprts.iter().zip(&submitted.sprts) {
        print_sprt(c.id, &c.label, v);
    }
    println!("wrote {} ({} matches)", csv_path.display(), order.len());
    unfinished(&order, &followed)
}

/// The plan's text, parsed (its errors are the user's: exit 2).
fn read_plan(path: &Path) -> Result<plan::Plan, CliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| CliError::Usage(format!("cannot read the plan {}: {e}", path.display())))?;
    plan::parse(&text).map_err(|e| CliError::Usage(format!("{}: {e}", path.display())))
}

/// A client of `--server` with the token; refuses a missing token and a URL that is not http://.
fn connect(args: &BatchArgs) -> Result<Client, CliError> {
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
    Ok(Client::new(&args.server, token))
}

/// The plan's jobs, its agent names resolved on the server, and the server's agents by id.
fn resolve(
    client: &Client,
    args: &BatchArgs,
    plan: &plan::Plan,
) -> Result<(Vec<Job>, HashMap<i64, String>), CliError> {
    let health: wire::Health = client.call("GET", "/healthz", None)?;
    let robot = plan.model();
    if !health.models.is_empty() && !health.models.iter().any(|m| m == robot) {
        return Err(CliError::Usage(format!(
            "{}: the server plays no robot '{robot}' (model); it plays: {}",
            args.plan.display(),
            health.models.join(", ")
        )));
    }
    let listed: wire::AgentList = client.call("GET", "/agents", None)?;
    let mut roster = plan::Roster::default();
    let mut names = HashMap::new();
    for a in listed.agents {
        if a.model == robot {
            roster.names.insert(a.name.clone(), a.id);
            roster.ids.push(a.id);
            names.insert(a.id, a.name);
        } else {
            roster.others.push((a.id, a.name, a.model));
        }
    }
    let jobs = jobs(plan, &roster)
        .map_err(|e| CliError::Usage(format!("{}: {e}", args.plan.display())))?;
    eprintln!(
        "server {} (simulator {}), {} agents; submitting {} entries",
        args.server,
        health.sim_version,
        names.len(),
        jobs.len()
    );
    Ok((jobs, names))
}

/// A tournament or SPRT submitted: its id, the plan's label, and its bar's length (a tournament's
/// matches, an SPRT's most).
struct Contest {
    id: i64,
    label: String,
    len: usize,
}

/// What went in so far, so that a refusal can say what to cancel.
#[derive(Default)]
struct Submitted {
    matches: Vec<i64>,
    tournaments: Vec<Contest>,
    sprts: Vec<Contest>,
}

fn contest_ids(v: &[Contest]) -> Vec<i64> {
    v.iter().map(|c| c.id).collect()
}

impl Submitted {
    fn is_empty(&self) -> bool {
        self.matches.is_empty() && self.tournaments.is_empty() && self.sprts.is_empty()
    }

    /// Says on stderr what was submitted.
    fn announce(&self) {
        let ids = |v: &[Contest]| {
            v.iter()
                .map(|c| c.id.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        };
        eprintln!(
            "submitted {} matches{}{}",
            self.matches.len(),
            if self.tournaments.is_empty() {
                String::new()
            } else {
                format!(", tournaments {}", ids(&self.tournaments))
            },
            if self.sprts.is_empty() {
                String::new()
            } else {
                format!(", SPRTs {}", ids(&self.sprts))
            }
        );
    }

    /// The ids, as `--no-wait` prints them.
    fn ids_json(&self) -> Value {
        json!({"matches": self.matches, "tournaments": contest_ids(&self.tournaments),
               "sprts": contest_ids(&self.sprts)})
    }
}

/// Submits every job in order; a refusal stops there, naming what was already submitted.
fn submit(client: &Client, jobs: &[Job], bars: &MultiProgress) -> Result<Submitted, CliError> {
    let say = |m: String| {
        let _ = bars.println(m);
    };
    let mut submitted = Submitted::default();
    for job in jobs {
        if let Err(e) = submit_one(client, job, &say, &mut submitted) {
            let done = if submitted.is_empty() {
                "nothing was submitted".to_string()
            } else {
                format!(
                    "already submitted: matches {:?}, tournaments {:?}, SPRTs {:?} (DELETE them to cancel)",
                    submitted.matches,
                    contest_ids(&submitted.tournaments),
                    contest_ids(&submitted.sprts)
                )
            };
            return Err(CliError::Failed(
                e.context(format!("a submission was refused; {done}")),
            ));
        }
    }
    Ok(submitted)
}

/// Submits one job as the server's request and records it in `submitted`.
fn submit_one(
    client: &Client,
    job: &Job,
    say: &dyn Fn(String),
    submitted: &mut Submitted,
) -> anyhow::Result<()> {
    match job {
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
            let m: wire::Match = client.post_patiently("/matches", &q, say)?;
            submitted.matches.push(m.id);
        }
        Job::Tournament {
            kind,
            agents,
            rallies_per_match,
            rounds,
            seed,
            label,
        } => {
            let kind = kind
                .parse::<wire::TournamentKind>()
                .map_err(|e| anyhow::anyhow!("{label}: {e}"))?;
            let q = wire::NewTournament {
                kind,
                agents: agents.iter().map(|&id| id.into()).collect(),
                rallies_per_match: *rallies_per_match,
                rounds: *rounds,
                seed: Some(*seed),
            };
            let t: wire::TournamentView = client.post_patiently("/tournaments", &q, say)?;
            let s = t.summary;
            submitted.tournaments.push(Contest {
                id: s.id,
                label: label.clone(),
                len: s.progress.total,
            });
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
            let t: wire::SprtView = client.post_patiently("/sprt", &q, say)?;
            submitted.sprts.push(Contest {
                id: t.row.id,
                label: label.clone(),
                len: t.row.max_matches.max(0) as usize,
            });
        }
    }
    Ok(())
}

/// Full rows of the tournaments' and SPRTs' matches, for the CSV and the summary. Returns every
/// match of the batch: the plain ones, then the contests'.
fn fetch_contest_rows(
    client: &Client,
    submitted: &Submitted,
    followed: &mut Followed,
) -> Result<Vec<i64>, CliError> {
    let contest_ids: Vec<i64> = followed
        .tournaments
        .iter()
        .flat_map(|v| v.matches.iter().map(|m| m.id))
        .chain(
            followed
                .sprts
                .iter()
                .flat_map(|v| v.matches.iter().map(|m| m.m.id)),
        )
        .collect();
    for &id in &contest_ids {
        let full: wire::MatchDetail = client.call("GET", &format!("/matches/{id}"), None)?;
        followed.rows.insert(id, full.row);
    }
    let mut order: Vec<i64> = submitted.matches.clone();
    order.extend(&contest_ids);
    Ok(order)
}

/// The batch's failures, if any: an SPRT that failed or was cancelled, else the matches of `order`
/// that did not finish.
fn unfinished(order: &[i64], followed: &Followed) -> Result<(), CliError> {
    let broken: Vec<String> = followed
        .sprts
        .iter()
        .filter(|v| {
            matches!(
                v.row.status,
                wire::SprtStatus::Failed | wire::SprtStatus::Cancelled
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
            let s = followed.rows.get(id)?.status;
            (s != wire::MatchStatus::Done).then(|| format!("{id} {s}"))
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
