//! `rally checkpoint`: write a template checkpoint of the right shape, or validate one.

use std::path::PathBuf;

use agents::checkpoint::{Activation, Checkpoint};
use agents::controller::{ControllerKind, ControllerSpec, PdGains, Synergies};
use clap::{Args, Subcommand, ValueEnum};

use super::CliError;

/// Arguments of `rally checkpoint`.
#[derive(Args, Debug)]
pub struct CheckpointArgs {
    #[command(subcommand)]
    command: CheckpointCommand,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Act {
    Elu,
    Tanh,
    Relu,
}

#[derive(Subcommand, Debug)]
enum CheckpointCommand {
    /// Print a zero-weight checkpoint for the default robot (JSON), to fill with trained weights.
    Template {
        /// Controller the policy drives.
        #[arg(long, default_value = "kmac", value_parser = ["kmac", "muscle_pd", "direct", "dynsyn"])]
        controller: String,
        /// Hidden layer widths, comma-separated.
        #[arg(long, default_value = "256,256", value_delimiter = ',')]
        hidden: Vec<usize>,
        /// Hidden-layer activation.
        #[arg(long, value_enum, default_value = "elu")]
        activation: Act,
        /// Name stored in the checkpoint.
        #[arg(long, default_value = "template")]
        name: String,
    },
    /// Check a checkpoint against the default robot; prints its shape, or the field that is wrong.
    Validate {
        /// Checkpoint file.
        file: PathBuf,
    },
}

/// Runs `rally checkpoint`.
pub fn run(args: &CheckpointArgs) -> Result<(), CliError> {
    let model = super::default_model()?;
    match &args.command {
        CheckpointCommand::Template {
            controller,
            hidden,
            activation,
            name,
        } => {
            let spec = match controller.as_str() {
                "kmac" => ControllerSpec::Kmac {
                    gains: PdGains { kp: 40.0, kd: 3.0 },
                },
                "muscle_pd" => ControllerSpec::MusclePd {
                    gains: PdGains::MUSCLE_PD,
                },
                "direct" => ControllerSpec::Direct,
                _ => ControllerSpec::Dynsyn {
                    synergies: Synergies::derive(&model, 16, 0),
                },
            };
            if hidden.contains(&0) {
                return Err(CliError::Usage(
                    "--hidden: layer widths must be positive".into(),
                ));
            }
            let act = match activation {
                Act::Elu => Activation::Elu,
                Act::Tanh => Activation::Tanh,
                Act::Relu => Activation::Relu,
            };
            let c = Checkpoint::template(&model, name, spec, hidden, act);
            c.validate(&model)
                .map_err(|e| CliError::Usage(e.to_string()))?;
            println!(
                "{}",
                serde_json::to_string(&c).map_err(anyhow::Error::from)?
            );
            Ok(())
        }
        CheckpointCommand::Validate { file } => {
            let text = std::fs::read_to_string(file)
                .map_err(|e| CliError::Usage(format!("{}: {e}", file.display())))?;
            let c = Checkpoint::from_json(&text, &model)
                .map_err(|e| CliError::Usage(format!("{}: {e}", file.display())))?;
            let kind: ControllerKind = c.controller.kind();
            println!(
                "{}: valid — '{}', {:?} controller, observation {} entries, {}",
                file.display(),
                c.name,
                kind,
                c.observation.mean.len(),
                match &c.policy {
                    Some(p) => format!(
                        "MLP of {} layers, {} parameters",
                        p.layers.len(),
                        p.parameters()
                    ),
                    None => "ONNX network".to_string(),
                }
            );
            Ok(())
        }
    }
}
