//! `muscle_rally._core`: the Rust environments behind the `muscle_rally` Python package.
//!
//! One class, `VecEnv`, over [`agents::vecenv::VecEnv`] — the environments `rally train` steps, so
//! Python and `rally train` share one implementation. Arrays are the caller's (numpy, C-contiguous,
//! float64 observations and actions, bool flags): `reset` and `step` write into them, `step` with
//! the GIL released while rayon steps every environment. The gymnasium and PettingZoo classes
//! (`muscle_rally/*.py`) wrap it. Bad arguments raise `ValueError` naming the argument; nothing in
//! here panics across the boundary (a panic would surface as `PanicException`).

use std::path::PathBuf;
use std::sync::Arc;

use agents::ppo::{Method, TrainConfig, TrainEnv, TrainServe};
use agents::vecenv::StepResult;
use numpy::{PyReadonlyArray2, PyReadwriteArray1, PyReadwriteArray2};
use pyo3::exceptions::{PyIndexError, PyValueError};
use pyo3::prelude::*;

fn bad(what: &str, e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(format!("{what}: {e}"))
}

/// Where `rally model import myosuite` writes the robot: `$RALLY_DATA_DIR/models`, else the user's
/// data directory's `muscle-rally/models` (the rule `rally` itself follows).
fn imported(file: &str) -> PathBuf {
    let dir = match std::env::var_os("RALLY_DATA_DIR").filter(|d| !d.is_empty()) {
        Some(d) => PathBuf::from(d),
        None => dirs::data_dir()
            .map(|d| d.join("muscle-rally"))
            .unwrap_or_else(|| PathBuf::from("data")),
    };
    dir.join("models").join(file)
}

/// The robot `model` names and the arena configuration (grip) it plays with.
fn robot(model: &str) -> PyResult<(Arc<sim::model::Model>, sim::config::ArenaConfig)> {
    let read = |p: &std::path::Path| {
        sim::mjcf::load(p, &|f| std::fs::read_to_string(f)).map_err(|e| bad("model", e))
    };
    Ok(match model {
        "default" => (
            Arc::new(sim::config::default_model()),
            sim::config::ArenaConfig::default(),
        ),
        "myochallenge" => {
            let path = imported("myochallenge.xml");
            if !path.exists() {
                return Err(bad(
                    "model",
                    format!(
                        "no MyoChallenge robot at {}: run `rally model import myosuite` first \
                         (or set RALLY_DATA_DIR to where it was imported)",
                        path.display()
                    ),
                ));
            }
            (
                Arc::new(read(&path)?),
                sim::config::ArenaConfig::myochallenge(),
            )
        }
        file => (
            Arc::new(read(std::path::Path::new(file))?),
            sim::config::ArenaConfig::default(),
        ),
    })
}

/// The training configuration: `config` (a `rally train --config` file) or the defaults, with
/// `serve` and `env` overriding its own.
fn configuration(
    config: Option<PathBuf>,
    serve: Option<&str>,
    env: Option<&str>,
) -> PyResult<TrainConfig> {
    let mut c = match config {
        None => TrainConfig::default(),
        Some(p) => {
            let text = std::fs::read_to_string(&p).map_err(|e| bad("config", e))?;
            toml::from_str(&text).map_err(|e| bad("config", e))?
        }
    };
    if let Some(s) = serve {
        c.serve = match s {
            "p2" => TrainServe::P2,
            "p1" => TrainServe::P1,
            "rally" => TrainServe::Rally,
            "stroke" => TrainServe::Stroke,
            other => return Err(bad("serve", format!("'{other}': p2, p1, rally or stroke"))),
        };
    }
    if let Some(e) = env {
        c.env = match e {
            "single" => TrainEnv::Single,
            "rally" => TrainEnv::Rally,
            other => return Err(bad("env", format!("'{other}': single or rally"))),
        };
    }
    c.validate().map_err(|e| bad("config", e))?;
    Ok(c)
}

/// N environments of one method on one robot, stepped together in Rust.
#[pyclass(module = "muscle_rally._core")]
struct VecEnv {
    inner: agents::vecenv::VecEnv,
    results: Vec<StepResult>,
    model: String,
    method: String,
}

#[pymethods]
impl VecEnv {
    #[new]
    #[pyo3(signature = (method, num_envs=1, model="default", config=None, serve=None, env=None))]
    fn new(
        method: &str,
        num_envs: usize,
        model: &str,
        config: Option<PathBuf>,
        serve: Option<&str>,
        env: Option<&str>,
    ) -> PyResult<Self> {
        let m: Method = method.parse().map_err(|e| bad("method", e))?;
        if num_envs == 0 {
            return Err(bad("num_envs", "at least 1"));
        }
        let c = configuration(config, serve, env)?;
        let (body, arena) = robot(model)?;
        let name = sim::config::robot_name(&body).to_string();
        let inner = agents::vecenv::VecEnv::new(body, &arena, m, &c, num_envs)
            .map_err(|e| bad("config", e))?;
        let rows = inner.len() * inner.agents();
        Ok(VecEnv {
            inner,
            results: vec![StepResult::default(); rows],
            model: name,
            method: m.name().to_string(),
        })
    }

    /// Environments.
    #[getter]
    fn num_envs(&self) -> usize {
        self.inner.len()
    }

    /// Robots per environment (2 in a rally).
    #[getter]
    fn agents(&self) -> usize {
        self.inner.agents()
    }

    #[getter]
    fn obs_dim(&self) -> usize {
        self.inner.obs_dim()
    }

    #[getter]
    fn act_dim(&self) -> usize {
        self.inner.act_dim()
    }

    #[getter]
    fn observation_names(&self) -> Vec<String> {
        self.inner.observation_names().to_vec()
    }

    #[getter]
    fn action_names(&self) -> Vec<String> {
        self.inner.action_names().to_vec()
    }

    /// The robot's name (`default`, `myochallenge`, or the MJCF model's).
    #[getter]
    fn model(&self) -> String {
        self.model.clone()
    }

    #[getter]
    fn method(&self) -> String {
        self.method.clone()
    }

    /// The reward's terms, in the order `step` writes them (the `[reward]` keys of a configuration).
    #[getter]
    fn reward_term_names(&self) -> Vec<&'static str> {
        agents::env::RewardTerms::NAMES.to_vec()
    }

    /// Steps every environment with the same `actions` (one robot's row) for about `seconds` in
    /// Rust alone, GIL released, each ended episode started again: the benchmark's reference.
    /// Robot-steps taken.
    fn run_fixed(
        &mut self,
        py: Python<'_>,
        actions: numpy::PyReadonlyArray1<f64>,
        seconds: f64,
    ) -> PyResult<u64> {
        let a = actions.as_slice().map_err(|e| bad("actions", e))?.to_vec();
        let inner = &mut self.inner;
        py.detach(|| inner.run_fixed(&a, seconds))
            .map_err(|e| bad("actions", e))
    }

    /// Starts environment `i`'s next episode from `seed`; writes its robots' observations into
    /// `obs` (agents × obs_dim, float64).
    fn reset(&mut self, i: usize, seed: u64, mut obs: PyReadwriteArray2<f64>) -> PyResult<()> {
        if i >= self.inner.len() {
            return Err(PyIndexError::new_err(format!(
                "env index {i}: there are {}",
                self.inner.len()
            )));
        }
        let o = obs.as_slice_mut().map_err(|e| bad("obs", e))?;
        self.inner.reset(i, seed, o).map_err(|e| bad("obs", e))
    }

    /// One step of every environment (GIL released): `actions` (num_envs·agents × act_dim) in;
    /// observations, rewards and the flags out, into the arrays given, and what each reward term
    /// added to each reward into `terms` (num_envs·agents × 13) if given (every length checked
    /// before anything steps).
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (actions, obs, rewards, terminated, truncated, hit, success, terms=None))]
    fn step(
        &mut self,
        py: Python<'_>,
        actions: PyReadonlyArray2<f64>,
        mut obs: PyReadwriteArray2<f64>,
        mut rewards: PyReadwriteArray1<f64>,
        mut terminated: PyReadwriteArray1<bool>,
        mut truncated: PyReadwriteArray1<bool>,
        mut hit: PyReadwriteArray1<bool>,
        mut success: PyReadwriteArray1<bool>,
        mut terms: Option<PyReadwriteArray2<f64>>,
    ) -> PyResult<()> {
        let rows = self.results.len();
        let a = actions.as_slice().map_err(|e| bad("actions", e))?;
        let o = obs.as_slice_mut().map_err(|e| bad("obs", e))?;
        let rw = rewards.as_slice_mut().map_err(|e| bad("rewards", e))?;
        let flags: [(&str, &mut [bool]); 4] = [
            (
                "terminated",
                terminated
                    .as_slice_mut()
                    .map_err(|e| bad("terminated", e))?,
            ),
            (
                "truncated",
                truncated.as_slice_mut().map_err(|e| bad("truncated", e))?,
            ),
            ("hit", hit.as_slice_mut().map_err(|e| bad("hit", e))?),
            (
                "success",
                success.as_slice_mut().map_err(|e| bad("success", e))?,
            ),
        ];
        if rw.len() != rows {
            return Err(bad("rewards", format!("{} entries, not {rows}", rw.len())));
        }
        for (name, out) in &flags {
            if out.len() != rows {
                return Err(bad(name, format!("{} entries, not {rows}", out.len())));
            }
        }
        let width = agents::env::RewardTerms::NAMES.len();
        let terms = match terms.as_mut() {
            None => None,
            Some(t) => {
                let t = t.as_slice_mut().map_err(|e| bad("terms", e))?;
                if t.len() != rows * width {
                    let want = format!("{} entries, not {rows} x {width}", t.len());
                    return Err(bad("terms", want));
                }
                Some(t)
            }
        };
        let (inner, results) = (&mut self.inner, &mut self.results);
        py.detach(|| inner.step(a, o, results))
            .map_err(|e| bad("actions", e))?;
        for (k, r) in self.results.iter().enumerate() {
            rw[k] = r.reward;
        }
        let [(_, t), (_, u), (_, h), (_, s)] = flags;
        for (k, r) in self.results.iter().enumerate() {
            (t[k], u[k], h[k], s[k]) = (r.terminated, r.truncated, r.hit, r.success);
        }
        if let Some(out) = terms {
            for (row, r) in out.chunks_mut(width).zip(&self.results) {
                row.copy_from_slice(&r.terms);
            }
        }
        Ok(())
    }
}

/// A checkpoint (its JSON text) around an ONNX network trained elsewhere, as `rally checkpoint
/// from-onnx` writes it: `method`'s controller (gains, K-MAC's clamp, its activation noise, drawn
/// in play as in training, and the grip floor from `config`, a `rally train` configuration file, or
/// its defaults; the command's `replan` from it too), `obs_mean` and `obs_std` applied
/// before the network (both or neither), validated against the robot `model` first.
#[pyfunction]
#[pyo3(signature = (onnx, method, name, model="default", obs_mean=None, obs_std=None, config=None))]
fn checkpoint_from_onnx(
    onnx: &[u8],
    method: &str,
    name: &str,
    model: &str,
    obs_mean: Option<Vec<f64>>,
    obs_std: Option<Vec<f64>>,
    config: Option<PathBuf>,
) -> PyResult<String> {
    let m: Method = method.parse().map_err(|e| bad("method", e))?;
    let c = configuration(config, None, None)?;
    let (body, _) = robot(model)?;
    let norm = match (obs_mean, obs_std) {
        (None, None) => None,
        (Some(mean), Some(std)) => Some((mean, std)),
        _ => return Err(bad("obs_mean", "give obs_mean and obs_std together")),
    };
    let grip = (c.controller.grip_floor > 0.0).then_some(c.controller.grip_floor);
    let mut ck = agents::checkpoint::Checkpoint::from_onnx(
        &body,
        name,
        c.controller(m, &body),
        onnx,
        norm,
        grip,
    )
    .map_err(|e| bad(&e.field, &e.message))?;
    // The player makes the command as the network's training did.
    ck.observation.replan = c.replan;
    serde_json::to_string(&ck).map_err(|e| bad("checkpoint", e))
}

/// `rally bench train`'s ceiling for the robot `model`: `num_envs` worlds stepped for about
/// `seconds` on every core with every muscle at 0.1 (no controller, observation or reward), GIL
/// released. Physics steps per second.
#[pyfunction]
#[pyo3(signature = (model="default", num_envs=64, seconds=3.0))]
fn physics_alone(py: Python<'_>, model: &str, num_envs: usize, seconds: f64) -> PyResult<f64> {
    if num_envs == 0 {
        return Err(bad("num_envs", "at least 1"));
    }
    let (body, arena) = robot(model)?;
    py.detach(|| agents::vecenv::physics_alone(&body, &arena, num_envs, seconds))
        .map_err(|e| bad("model", e))
}

/// One traced control step: episode, step, time, observation, network output, controls.
type Traced = (usize, usize, f64, Vec<f64>, Vec<f64>, Vec<f64>);

/// `rally eval` (the same function): `agent` (a scripted variant, a built-in checkpoint's name or
/// a checkpoint file) on `episodes` single serves of `serve` from `seed` on the robot `model`, all
/// cores, the GIL released. The report's JSON text, and every control step when `trace` (at most
/// 100 episodes).
#[pyfunction]
#[pyo3(signature = (agent, episodes=100, seed=0, serve="p2", model="default", mean_action=false, trace=false))]
#[allow(clippy::too_many_arguments)]
fn evaluate(
    py: Python<'_>,
    agent: &str,
    episodes: usize,
    seed: u64,
    serve: &str,
    model: &str,
    mean_action: bool,
    trace: bool,
) -> PyResult<(String, Vec<Traced>)> {
    if !(1..=100_000).contains(&episodes) {
        return Err(bad("episodes", format!("{episodes}: 1 to 100000")));
    }
    if trace && episodes > 100 {
        let why = "a trace holds every step's observation";
        return Err(bad(
            "trace",
            format!("at most 100 episodes ({episodes} asked): {why}"),
        ));
    }
    let kind = match serve {
        "p1" | "p2" | "rally" | "stroke" => sim::serve::ServeKind::parse(serve).expect("a serve"),
        other => return Err(bad("serve", format!("'{other}': p1, p2, rally or stroke"))),
    };
    let (body, arena) = robot(model)?;
    let mut spec =
        agents::factory::PlayerSpec::resolve(agent, &body, &|p| std::fs::read_to_string(p))
            .map_err(|e| bad("agent", e))?;
    if mean_action {
        spec = spec.mean_action();
    }
    let e = agents::eval::Evaluation {
        lead_in: false,
        model: body,
        config: arena,
        preset: sim::arena::MYOCHALLENGE,
        kind,
        episodes,
        seed,
    };
    let (report, steps) = py
        .detach(|| agents::eval::evaluate_traced(&e, &spec, &|| {}, trace))
        .map_err(|e| bad("agent", e))?;
    let text = serde_json::to_string(&report).map_err(|e| bad("report", e))?;
    let steps = steps
        .into_iter()
        .map(|s| {
            (
                s.episode,
                s.step,
                s.time,
                s.observation,
                s.action,
                s.controls,
            )
        })
        .collect();
    Ok((text, steps))
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<VecEnv>()?;
    m.add_function(wrap_pyfunction!(checkpoint_from_onnx, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(physics_alone, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
