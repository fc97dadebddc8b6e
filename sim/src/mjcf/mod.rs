//! MJCF loader for the subset of MuJoCo's format that our robots use (issue 3): `<mujoco>`,
//! `<compiler>`, `<option>`, nested `<default>` classes (`class`, `childclass`), `<include>`, the
//! `<worldbody>` tree (`pos`/`quat`/`euler`/`axisangle`, `<inertial>` or inertia from geoms, hinge,
//! slide and free joints, sites, sphere/capsule/cylinder/box geoms), spatial tendons through sites,
//! `<general>`/`<muscle>`/`<position>` actuators with MuJoCo's parameter layout, `<equality><joint
//! polycoef>` and `<keyframe>`. Anything else is an error naming the file, line, element and attribute.
//!
//! No I/O of its own: included files are read through the `read` function the caller passes.
//!
//! Two stages, as MuJoCo's parser and compiler: `reader` turns the XML into elements with their
//! source lines, includes and default classes; `compiler` builds the `Model` (bodies, inertia,
//! joints, geoms and sites, tendons, actuators, equalities, keyframes).

mod compiler;
mod reader;

use std::fmt;
use std::path::Path;

use crate::model::Model;
use compiler::compile;
use reader::{parse_tree, read_tree, Nesting};

/// A model that could not be loaded: where and why.
#[derive(Debug, Clone, PartialEq)]
pub struct MjcfError {
    /// File the problem is in.
    pub file: String,
    /// 1-based line (0 when the file could not be read at all).
    pub line: u32,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for MjcfError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line > 0 {
            write!(f, "{}:{}: {}", self.file, self.line, self.message)
        } else {
            write!(f, "{}: {}", self.file, self.message)
        }
    }
}

impl std::error::Error for MjcfError {}

type Result<T> = std::result::Result<T, MjcfError>;

/// Loads the model file at `path`, reading it and anything it includes through `read`.
pub fn load(path: &Path, read: &dyn Fn(&Path) -> std::io::Result<String>) -> Result<Model> {
    let files = std::cell::Cell::new(0);
    let root = read_tree(
        path,
        read,
        Nesting {
            depth: 0,
            files: &files,
        },
        None,
    )?;
    compile(&root)
}

/// Parses a model from a string (`name` is used in messages; `<include>` is refused).
pub fn parse_str(text: &str, name: &str) -> Result<Model> {
    let no_files = |p: &Path| -> std::io::Result<String> {
        Err(std::io::Error::new(
            std::io::ErrorKind::Unsupported,
            format!("cannot include {} from a string", p.display()),
        ))
    };
    let files = std::cell::Cell::new(0);
    let root = parse_tree(
        text,
        Path::new(name),
        &no_files,
        Nesting {
            depth: 0,
            files: &files,
        },
    )?;
    compile(&root)
}
