//! `rally model import myosuite`: MyoSuite's MyoChallenge 2025 table-tennis robot (273 muscles) as
//! one MJCF file our simulator loads. The model is MyoSuite's and stays out of the repository: it
//! is written at set-up from the `myosuite` package (installed into a virtual environment of its
//! own unless `--python` names one that has it) by `tools/myosuite_import.py`, compiled into this
//! binary, which says what it changes and checks the result against MuJoCo.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

use super::super::CliError;
use super::data_dir;

/// The MyoSuite release the import is written for.
pub const MYOSUITE_VERSION: &str = "3.0.0";

/// The MuJoCo release its own virtual environment gets (myosuite does not pin one): the one
/// the simulator's MuJoCo fixtures were generated with, so that a later MuJoCo cannot change
/// what the import compiles.
pub const MUJOCO_VERSION: &str = "4.0.0";

/// The import script, compiled in so that the binary needs no checkout.
const IMPORT_SCRIPT: &str = include_str!("../../../tools/myosuite_import.py");

/// Where imported models go under the data directory.
pub use server::arenas::MYOCHALLENGE_FILE;

/// Arguments of `rally model import`.
#[derive(Args, Debug)]
#[command(
    after_help = "The model is written to DATA/models/myochallenge.xml (DATA: $RALLY_DATA_DIR, else ~/.local/share/muscle-rally), \
where `--model myochallenge` finds it. Without --python, myosuite is installed from PyPI into \
DATA/venv-myosuite (about 300 MB, a few minutes the first time; reused afterwards)."
)]
pub struct ImportArgs {
    /// Where the model comes from.
    source: ImportSource,
    /// A Python that already has myosuite 3.0.0 (skips the virtual environment).
    #[arg(long, value_name = "PY")]
    python: Option<PathBuf>,
    /// Output file (default: DATA/models/myochallenge.xml).
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum ImportSource {
    /// MyoSuite's MyoChallenge 2025 table-tennis robot (recipe `challenge_tabletennis`).
    Myosuite,
}

fn spinner(message: &str) -> ProgressBar {
    let bar = ProgressBar::new_spinner();
    bar.set_style(
        ProgressStyle::with_template("{spinner} {msg} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.set_message(message.to_string());
    bar.enable_steady_tick(Duration::from_millis(120));
    bar
}

/// The last lines of a process's stderr, without MuJoCo's warnings about MyoSuite's spec edits.
fn stderr_tail(stderr: &[u8]) -> String {
    let text = String::from_utf8_lossy(stderr);
    let lines: Vec<&str> = text
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.contains("Attaching a spec with an empty prefix"))
        .collect();
    lines[lines.len().saturating_sub(12)..].join("\n")
}

/// The myosuite version `python` can import, or why it cannot.
fn myosuite_version(python: &Path) -> Result<String, String> {
    let out = Command::new(python)
        .args([
            "-c",
            "import importlib.metadata as m; import myosuite; print(m.version('myosuite'))",
        ])
        .output()
        .map_err(|e| format!("cannot run {}: {e}", python.display()))?;
    if !out.status.success() {
        return Err(format!(
            "{} cannot import myosuite:\n{}",
            python.display(),
            stderr_tail(&out.stderr)
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// The mujoco version `python` has installed, if it has one.
fn mujoco_version(python: &Path) -> Option<String> {
    let out = Command::new(python)
        .args([
            "-c",
            "import importlib.metadata as m; print(m.version('mujoco'))",
        ])
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// `--python`: it must have the release the import is written for.
fn given_python(python: &Path) -> Result<PathBuf, CliError> {
    let version = myosuite_version(python).map_err(|e| {
        CliError::Usage(format!(
            "--python: {e} (pip install myosuite=={MYOSUITE_VERSION})"
        ))
    })?;
    if version != MYOSUITE_VERSION {
        return Err(CliError::Usage(format!(
            "--python: {} has myosuite {version}; the import is written for {MYOSUITE_VERSION} \
             (pip install myosuite=={MYOSUITE_VERSION}, or leave out --python to use a virtual environment of its own)",
            python.display()
        )));
    }
    Ok(python.to_path_buf())
}

/// The virtual environment's Python, made and filled with myosuite when needed.
fn venv_python(venv: &Path) -> Result<PathBuf, CliError> {
    let python = venv.join("bin").join("python");
    if python.exists()
        && myosuite_version(&python).as_deref() == Ok(MYOSUITE_VERSION)
        && mujoco_version(&python).as_deref() == Some(MUJOCO_VERSION)
    {
        return Ok(python);
    }
    if !python.exists() {
        let bar = spinner(&format!(
            "creating a Python virtual environment in {}",
            venv.display()
        ));
        let out = Command::new("python3")
            .args(["-m", "venv"])
            .arg(venv)
            .output();
        bar.finish_and_clear();
        let out = out.map_err(|e| {
            CliError::Failed(anyhow::anyhow!(
                "cannot run python3 ({e}): install Python 3.10 or newer, or give --python PY with myosuite {MYOSUITE_VERSION}"
            ))
        })?;
        if !out.status.success() {
            return Err(CliError::Failed(anyhow::anyhow!(
                "python3 -m venv {} failed:\n{}",
                venv.display(),
                stderr_tail(&out.stderr)
            )));
        }
    }
    let bar = spinner(&format!(
        "installing myosuite {MYOSUITE_VERSION} and mujoco {MUJOCO_VERSION} from PyPI into {} (a few minutes)",
        venv.display()
    ));
    let out = Command::new(&python)
        .args([
            "-m",
            "pip",
            "install",
            "--disable-pip-version-check",
            "--quiet",
        ])
        .arg(format!("myosuite=={MYOSUITE_VERSION}"))
        .arg(format!("mujoco=={MUJOCO_VERSION}"))
        .output();
    bar.finish_and_clear();
    let out = out.with_context(|| format!("cannot run {}", python.display()))?;
    if !out.status.success() {
        return Err(CliError::Failed(anyhow::anyhow!(
            "pip install myosuite=={MYOSUITE_VERSION} mujoco=={MUJOCO_VERSION} failed:\n{}",
            stderr_tail(&out.stderr)
        )));
    }
    Ok(python)
}

/// Removes a file when dropped (the half-written output, the script), unless told to keep it.
struct Scratch(Option<PathBuf>);

impl Drop for Scratch {
    fn drop(&mut self) {
        if let Some(p) = self.0.take() {
            let _ = std::fs::remove_file(p);
        }
    }
}

/// Runs `rally model import`.
pub fn run(args: &ImportArgs) -> Result<(), CliError> {
    let ImportSource::Myosuite = args.source;
    let data = data_dir();
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| data.join(MYOCHALLENGE_FILE));
    // Absolute paths: the script runs in the temporary directory.
    let absolute = |p: &Path| {
        std::path::absolute(p).map_err(|e| CliError::Usage(format!("{}: {e}", p.display())))
    };
    let out = absolute(&out)?;
    let python = match &args.python {
        // A bare name is looked up on PATH; a path is made absolute.
        Some(p) if p.components().count() > 1 => given_python(&absolute(p)?)?,
        Some(p) => given_python(p)?,
        None => venv_python(&absolute(&data)?.join("venv-myosuite"))?,
    };
    let dir = out
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let name = out
        .file_name()
        .ok_or_else(|| CliError::Usage(format!("--out {}: not a file name", out.display())))?;
    let mut partial = Scratch(Some(dir.join(format!(
        ".{}.partial-{}",
        name.to_string_lossy(),
        std::process::id()
    ))));
    let script = Scratch(Some(
        std::env::temp_dir().join(format!("rally-myosuite-import-{}.py", std::process::id())),
    ));
    let script_path = script.0.as_deref().expect("set");
    let partial_path = partial.0.clone().expect("set");
    std::fs::write(script_path, IMPORT_SCRIPT)
        .with_context(|| format!("cannot write {}", script_path.display()))?;

    let bar = spinner("MyoSuite builds the challenge's model; checking it against MuJoCo");
    // In the temporary directory: MuJoCo writes its MUJOCO_LOG.TXT where it runs.
    let run = Command::new(&python)
        .arg(script_path)
        .arg(&partial_path)
        .current_dir(std::env::temp_dir())
        .output();
    bar.finish_and_clear();
    let run = run.with_context(|| format!("cannot run {}", python.display()))?;
    if !run.status.success() {
        return Err(CliError::Failed(anyhow::anyhow!(
            "the import failed (nothing written to {}):\n{}",
            out.display(),
            stderr_tail(&run.stderr)
        )));
    }
    let summary: serde_json::Value = String::from_utf8_lossy(&run.stdout)
        .lines()
        .last()
        .and_then(|l| serde_json::from_str(l).ok())
        .unwrap_or(serde_json::Value::Null);
    // Our own loader must take it, or nothing is written.
    let model = sim::mjcf::load(&partial_path, &|p| std::fs::read_to_string(p)).map_err(|e| {
        CliError::Failed(anyhow::anyhow!(
            "MyoSuite wrote a model muscle-rally cannot load (nothing written to {}): {e}",
            out.display()
        ))
    })?;
    std::fs::rename(&partial_path, &out)
        .with_context(|| format!("cannot move the model to {}", out.display()))?;
    partial.0 = None;
    println!(
        "wrote {}: MyoSuite {} (myo_sim {}, MuJoCo {}), {} joints ({} DoF, {} coupled), {} muscles + {} servos, {} tendons",
        out.display(),
        summary["myosuite"].as_str().unwrap_or("?"),
        summary["myo_sim"].as_str().unwrap_or("?"),
        summary["mujoco"].as_str().unwrap_or("?"),
        model.joints.len(),
        model.nv,
        model.couplings.len(),
        model.muscles().count(),
        model.actuators.len() - model.muscles().count(),
        model.tendons.len(),
    );
    if let Some(digest) = super::file_sha256(&out) {
        println!("sha256 {digest}");
    }
    println!("use it with --model myochallenge (e.g. rally model inspect myochallenge)");
    Ok(())
}
