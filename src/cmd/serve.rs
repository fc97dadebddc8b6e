//! `rally serve`: the tournament server (REST API, scheduler, leaderboard page) on SQLite.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;

use super::CliError;

/// Arguments of `rally serve`.
#[derive(Args, Debug)]
#[command(
    after_help = "Settings are config/default.toml's (built into the binary: the same from any directory) with\n\
                  what a --config file changes laid over them (it names only those). --addr, --db, --workers and\n\
                  --no-continuous override them, and RALLY_ADMIN_TOKEN the admin_token. The store is DATA/rally.db\n\
                  unless --db or the file names another (DATA: $RALLY_DATA_DIR, else the platform's data directory,\n\
                  on Linux ~/.local/share/muscle-rally). Logs go to stderr (RUST_LOG=debug for more).\n\n\
                  On first start the built-in agents (scripted and trained) are registered and, unless continuous\n\
                  mode is off, matches between them start at once: open the printed address to watch the\n\
                  leaderboard fill.\n\n\
                  Example:\n  RALLY_ADMIN_TOKEN=secret rally serve --addr 127.0.0.1:8080 --db data/rally.db\n  \
                  rally serve --db postgres://rally:secret@db.lab:5432/rally --workers 0"
)]
pub struct ServeArgs {
    /// Settings file (TOML).
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Listen address (port 0 picks a free port).
    #[arg(long)]
    addr: Option<SocketAddr>,
    /// The store: an SQLite file (created with its directory if missing; the default) or a
    /// PostgreSQL 15 database, postgres://USER:PASS@HOST:PORT/DB (it must exist; the migrations are
    /// applied at start).
    #[arg(long, value_name = "FILE|URL")]
    db: Option<server::db::Location>,
    /// Match workers in this process (0: serve the API alone; `rally worker` processes play).
    #[arg(long, value_parser = clap::value_parser!(u16).range(0..=64))]
    workers: Option<u16>,
    /// Play only requested matches (no continuous matches for the agents whose ratings are least
    /// certain).
    #[arg(long)]
    no_continuous: bool,
}

/// The settings: config/default.toml's values (compiled into the binary, so the same from any
/// directory) with what the file `config` names laid over them; errors name the file and the field.
pub fn load_settings(config: Option<&Path>) -> Result<server::Settings, CliError> {
    let (text, name) = match config {
        Some(p) => (
            std::fs::read_to_string(p)
                .map_err(|e| CliError::Usage(format!("cannot read {}: {e}", p.display())))?,
            p.display().to_string(),
        ),
        None => (String::new(), "config/default.toml".to_string()),
    };
    server::Settings::from_toml(&text).map_err(|e| CliError::Usage(format!("{name}: {e}")))
}

/// Logs to stderr (RUST_LOG overrides the default filter).
pub fn init_logging() {
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "info,sqlx=warn,tower_http=warn".into()),
        )
        .init();
}

/// Runs `rally serve`.
pub fn run(args: &ServeArgs) -> Result<(), CliError> {
    let mut settings = load_settings(args.config.as_deref())?;
    if let Some(a) = args.addr {
        settings.addr = a;
    }
    if let Some(d) = &args.db {
        settings.db = d.clone();
    }
    if let Some(w) = args.workers {
        settings.workers = w as usize;
    }
    if args.no_continuous {
        settings.continuous = false;
    }
    if let Ok(t) = std::env::var("RALLY_ADMIN_TOKEN") {
        settings.admin_token = t;
    }
    init_logging();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    let db = settings.db.clone();
    let submissions = !settings.admin_token.is_empty();
    runtime.block_on(server::serve(settings, |addr| {
        // The first stdout line is the address (scripts and tests read it).
        println!("listening on http://{addr}");
        eprintln!(
            "rally serve: database {}, leaderboard at http://{addr}/, API at http://{addr}/api/v1{}",
            db,
            if submissions { "" } else { " (submissions off: set RALLY_ADMIN_TOKEN)" }
        );
    }))?;
    Ok(())
}
