//! The subcommands of `rally`, and what they share: argument parsers and the error type that picks
//! the exit code (2 for bad arguments, 1 for anything that failed while running).

pub mod ball;
pub mod batch;
pub mod bench;
pub mod checkpoint;
pub mod eval;
pub mod matchcmd;
pub mod model;
pub mod plan;
pub mod plot;
pub mod reproduce;
pub mod serve;
pub mod train;
pub mod worker;

use nalgebra::Vector3;

/// Why a command stopped.
#[derive(Debug)]
pub enum CliError {
    /// The arguments were wrong: exit 2 with this message.
    Usage(String),
    /// Something failed while running: exit 1.
    Failed(anyhow::Error),
}

impl From<anyhow::Error> for CliError {
    fn from(e: anyhow::Error) -> Self {
        CliError::Failed(e)
    }
}

impl From<std::io::Error> for CliError {
    fn from(e: std::io::Error) -> Self {
        CliError::Failed(e.into())
    }
}

/// Parses "X,Y,Z" into a vector of three finite numbers (clap value parser).
pub fn parse_vec3(s: &str) -> Result<Vector3<f64>, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return Err(format!(
            "expected 3 comma-separated numbers, got {}",
            parts.len()
        ));
    }
    let mut v = [0.0; 3];
    for (i, p) in parts.iter().enumerate() {
        let x: f64 = p.parse().map_err(|_| format!("'{p}' is not a number"))?;
        if !x.is_finite() {
            return Err(format!("'{p}' is not a finite number"));
        }
        v[i] = x;
    }
    Ok(Vector3::from(v))
}

/// Parses a positive, finite number of seconds no larger than an hour (clap value parser).
pub fn parse_seconds(s: &str) -> Result<f64, String> {
    let x: f64 = s
        .trim()
        .parse()
        .map_err(|_| format!("'{s}' is not a number"))?;
    if !x.is_finite() || x <= 0.0 {
        return Err("must be a positive number of seconds".into());
    }
    if x > 3600.0 {
        return Err("must be at most 3600 seconds".into());
    }
    Ok(x)
}

/// Parses a preset name (clap value parser).
pub fn parse_preset(s: &str) -> Result<sim::Preset, String> {
    sim::Preset::by_name(s).ok_or_else(|| {
        format!(
            "unknown preset; expected one of: {}",
            sim::Preset::names().join(", ")
        )
    })
}

/// The default robot model compiled into the simulator.
pub fn default_model() -> Result<std::sync::Arc<sim::model::Model>, CliError> {
    Ok(std::sync::Arc::new(sim::config::default_model()))
}

/// `--model`: the robot that plays, for the commands that run one.
#[derive(clap::Args, Debug, Clone)]
pub struct ModelArg {
    /// The robot: `default` (the built-in 75-muscle body), `myochallenge` (MyoSuite's 273-muscle
    /// robot, after `rally model import myosuite`) or an MJCF file (played with the built-in arena's
    /// grip: hand body `hand`, paddle body `paddle`, flexors FDS, FDP and FPL).
    #[arg(
        long = "model",
        id = "model",
        value_name = "MODEL",
        default_value = "default",
        global = true
    )]
    pub name: String,
}

/// A robot ready to play: its model, its arena configuration (the grip) and its name.
pub struct Body {
    /// The model.
    pub model: std::sync::Arc<sim::model::Model>,
    /// Its arena configuration.
    pub config: sim::config::ArenaConfig,
    /// As `--model` gave it.
    pub name: String,
}

/// The arena configuration (grip) a `--model` plays with: MyoChallenge's for `myochallenge`, the
/// built-in arena's for the default robot and any MJCF file.
pub fn arena_config(model_name: &str) -> sim::config::ArenaConfig {
    match model_name {
        "myochallenge" => sim::config::ArenaConfig::myochallenge(),
        _ => sim::config::ArenaConfig::default(),
    }
}

impl ModelArg {
    /// Loads the model and checks that its grip configuration fits it (a usage error otherwise).
    pub fn load(&self) -> Result<Body, CliError> {
        let model = match self.name.as_str() {
            "default" => default_model()?,
            other => std::sync::Arc::new(model::resolve_model(other)?.0),
        };
        let config = arena_config(&self.name);
        sim::robot::Robot::new(model.clone(), &config.grip, sim::Side::A)
            .map_err(|e| CliError::Usage(format!("--model {}: {e}", self.name)))?;
        Ok(Body {
            model,
            config,
            name: self.name.clone(),
        })
    }
}

/// An agent argument: a scripted variant's name or a checkpoint file (a usage error names `which`).
pub fn player(
    name: &str,
    model: &sim::model::Model,
    which: &str,
) -> Result<agents::factory::PlayerSpec, CliError> {
    agents::factory::PlayerSpec::resolve(name, model, &|p| std::fs::read_to_string(p))
        .map_err(|e| CliError::Usage(format!("{which}: {e}")))
}
