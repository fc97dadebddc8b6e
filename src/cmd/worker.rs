//! `rally worker`: a match-playing process without the HTTP server, for tournaments larger than one
//! machine's workers (docs/design.md §12; the loop is `server::scheduler`'s).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;

use super::CliError;

/// Arguments of `rally worker`.
#[derive(Args, Debug)]
#[command(
    after_help = "The worker loop (fishtest's): ask the database for the oldest queued match, play it, report\n\
                  its result in one transaction, repeat. A claimed match holds a lease that the worker's\n\
                  heartbeat renews every quarter of lease_s; a worker killed with -9 (or cut off from the\n\
                  database) loses its matches when their leases run out, they are queued again, and a result\n\
                  it reports after that is refused: no match is lost or stored twice. SIGTERM or Ctrl-C\n\
                  finishes and stores the matches being played, then exits.\n\n\
                  The database is the server's (every process on one SQLite file must run on one machine).\n\
                  Settings come from the config file as for `rally serve` (lease_s among them); --db,\n\
                  --workers and --name override it. The first stdout line is `worker NAME ready`.\n\n\
                  Example (an API server and two workers on one machine):\n  \
                  rally serve --workers 0 --db data/rally.db &\n  \
                  rally worker --db data/rally.db --workers 1 --name w1 &\n  \
                  rally worker --db data/rally.db --workers 1 --name w2 &"
)]
pub struct WorkerArgs {
    /// Settings file (TOML), as for `rally serve`.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// The server's store: its SQLite file, or its postgres://USER:PASS@HOST:PORT/DB URL.
    #[arg(long, value_name = "FILE|URL")]
    db: Option<server::db::Location>,
    /// Matches this process plays at once.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=64))]
    workers: u16,
    /// Its name in the workers list and on the matches it plays (default: HOST:PID); two live
    /// processes may not share one.
    #[arg(long)]
    name: Option<String>,
}

/// Runs `rally worker`.
pub fn run(args: &WorkerArgs) -> Result<(), CliError> {
    let mut settings = super::serve::load_settings(args.config.as_deref())?;
    if let Some(d) = &args.db {
        settings.db = d.clone();
    }
    if let server::db::Location::Sqlite(path) = &settings.db {
        if !path.exists() {
            return Err(CliError::Usage(format!(
                "{}: no such database (start `rally serve --db {}` first: it creates and migrates it)",
                path.display(),
                path.display()
            )));
        }
    }
    settings.workers = args.workers as usize;
    settings.continuous = false;
    if let Some(n) = &args.name {
        if n.trim().is_empty() || n.len() > 100 {
            return Err(CliError::Usage("--name must be 1 to 100 characters".into()));
        }
        settings.worker_name = n.clone();
    }
    super::serve::init_logging();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let db = settings.db.clone();
    runtime.block_on(server::work(settings, |name| {
        println!("worker {name} ready");
        eprintln!("rally worker {name}: playing queued matches from {}", db);
    }))?;
    Ok(())
}
