//! `rally checkpoint spec` (what a policy of a method sees and drives, entry by entry) and
//! `rally checkpoint from-onnx` (a checkpoint around a network trained elsewhere).

use std::path::{Path, PathBuf};

use agents::checkpoint::Checkpoint;
use agents::controller::{ActionMapper, ActionSpace};
use agents::observation::{observation_names, ObsBlock};
use agents::ppo::{Method, TrainConfig};
use serde::{Deserialize, Serialize};
use sim::model::Model;

use crate::cmd::CliError;

/// The controller settings of `--config` (`rally train`'s file; absent, its defaults).
fn config(path: Option<&Path>) -> Result<TrainConfig, CliError> {
    match path {
        Some(p) => crate::cmd::train::read_config(p),
        None => Ok(TrainConfig::default()),
    }
}

fn method(name: &str) -> Result<Method, CliError> {
    name.parse()
        .map_err(|e| CliError::Usage(format!("--method {e}")))
}

/// What `spec` prints as JSON.
#[derive(Serialize)]
struct Spec {
    model: String,
    method: String,
    /// The observation is normalised before the network, `(x − mean) / std` with the checkpoint's
    /// `observation.mean` and `observation.std`.
    normalised: bool,
    observation: Vec<String>,
    /// The network's outputs, each clipped to [−1, 1], in order.
    action: Vec<String>,
}

fn spec_of(model: &Model, method: Method, config: &TrainConfig) -> Spec {
    let mapper = ActionMapper::new(model, &config.controller(method, model));
    Spec {
        model: sim::config::robot_name(model).to_string(),
        method: method.name().to_string(),
        normalised: true,
        observation: observation_names(model, &ObsBlock::ALL),
        action: mapper.action_names(model),
    }
}

/// `rally checkpoint spec --method M`: every observation and action entry of the method on the robot.
pub fn spec(model: &Model, name: &str, cfg: Option<&Path>, json: bool) -> Result<(), CliError> {
    let s = spec_of(model, method(name)?, &config(cfg)?);
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(&s).map_err(anyhow::Error::from)?
        );
        return Ok(());
    }
    println!(
        "{} on the {} robot: the network reads {} observation entries, normalised first as \
         (x - observation.mean) / observation.std, and writes {} actions, each clipped to [-1, 1].",
        s.method,
        s.model,
        s.observation.len(),
        s.action.len()
    );
    println!("\nobservation");
    for (i, n) in s.observation.iter().enumerate() {
        println!("{i:5}  {n}");
    }
    println!("\naction");
    for (i, n) in s.action.iter().enumerate() {
        println!("{i:5}  {n}");
    }
    Ok(())
}

/// The observation normalisation `--obs-norm` reads.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ObsNorm {
    mean: Vec<f64>,
    std: Vec<f64>,
}

/// What `from-onnx` needs besides the robot.
pub struct FromOnnx<'a> {
    pub file: &'a Path,
    pub method: &'a str,
    pub config: Option<&'a Path>,
    pub obs_norm: Option<&'a Path>,
    pub name: &'a str,
    pub out: Option<&'a PathBuf>,
}

/// `rally checkpoint from-onnx FILE --method M --name N`: the checkpoint, validated, to `--out` or
/// standard output.
pub fn from_onnx(model: &Model, a: &FromOnnx) -> Result<(), CliError> {
    let method = method(a.method)?;
    let config = config(a.config)?;
    let bytes =
        std::fs::read(a.file).map_err(|e| CliError::Usage(format!("{}: {e}", a.file.display())))?;
    let norm = match a.obs_norm {
        None => None,
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .map_err(|e| CliError::Usage(format!("--obs-norm {}: {e}", p.display())))?;
            let n: ObsNorm = serde_json::from_str(&text).map_err(|e| {
                CliError::Usage(format!(
                    "--obs-norm {}: {e} (expected {{\"mean\": [...], \"std\": [...]}})",
                    p.display()
                ))
            })?;
            let want: usize = {
                let space = ActionSpace::new(model);
                ObsBlock::ALL.iter().map(|b| b.size(&space)).sum()
            };
            for (field, v) in [("mean", &n.mean), ("std", &n.std)] {
                if v.len() != want {
                    return Err(CliError::Usage(format!(
                        "--obs-norm {}: {field} has {} entries; the observation has {want} \
                         (rally checkpoint spec --method {} names them)",
                        p.display(),
                        v.len(),
                        method.name()
                    )));
                }
            }
            Some((n.mean, n.std))
        }
    };
    let grip = (config.controller.grip_floor > 0.0).then_some(config.controller.grip_floor);
    let mut c = Checkpoint::from_onnx(
        model,
        a.name,
        config.controller(method, model),
        &bytes,
        norm,
        grip,
    )
    .map_err(|e| CliError::Usage(format!("{}: {e}", a.file.display())))?;
    // The player makes the command as the network's training did.
    c.observation.replan = config.replan;
    let text = serde_json::to_string(&c).map_err(anyhow::Error::from)?;
    match a.out {
        Some(out) => {
            std::fs::write(out, text + "\n")
                .map_err(|e| CliError::Usage(format!("--out {}: {e}", out.display())))?;
            eprintln!(
                "wrote {}: '{}', {} on the {} robot",
                out.display(),
                a.name,
                method.name(),
                c.model
            );
        }
        None => println!("{text}"),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_entry_is_named_and_the_counts_match_the_network() {
        let m = sim::config::default_model();
        let config = TrainConfig::default();
        for method in Method::ALL {
            let s = spec_of(&m, method, &config);
            let t = Checkpoint::template(
                &m,
                "t",
                config.controller(method, &m),
                &[4],
                agents::checkpoint::Activation::Tanh,
            );
            assert_eq!(s.observation.len(), t.observation.mean.len(), "{method:?}");
            let layers = &t.policy.as_ref().unwrap().layers;
            assert_eq!(s.action.len(), layers.last().unwrap().bias.len());
            let mut names = s.observation.clone();
            names.sort();
            names.dedup();
            assert_eq!(
                names.len(),
                s.observation.len(),
                "observation names are unique"
            );
        }
    }
}
