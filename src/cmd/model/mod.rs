//! `rally model`: look inside an MJCF model — its structure (`inspect`) and its muscle geometry at a
//! configuration (`kinematics`) — and bring in MyoSuite's MyoChallenge robot (`import`).

pub mod import;

use std::path::{Path, PathBuf};

use clap::{ArgGroup, Args, Subcommand};
use serde_json::{json, Value};
use sim::kinematics::{actuator_length, Kinematics, TendonKinematics};
use sim::model::{Bias, Dynamics, Gain, JointKind, Model, Transmission};

use super::CliError;

/// Arguments of `rally model`.
#[derive(Args, Debug)]
pub struct ModelArgs {
    #[command(subcommand)]
    command: ModelCommand,
}

#[derive(Subcommand, Debug)]
enum ModelCommand {
    /// Bodies, joints, degrees of freedom, muscles, actuators and couplings of a model.
    Inspect {
        /// An MJCF file, `default` (the built-in 75-muscle body) or `myochallenge` (MyoSuite's
        /// 273-muscle robot, after `rally model import myosuite`).
        model: String,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Muscle lengths and moment arms at a configuration, as JSON.
    #[command(
        group(ArgGroup::new("config").required(true).args(["qpos", "qpos_file"])),
        after_help = "Output: {\"joints\":[names in model order],\"muscles\":[{\"name\":…,\"length\":…,\"moment_arms\":[one per DoF]}]}\n\
                      A moment arm is ∂length/∂q per degree of freedom (MuJoCo's actuator_moment). Values given for\n\
                      dependent (coupled) joints are replaced by their couplings."
    )]
    Kinematics {
        /// An MJCF file, `default` or `myochallenge` (see `rally model inspect --help`).
        model: String,
        /// MuJoCo's qpos: every joint in model order (7 numbers for a free joint), comma-separated.
        #[arg(long, value_name = "Q1,Q2,…", allow_hyphen_values = true)]
        qpos: Option<String>,
        /// A file holding the qpos as a JSON array or as numbers separated by commas or whitespace.
        #[arg(long, value_name = "FILE")]
        qpos_file: Option<PathBuf>,
    },
    /// Import MyoSuite's MyoChallenge 2025 table-tennis robot (273 muscles) as a model file.
    Import(import::ImportArgs),
}

/// Where muscle-rally keeps what it fetches or builds at set-up (see [`server::data_dir`]:
/// `$RALLY_DATA_DIR`, else the user's data directory, whatever the working directory).
pub fn data_dir() -> PathBuf {
    server::data_dir()
}

/// A MODEL argument: `default`, `myochallenge`, or a file. Returns the model and what to call it.
pub fn resolve_model(arg: &str) -> Result<(Model, PathBuf), CliError> {
    match arg {
        "default" => Ok((
            (*super::default_model()?).clone(),
            PathBuf::from("config/models/upper_body.xml"),
        )),
        "myochallenge" => {
            let path = data_dir().join(import::MYOCHALLENGE_FILE);
            if !path.exists() {
                return Err(CliError::Usage(format!(
                    "no MyoChallenge model at {}: run `rally model import myosuite` first \
                     (or set RALLY_DATA_DIR to where it was imported)",
                    path.display()
                )));
            }
            Ok((load_model(&path)?, path))
        }
        file => Ok((load_model(Path::new(file))?, PathBuf::from(file))),
    }
}

/// The SHA-256, in hex, of a MODEL argument's MJCF text (the built-in body's compiled-in text, the
/// imported MyoChallenge robot's file, or the file named): what tells two imports, or two
/// machines' files, apart. `None` when the file cannot be read.
pub fn model_sha256(arg: &str) -> Option<String> {
    let path = match arg {
        "default" => return Some(server::db::sha256_hex(sim::config::DEFAULT_MODEL_XML)),
        "myochallenge" => data_dir().join(import::MYOCHALLENGE_FILE),
        file => PathBuf::from(file),
    };
    file_sha256(&path)
}

/// The SHA-256 of a file's text, in hex.
pub fn file_sha256(path: &Path) -> Option<String> {
    std::fs::read_to_string(path)
        .ok()
        .map(|text| server::db::sha256_hex(&text))
}

/// Loads a model from disk; a problem is a usage error naming the file and line.
pub fn load_model(path: &Path) -> Result<Model, CliError> {
    sim::mjcf::load(path, &|p| std::fs::read_to_string(p))
        .map_err(|e| CliError::Usage(e.to_string()))
}

/// Runs `rally model`.
pub fn run(args: &ModelArgs) -> Result<(), CliError> {
    match &args.command {
        ModelCommand::Inspect { model: arg, json } => {
            let (m, model) = resolve_model(arg)?;
            if *json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&inspect_json(&m)).map_err(anyhow::Error::from)?
                );
            } else {
                print!("{}", inspect_text(&m, &model, model_sha256(arg)));
            }
            Ok(())
        }
        ModelCommand::Kinematics {
            model,
            qpos,
            qpos_file,
        } => {
            let (m, _) = resolve_model(model)?;
            let (text, source) = match (qpos, qpos_file) {
                (Some(q), _) => (q.clone(), "--qpos".to_string()),
                (None, Some(f)) => (
                    std::fs::read_to_string(f).map_err(|e| {
                        CliError::Usage(format!("--qpos-file {}: {e}", f.display()))
                    })?,
                    format!("--qpos-file {}", f.display()),
                ),
                (None, None) => return Err(CliError::Usage("give --qpos or --qpos-file".into())),
            };
            let q =
                parse_qpos(&text, m.nq).map_err(|e| CliError::Usage(format!("{source}: {e}")))?;
            println!("{}", kinematics_json(&m, &q));
            Ok(())
        }
        ModelCommand::Import(args) => import::run(args),
    }
}

/// Parses a qpos given as a JSON array or as numbers separated by commas or whitespace.
fn parse_qpos(text: &str, nq: usize) -> Result<Vec<f64>, String> {
    let t = text.trim();
    let values: Vec<f64> = if t.starts_with('[') {
        serde_json::from_str::<Vec<f64>>(t)
            .map_err(|e| format!("not a JSON array of numbers: {e}"))?
    } else {
        t.split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(|s| {
                s.parse::<f64>()
                    .map_err(|_| format!("'{s}' is not a number"))
            })
            .collect::<Result<_, _>>()?
    };
    if values.len() != nq {
        return Err(format!(
            "{} numbers for a model with nq = {nq}",
            values.len()
        ));
    }
    if let Some(i) = values.iter().position(|x| !x.is_finite()) {
        return Err(format!("entry {i} is not a finite number"));
    }
    Ok(values)
}

fn kinematics_json(m: &Model, qpos: &[f64]) -> Value {
    let mut q = qpos.to_vec();
    m.apply_couplings(&mut q);
    let mut kin = Kinematics::new(m);
    kin.update(m, &q);
    let mut ten = TendonKinematics::new(m);
    ten.update(m, &kin);
    let muscles: Vec<Value> = m
        .muscles()
        .map(|(_, a)| {
            let moment: Vec<f64> = match a.transmission {
                Transmission::Tendon(t) => ten.moment_arms(t).to_vec(),
                Transmission::Joint(j) => {
                    let mut row = vec![0.0; m.nv];
                    row[m.joints[j].dof_adr] = 1.0;
                    row
                }
            };
            json!({
                "name": a.name,
                "length": actuator_length(m, a.transmission, &ten, &q),
                "moment_arms": moment,
            })
        })
        .collect();
    json!({
        "joints": m.joints.iter().map(|j| j.name.clone()).collect::<Vec<_>>(),
        "muscles": muscles,
    })
}

fn actuator_kind(a: &sim::model::Actuator) -> &'static str {
    match (&a.dynamics, &a.gain, &a.bias) {
        (Dynamics::Muscle(_), Gain::Muscle(_), Bias::Muscle(_)) => "muscle",
        (Dynamics::None, Gain::Fixed(_), Bias::Affine(b)) if b[0] == 0.0 => "position",
        _ => "general",
    }
}

fn transmission_name(m: &Model, t: Transmission) -> (&'static str, String) {
    match t {
        Transmission::Tendon(i) => ("tendon", m.tendons[i].name.clone()),
        Transmission::Joint(j) => ("joint", m.joints[j].name.clone()),
    }
}

fn inspect_json(m: &Model) -> Value {
    let independent: usize = (0..m.nv)
        .filter(|&d| !m.is_dependent(m.dof_joint[d]))
        .count();
    json!({
        "name": m.name,
        "timestep": m.timestep,
        "nq": m.nq,
        "nv": m.nv,
        "independent_dof": independent,
        "bodies": m.bodies.iter().map(|b| json!({
            "name": b.name,
            "parent": b.parent.map(|p| m.bodies[p].name.clone()),
            "mass": b.mass,
        })).collect::<Vec<_>>(),
        "joints": m.joints.iter().enumerate().map(|(j, joint)| json!({
            "name": joint.name,
            "type": joint.kind.name(),
            "body": m.bodies[joint.body].name,
            "range": joint.range,
            "dependent": m.is_dependent(j),
        })).collect::<Vec<_>>(),
        "muscles": m.muscles().map(|(_, a)| {
            let p = a.muscle().expect("muscle");
            let (kind, target) = transmission_name(m, a.transmission);
            json!({
                "name": a.name,
                kind: target,
                "force": p.force,
                "lengthrange": a.lengthrange,
                "lengthrange_given": a.lengthrange_given,
            })
        }).collect::<Vec<_>>(),
        "actuators": m.actuators.iter().map(|a| {
            let (kind, target) = transmission_name(m, a.transmission);
            json!({"name": a.name, "kind": actuator_kind(a), kind: target, "ctrlrange": a.ctrlrange})
        }).collect::<Vec<_>>(),
        "couplings": m.couplings.iter().map(|c| json!({
            "dependent": m.joints[c.dependent].name,
            "independent": c.independent.map(|i| m.joints[i].name.clone()),
            "polycoef": c.coef,
        })).collect::<Vec<_>>(),
        "keyframes": m.keyframes.iter().map(|k| k.name.clone()).collect::<Vec<_>>(),
        "spaces": spaces(m),
    })
}

/// The policy's observation (every block, as training builds it) and each method's action, entry by
/// entry, on `m`.
fn spaces(m: &Model) -> Value {
    use agents::controller::ActionMapper;
    use agents::observation::{observation_names, ObsBlock};
    use agents::ppo::{Method, TrainConfig};
    let config = TrainConfig::default();
    let actions: serde_json::Map<String, Value> = Method::ALL
        .iter()
        .map(|&method| {
            let mapper = ActionMapper::new(m, &config.controller(method, m));
            (method.name().to_string(), json!(mapper.action_names(m)))
        })
        .collect();
    json!({
        "observation": observation_names(m, &ObsBlock::ALL),
        "actions": actions,
    })
}

/// `spaces` in a few lines: how many entries of each kind.
fn spaces_text(m: &Model) -> String {
    let v = spaces(m);
    let count = |names: &Value| {
        let mut order: Vec<(String, usize)> = Vec::new();
        for n in names.as_array().into_iter().flatten() {
            let kind = n.as_str().unwrap_or("").split('.').next().unwrap_or("");
            match order.last_mut() {
                Some((k, c)) if k == kind => *c += 1,
                _ => order.push((kind.to_string(), 1)),
            }
        }
        let total: usize = order.iter().map(|(_, c)| c).sum();
        let parts: Vec<String> = order.iter().map(|(k, c)| format!("{k} {c}")).collect();
        format!("{total} ({})", parts.join(", "))
    };
    let mut s = format!(
        "\nspaces (`rally model inspect --json` names every entry)\n  observation  {}\n",
        count(&v["observation"])
    );
    for method in agents::ppo::Method::ALL {
        let name = method.name();
        s += &format!("  {name:<12} {}\n", count(&v["actions"][name]));
    }
    s
}

fn inspect_text(m: &Model, path: &Path, sha256: Option<String>) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let independent: usize = (0..m.nv)
        .filter(|&d| !m.is_dependent(m.dof_joint[d]))
        .count();
    let nmuscles = m.muscles().count();
    let total_mass: f64 = m.bodies.iter().map(|b| b.mass).sum();
    let _ = writeln!(s, "{} ({})", m.name, path.display());
    if let Some(digest) = sha256 {
        let _ = writeln!(s, "  MJCF sha256 {digest}");
    }
    let _ = writeln!(
        s,
        "  {} bodies ({total_mass:.2} kg), {} joints, nq {}, {} DoF ({independent} independent, {} coupled), {} actuators ({nmuscles} muscles), timestep {} s",
        m.bodies.len() - 1,
        m.joints.len(),
        m.nq,
        m.nv,
        m.couplings.len(),
        m.actuators.len(),
        m.timestep
    );
    let _ = writeln!(s, "\nbodies");
    for b in m.bodies.iter().skip(1) {
        let parent = b.parent.map(|p| m.bodies[p].name.as_str()).unwrap_or("");
        let _ = writeln!(
            s,
            "  {:<16} parent {:<16} {:>7.3} kg",
            b.name, parent, b.mass
        );
    }
    let _ = writeln!(s, "\njoints");
    for (j, joint) in m.joints.iter().enumerate() {
        let range = match (joint.range, joint.kind) {
            (Some([lo, hi]), JointKind::Slide) => format!("[{lo:.3}, {hi:.3}] m"),
            (Some([lo, hi]), _) => format!("[{lo:.3}, {hi:.3}] rad"),
            (None, _) => "unlimited".into(),
        };
        let coupled = m
            .couplings
            .iter()
            .find(|c| c.dependent == j)
            .map(|c| match c.independent {
                Some(i) => format!("follows {}", m.joints[i].name),
                None => "locked".to_string(),
            })
            .unwrap_or_default();
        let _ = writeln!(
            s,
            "  {:<16} {:<6} {:<10} {:<24} {coupled}",
            joint.name,
            joint.kind.name(),
            m.bodies[joint.body].name,
            range
        );
    }
    let _ = writeln!(s, "\nactuators");
    for a in &m.actuators {
        let (kind, target) = transmission_name(m, a.transmission);
        let extra = match a.muscle() {
            Some(p) => format!(
                "F {:>6.0} N  lengthrange [{:.4}, {:.4}] m",
                p.force, a.lengthrange[0], a.lengthrange[1]
            ),
            None => String::new(),
        };
        let _ = writeln!(
            s,
            "  {:<16} {:<8} {kind} {:<20} {extra}",
            a.name,
            actuator_kind(a),
            target
        );
    }
    if !m.keyframes.is_empty() {
        let _ = writeln!(
            s,
            "\nkeyframes: {}",
            m.keyframes
                .iter()
                .map(|k| k.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    s + &spaces_text(m)
}
