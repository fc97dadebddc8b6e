//! MJCF loader for the subset of MuJoCo's format that our robots use (issue 3): `<mujoco>`,
//! `<compiler>`, `<option>`, nested `<default>` classes (`class`, `childclass`), `<include>`, the
//! `<worldbody>` tree (`pos`/`quat`/`euler`/`axisangle`, `<inertial>` or inertia from geoms, hinge,
//! slide and free joints, sites, sphere/capsule/cylinder/box geoms), spatial tendons through sites,
//! `<general>`/`<muscle>`/`<position>` actuators with MuJoCo's parameter layout, `<equality><joint
//! polycoef>` and `<keyframe>`. Anything else is an error naming the file, line, element and attribute.
//!
//! No I/O of its own: included files are read through the `read` function the caller passes.

use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use nalgebra::{Matrix3, Quaternion, SymmetricEigen, UnitQuaternion, Vector3};

use crate::model::*;
use crate::muscle::{ActivationParams, MuscleParams};

type V3 = Vector3<f64>;

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

/// Where an element came from.
#[derive(Debug, Clone)]
struct Src {
    file: Rc<str>,
    line: u32,
}

impl Src {
    fn err(&self, message: impl Into<String>) -> MjcfError {
        MjcfError {
            file: self.file.to_string(),
            line: self.line,
            message: message.into(),
        }
    }
}

/// An owned XML element with includes already spliced in.
#[derive(Debug, Clone)]
struct Elem {
    name: String,
    attrs: Vec<(String, String)>,
    children: Vec<Elem>,
    src: Src,
}

impl Elem {
    fn attr(&self, key: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    fn check_attrs(&self, allowed: &[&str]) -> Result<()> {
        for (k, _) in &self.attrs {
            if !allowed.contains(&k.as_str()) {
                return Err(self.src.err(format!(
                    "<{}>: unsupported attribute '{k}' (supported: {})",
                    self.name,
                    allowed.join(", ")
                )));
            }
        }
        Ok(())
    }

    fn unsupported(&self, parent: &str) -> MjcfError {
        self.src.err(format!(
            "<{}> inside <{parent}> is not supported by muscle-rally's MJCF loader",
            self.name
        ))
    }
}

const MAX_INCLUDE_DEPTH: usize = 16;

/// Loads the model file at `path`, reading it and anything it includes through `read`.
pub fn load(path: &Path, read: &dyn Fn(&Path) -> std::io::Result<String>) -> Result<Model> {
    let root = read_tree(path, read, 0, None)?;
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
    let root = parse_tree(text, Path::new(name), &no_files, 0)?;
    compile(&root)
}

fn read_tree(
    path: &Path,
    read: &dyn Fn(&Path) -> std::io::Result<String>,
    depth: usize,
    from: Option<&Src>,
) -> Result<Elem> {
    let text = read(path).map_err(|e| {
        let msg = format!("cannot read {}: {e}", path.display());
        match from {
            Some(src) => src.err(msg),
            None => MjcfError {
                file: path.display().to_string(),
                line: 0,
                message: msg,
            },
        }
    })?;
    parse_tree(&text, path, read, depth)
}

fn parse_tree(
    text: &str,
    path: &Path,
    read: &dyn Fn(&Path) -> std::io::Result<String>,
    depth: usize,
) -> Result<Elem> {
    let file: Rc<str> = Rc::from(path.display().to_string());
    let doc = roxmltree::Document::parse(text).map_err(|e| MjcfError {
        file: file.to_string(),
        line: e.pos().row,
        message: format!("malformed XML: {e}"),
    })?;
    let root = doc.root_element();
    let lines = LineIndex::new(text);
    let src = Src {
        file: file.clone(),
        line: lines.line(root.range().start),
    };
    if root.tag_name().name() != "mujoco" {
        return Err(src.err(format!(
            "the root element is <{}>; an MJCF model starts with <mujoco>",
            root.tag_name().name()
        )));
    }
    convert(&lines, root, &file, path, read, depth)
}

/// Byte offset → 1-based line, by binary search over the line starts (roxmltree's own lookup scans
/// the text from the start each time).
struct LineIndex(Vec<usize>);

impl LineIndex {
    fn new(text: &str) -> LineIndex {
        LineIndex(
            std::iter::once(0)
                .chain(text.match_indices('\n').map(|(i, _)| i + 1))
                .collect(),
        )
    }

    fn line(&self, offset: usize) -> u32 {
        self.0.partition_point(|&start| start <= offset) as u32
    }
}

fn convert(
    lines: &LineIndex,
    node: roxmltree::Node,
    file: &Rc<str>,
    path: &Path,
    read: &dyn Fn(&Path) -> std::io::Result<String>,
    depth: usize,
) -> Result<Elem> {
    let src = Src {
        file: file.clone(),
        line: lines.line(node.range().start),
    };
    let mut children = Vec::new();
    for child in node.children().filter(|n| n.is_element()) {
        if child.tag_name().name() == "include" {
            let csrc = Src {
                file: file.clone(),
                line: lines.line(child.range().start),
            };
            let Some(f) = child.attribute("file") else {
                return Err(csrc.err("<include> needs a 'file' attribute"));
            };
            if let Some(a) = child.attributes().find(|a| a.name() != "file") {
                return Err(csrc.err(format!("<include>: unsupported attribute '{}'", a.name())));
            }
            if depth >= MAX_INCLUDE_DEPTH {
                return Err(csrc.err(format!("<include file=\"{f}\">: includes nested more than {MAX_INCLUDE_DEPTH} deep (a cycle?)")));
            }
            let target: PathBuf = path.parent().unwrap_or(Path::new("")).join(f);
            let included = read_tree(&target, read, depth + 1, Some(&csrc))?;
            children.extend(included.children);
        } else {
            children.push(convert(lines, child, file, path, read, depth)?);
        }
    }
    Ok(Elem {
        name: node.tag_name().name().to_string(),
        attrs: node
            .attributes()
            .map(|a| (a.name().to_string(), a.value().to_string()))
            .collect(),
        children,
        src,
    })
}

// ---------------------------------------------------------------------------------------------
// Attribute parsing

fn parse_numbers(e: &Elem, key: &str, value: &str) -> Result<Vec<f64>> {
    value
        .split_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    e.src.err(format!(
                        "<{}> {key}=\"{value}\": '{t}' is not a finite number",
                        e.name
                    ))
                })
        })
        .collect()
}

/// Attributes of an element, falling back to its default class.
struct Attrs<'a> {
    elem: &'a Elem,
    defaults: Option<&'a HashMap<String, String>>,
}

impl<'a> Attrs<'a> {
    fn raw(&self, key: &str) -> Option<&'a str> {
        self.elem
            .attr(key)
            .or_else(|| self.defaults.and_then(|d| d.get(key)).map(|s| s.as_str()))
    }

    fn nums(&self, key: &str) -> Result<Option<Vec<f64>>> {
        self.raw(key)
            .map(|v| parse_numbers(self.elem, key, v))
            .transpose()
    }

    fn arr<const N: usize>(&self, key: &str) -> Result<Option<[f64; N]>> {
        match self.nums(key)? {
            None => Ok(None),
            Some(v) if v.len() == N => Ok(Some(std::array::from_fn(|i| v[i]))),
            Some(v) => Err(self.elem.src.err(format!(
                "<{}> {key}: expected {N} numbers, got {}",
                self.elem.name,
                v.len()
            ))),
        }
    }

    /// Up to N numbers; missing trailing entries keep `init`'s values (MuJoCo's rule for prm arrays).
    fn prefix<const N: usize>(&self, key: &str, init: [f64; N]) -> Result<[f64; N]> {
        let mut out = init;
        if let Some(v) = self.nums(key)? {
            if v.len() > N {
                return Err(self.elem.src.err(format!(
                    "<{}> {key}: at most {N} numbers, got {}",
                    self.elem.name,
                    v.len()
                )));
            }
            out[..v.len()].copy_from_slice(&v);
        }
        Ok(out)
    }

    fn f64(&self, key: &str) -> Result<Option<f64>> {
        Ok(self.arr::<1>(key)?.map(|a| a[0]))
    }

    fn f64_or(&self, key: &str, default: f64) -> Result<f64> {
        Ok(self.f64(key)?.unwrap_or(default))
    }

    fn bool_auto(&self, key: &str) -> Result<Option<bool>> {
        match self.raw(key) {
            None | Some("auto") => Ok(None),
            Some("true") => Ok(Some(true)),
            Some("false") => Ok(Some(false)),
            Some(v) => Err(self.elem.src.err(format!(
                "<{}> {key}=\"{v}\": expected true, false or auto",
                self.elem.name
            ))),
        }
    }

    fn choice<'c>(&self, key: &str, options: &[&'c str], default: &'c str) -> Result<&'c str> {
        match self.raw(key) {
            None => Ok(default),
            Some(v) => options.iter().copied().find(|o| *o == v).ok_or_else(|| {
                self.elem.src.err(format!(
                    "<{}> {key}=\"{v}\": supported values are {}",
                    self.elem.name,
                    options.join(", ")
                ))
            }),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Defaults

/// Attribute defaults of one class, per element kind.
#[derive(Debug, Clone, Default)]
struct ClassDefaults {
    kinds: HashMap<String, HashMap<String, String>>,
}

const DEFAULTABLE: [&str; 7] = [
    "joint", "geom", "site", "muscle", "general", "position", "tendon",
];

fn collect_defaults(
    e: &Elem,
    parent: &ClassDefaults,
    out: &mut HashMap<String, ClassDefaults>,
    top: bool,
) -> Result<()> {
    e.check_attrs(&["class"])?;
    let class = match (e.attr("class"), top) {
        (Some(c), _) => c.to_string(),
        (None, true) => "main".to_string(),
        (None, false) => return Err(e.src.err("a nested <default> needs a 'class' attribute")),
    };
    if out.contains_key(&class) {
        return Err(e
            .src
            .err(format!("default class '{class}' is defined twice")));
    }
    let mut mine = parent.clone();
    for child in &e.children {
        if DEFAULTABLE.contains(&child.name.as_str()) {
            let map = mine.kinds.entry(child.name.clone()).or_default();
            for (k, v) in &child.attrs {
                if k == "class" || k == "name" {
                    return Err(child
                        .src
                        .err(format!("<{}> in a <default> cannot have '{k}'", child.name)));
                }
                map.insert(k.clone(), v.clone());
            }
        } else if child.name != "default" {
            return Err(child.unsupported("default"));
        }
    }
    out.insert(class.clone(), mine.clone());
    for child in e.children.iter().filter(|c| c.name == "default") {
        collect_defaults(child, &mine, out, false)?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Compilation

struct Compiler {
    degrees: bool,
    autolimits: bool,
    defaults: HashMap<String, ClassDefaults>,
    model: Model,
    body_has_inertial: Vec<bool>,
}

fn quat_wxyz(q: [f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(q[0], q[1], q[2], q[3]))
}

impl Compiler {
    fn attrs<'a>(
        &'a self,
        e: &'a Elem,
        kind: &str,
        childclass: Option<&'a str>,
    ) -> Result<Attrs<'a>> {
        let class = e.attr("class").or(childclass).unwrap_or("main");
        let defaults = match self.defaults.get(class) {
            Some(d) => d.kinds.get(kind),
            None if class == "main" => None,
            None => {
                return Err(e
                    .src
                    .err(format!("<{}>: unknown default class '{class}'", e.name)))
            }
        };
        Ok(Attrs { elem: e, defaults })
    }

    fn angle(&self, x: f64) -> f64 {
        if self.degrees {
            x.to_radians()
        } else {
            x
        }
    }

    /// Orientation from `quat`, `euler` (intrinsic xyz) or `axisangle`; identity if none.
    fn orientation(&self, a: &Attrs) -> Result<UnitQuaternion<f64>> {
        let given: Vec<&str> = ["quat", "euler", "axisangle"]
            .into_iter()
            .filter(|k| a.raw(k).is_some())
            .collect();
        if given.len() > 1 {
            return Err(a.elem.src.err(format!(
                "<{}>: give only one of {}",
                a.elem.name,
                given.join(", ")
            )));
        }
        if let Some(q) = a.arr::<4>("quat")? {
            if q.iter().map(|x| x * x).sum::<f64>() < 1e-20 {
                return Err(a
                    .elem
                    .src
                    .err(format!("<{}> quat: zero quaternion", a.elem.name)));
            }
            return Ok(quat_wxyz(q));
        }
        if let Some(e) = a.arr::<3>("euler")? {
            // MuJoCo's default eulerseq "xyz": intrinsic rotations about x, then y', then z''.
            let rx = UnitQuaternion::from_axis_angle(&V3::x_axis(), self.angle(e[0]));
            let ry = UnitQuaternion::from_axis_angle(&V3::y_axis(), self.angle(e[1]));
            let rz = UnitQuaternion::from_axis_angle(&V3::z_axis(), self.angle(e[2]));
            return Ok(rx * ry * rz);
        }
        if let Some(aa) = a.arr::<4>("axisangle")? {
            let axis = V3::new(aa[0], aa[1], aa[2]);
            let n = axis.norm();
            if n < 1e-12 {
                return Err(a
                    .elem
                    .src
                    .err(format!("<{}> axisangle: zero axis", a.elem.name)));
            }
            return Ok(UnitQuaternion::from_scaled_axis(
                axis / n * self.angle(aa[3]),
            ));
        }
        Ok(UnitQuaternion::identity())
    }

    fn body(&mut self, e: &Elem, parent: usize, childclass: Option<&str>) -> Result<()> {
        e.check_attrs(&["name", "pos", "quat", "euler", "axisangle", "childclass"])?;
        let a = Attrs {
            elem: e,
            defaults: None,
        };
        let childclass = e.attr("childclass").or(childclass);
        if let Some(c) = e.attr("childclass") {
            if c != "main" && !self.defaults.contains_key(c) {
                return Err(e.src.err(format!("<body>: unknown childclass '{c}'")));
            }
        }
        let id = self.model.bodies.len();
        let name = e.attr("name").unwrap_or("").to_string();
        if !name.is_empty() && self.model.bodies.iter().any(|b| b.name == name) {
            return Err(e.src.err(format!("<body>: duplicate name '{name}'")));
        }
        self.model.bodies.push(Body {
            name,
            parent: Some(parent),
            pos: V3::from(a.arr::<3>("pos")?.unwrap_or([0.0; 3])),
            quat: self.orientation(&a)?,
            mass: 0.0,
            com: V3::zeros(),
            inertia: Matrix3::zeros(),
            first_joint: self.model.joints.len(),
            joint_count: 0,
            source: format!("{}:{}", e.src.file, e.src.line),
        });
        self.body_has_inertial.push(false);
        let mut children = Vec::new();
        for c in &e.children {
            match c.name.as_str() {
                "inertial" => self.inertial(c, id)?,
                "joint" => self.joint(c, id, childclass, false)?,
                "freejoint" => self.joint(c, id, childclass, true)?,
                "geom" => self.geom(c, id, childclass)?,
                "site" => self.site(c, id, childclass)?,
                "body" => children.push(c),
                _ => return Err(c.unsupported("body")),
            }
        }
        for c in children {
            self.body(c, id, childclass)?;
        }
        Ok(())
    }

    fn inertial(&mut self, e: &Elem, body: usize) -> Result<()> {
        e.check_attrs(&[
            "pos",
            "quat",
            "euler",
            "axisangle",
            "mass",
            "diaginertia",
            "fullinertia",
        ])?;
        if self.body_has_inertial[body] {
            return Err(e.src.err("a body has at most one <inertial>"));
        }
        let a = Attrs {
            elem: e,
            defaults: None,
        };
        let mass = a
            .f64("mass")?
            .ok_or_else(|| e.src.err("<inertial> needs 'mass'"))?;
        let rot = self.orientation(&a)?.to_rotation_matrix();
        let local = match (a.arr::<3>("diaginertia")?, a.arr::<6>("fullinertia")?) {
            (Some(d), None) => Matrix3::from_diagonal(&V3::from(d)),
            (None, Some(f)) => Matrix3::new(f[0], f[3], f[4], f[3], f[1], f[5], f[4], f[5], f[2]),
            (Some(_), Some(_)) => {
                return Err(e
                    .src
                    .err("<inertial>: give diaginertia or fullinertia, not both"))
            }
            (None, None) => {
                return Err(e.src.err("<inertial> needs 'diaginertia' or 'fullinertia'"))
            }
        };
        let b = &mut self.model.bodies[body];
        b.mass = mass;
        b.com = V3::from(a.arr::<3>("pos")?.unwrap_or([0.0; 3]));
        b.inertia = rot.matrix() * local * rot.matrix().transpose();
        self.body_has_inertial[body] = true;
        check_mass(e, mass, &b.inertia)
    }

    fn joint(&mut self, e: &Elem, body: usize, childclass: Option<&str>, free: bool) -> Result<()> {
        let a = if free {
            e.check_attrs(&["name"])?;
            Attrs {
                elem: e,
                defaults: None,
            }
        } else {
            e.check_attrs(&[
                "name",
                "class",
                "type",
                "pos",
                "axis",
                "range",
                "limited",
                "damping",
                "armature",
                "stiffness",
                "ref",
                "springref",
                "group",
                "solreflimit",
                "solimplimit",
            ])?;
            self.attrs(e, "joint", childclass)?
        };
        let kind = if free {
            JointKind::Free
        } else {
            match a.choice("type", &["hinge", "slide", "free"], "hinge")? {
                "hinge" => JointKind::Hinge,
                "slide" => JointKind::Slide,
                _ => JointKind::Free,
            }
        };
        if kind == JointKind::Free && self.model.bodies[body].parent != Some(0) {
            return Err(e
                .src
                .err("a free joint can only move a body whose parent is the world"));
        }
        if kind == JointKind::Free && self.model.bodies[body].joint_count > 0 {
            return Err(e.src.err("a free joint must be its body's only joint"));
        }
        let name = e.attr("name").unwrap_or("").to_string();
        if !name.is_empty() && self.model.joints.iter().any(|j| j.name == name) {
            return Err(e.src.err(format!("<joint>: duplicate name '{name}'")));
        }
        let angular = kind == JointKind::Hinge;
        let conv = |x: f64| if angular { self.angle(x) } else { x };
        let axis = V3::from(a.arr::<3>("axis")?.unwrap_or([0.0, 0.0, 1.0]));
        if axis.norm() < 1e-12 {
            return Err(e.src.err("<joint> axis: zero vector"));
        }
        let range = a.arr::<2>("range")?;
        let limited = match a.bool_auto("limited")? {
            Some(l) => l,
            None => self.autolimits && range.is_some(),
        };
        if limited && range.is_none() {
            return Err(e.src.err("<joint> is limited but has no range"));
        }
        let range = match (limited, range) {
            (true, Some(r)) => {
                if r[0] >= r[1] {
                    return Err(e.src.err(format!(
                        "<joint> range: lower {} must be below upper {}",
                        r[0], r[1]
                    )));
                }
                Some([conv(r[0]), conv(r[1])])
            }
            _ => None,
        };
        let nonneg = |key: &str| -> Result<f64> {
            let v = a.f64_or(key, 0.0)?;
            if v < 0.0 {
                return Err(e.src.err(format!("<joint> {key}: must not be negative")));
            }
            Ok(v)
        };
        let reference = conv(a.f64_or("ref", 0.0)?);
        let limit_solref = a
            .arr::<2>("solreflimit")?
            .unwrap_or(crate::dynamics::LIMIT_SOLREF);
        if limit_solref[0] <= 0.0 || limit_solref[1] <= 0.0 {
            return Err(e.src.err("<joint> solreflimit: only the standard form (time constant, damping ratio > 0) is supported"));
        }
        let limit_solimp = match a.nums("solimplimit")? {
            None => crate::dynamics::LIMIT_SOLIMP,
            Some(v) if v.len() == 3 || (v.len() == 5 && v[3] == 0.5 && v[4] == 2.0) => {
                [v[0], v[1], v[2]]
            }
            Some(_) => {
                return Err(e.src.err(
                    "<joint> solimplimit: give d0 dwidth width (midpoint 0.5 and power 2 only)",
                ))
            }
        };
        if !(0.0 < limit_solimp[0]
            && limit_solimp[0] < 1.0
            && 0.0 < limit_solimp[1]
            && limit_solimp[1] < 1.0
            && limit_solimp[2] > 0.0)
        {
            return Err(e
                .src
                .err("<joint> solimplimit: need 0 < d0, dwidth < 1 and width > 0"));
        }
        let joint = Joint {
            name,
            kind,
            body,
            pos: V3::from(a.arr::<3>("pos")?.unwrap_or([0.0; 3])),
            axis: axis.normalize(),
            range,
            damping: nonneg("damping")?,
            armature: nonneg("armature")?,
            stiffness: nonneg("stiffness")?,
            springref: a.f64("springref")?.map(conv).unwrap_or(0.0),
            reference,
            limit_solref,
            limit_solimp,
            qpos_adr: self.model.nq,
            dof_adr: self.model.nv,
        };
        self.model.nq += kind.nq();
        self.model.nv += kind.nv();
        self.model.joints.push(joint);
        self.model.bodies[body].joint_count += 1;
        Ok(())
    }

    fn geom(&mut self, e: &Elem, body: usize, childclass: Option<&str>) -> Result<()> {
        e.check_attrs(&[
            "name",
            "class",
            "type",
            "size",
            "pos",
            "quat",
            "euler",
            "axisangle",
            "fromto",
            "mass",
            "density",
            "rgba",
            "group",
            "contype",
            "conaffinity",
            "condim",
            "friction",
            "solref",
            "solimp",
            "margin",
            "gap",
            "priority",
        ])?;
        let a = self.attrs(e, "geom", childclass)?;
        let kind = match a.choice(
            "type",
            &["sphere", "capsule", "cylinder", "box", "plane"],
            "sphere",
        )? {
            "sphere" => GeomKind::Sphere,
            "capsule" => GeomKind::Capsule,
            "cylinder" => GeomKind::Cylinder,
            "box" => GeomKind::Box,
            _ => GeomKind::Plane,
        };
        let mut size = [0.0; 3];
        if let Some(v) = a.nums("size")? {
            if v.len() > 3 {
                return Err(e.src.err("<geom> size: at most 3 numbers"));
            }
            size[..v.len()].copy_from_slice(&v);
        }
        let (mut pos, mut quat) = (
            V3::from(a.arr::<3>("pos")?.unwrap_or([0.0; 3])),
            self.orientation(&a)?,
        );
        if let Some(ft) = a.arr::<6>("fromto")? {
            if !matches!(kind, GeomKind::Capsule | GeomKind::Cylinder) {
                return Err(e.src.err("<geom> fromto: only for capsules and cylinders"));
            }
            let (p0, p1) = (V3::new(ft[0], ft[1], ft[2]), V3::new(ft[3], ft[4], ft[5]));
            let d = p1 - p0;
            if d.norm() < 1e-12 {
                return Err(e.src.err("<geom> fromto: the two ends coincide"));
            }
            pos = 0.5 * (p0 + p1);
            quat = UnitQuaternion::rotation_between(&V3::z(), &d).unwrap_or_else(|| {
                UnitQuaternion::from_axis_angle(&V3::x_axis(), std::f64::consts::PI)
            });
            size[1] = 0.5 * d.norm();
        }
        let needed = match kind {
            GeomKind::Sphere => 1,
            GeomKind::Capsule | GeomKind::Cylinder => 2,
            GeomKind::Box => 3,
            GeomKind::Plane => 0,
        };
        if size[..needed].iter().any(|s| *s <= 0.0) {
            return Err(e.src.err(
                format!("<geom> size: a {:?} needs {needed} positive sizes", kind).to_lowercase(),
            ));
        }
        if kind == GeomKind::Plane && body != 0 {
            return Err(e
                .src
                .err("<geom type=\"plane\">: planes belong to the worldbody"));
        }
        let volume = geom_volume(kind, &size);
        let mass = match (a.f64("mass")?, a.f64("density")?) {
            (Some(m), _) => m,
            (None, Some(d)) => d * volume,
            (None, None) => 1000.0 * volume,
        };
        if mass < 0.0 {
            return Err(e.src.err("<geom> mass/density: must not be negative"));
        }
        self.model.geoms.push(Geom {
            name: e.attr("name").unwrap_or("").to_string(),
            body,
            kind,
            size,
            pos,
            quat,
            mass,
        });
        Ok(())
    }

    fn site(&mut self, e: &Elem, body: usize, childclass: Option<&str>) -> Result<()> {
        e.check_attrs(&[
            "name",
            "class",
            "type",
            "size",
            "pos",
            "quat",
            "euler",
            "axisangle",
            "rgba",
            "group",
        ])?;
        let a = self.attrs(e, "site", childclass)?;
        self.orientation(&a)?;
        let name = e.attr("name").unwrap_or("").to_string();
        if !name.is_empty() && self.model.sites.iter().any(|s| s.name == name) {
            return Err(e.src.err(format!("<site>: duplicate name '{name}'")));
        }
        self.model.sites.push(Site {
            name,
            body,
            pos: V3::from(a.arr::<3>("pos")?.unwrap_or([0.0; 3])),
        });
        Ok(())
    }

    fn tendons(&mut self, e: &Elem) -> Result<()> {
        e.check_attrs(&[])?;
        for t in &e.children {
            if t.name != "spatial" {
                return Err(t.unsupported("tendon"));
            }
            t.check_attrs(&["name", "class", "width", "rgba", "group"])?;
            let name = t.attr("name").unwrap_or("").to_string();
            if name.is_empty() {
                return Err(t.src.err("<spatial> needs a name"));
            }
            if self.model.tendons.iter().any(|x| x.name == name) {
                return Err(t.src.err(format!("<spatial>: duplicate name '{name}'")));
            }
            let mut sites = Vec::new();
            for p in &t.children {
                match p.name.as_str() {
                    "site" => {
                        p.check_attrs(&["site"])?;
                        let s = p.attr("site").ok_or_else(|| p.src.err("<site> in a tendon needs 'site'"))?;
                        let id = self.model.site(s).ok_or_else(|| p.src.err(format!("tendon '{name}': no site named '{s}'")))?;
                        sites.push(id);
                    }
                    "geom" | "pulley" => {
                        return Err(p.src.err(format!(
                            "tendon '{name}': <{}> (wrapping) is not supported yet; paths go through sites only",
                            p.name
                        )))
                    }
                    _ => return Err(p.unsupported("spatial")),
                }
            }
            if sites.len() < 2 {
                return Err(t
                    .src
                    .err(format!("tendon '{name}': a path needs at least two sites")));
            }
            self.model.tendons.push(Tendon { name, sites });
        }
        Ok(())
    }

    fn transmission(&self, a: &Attrs) -> Result<Transmission> {
        let e = a.elem;
        match (e.attr("tendon"), e.attr("joint")) {
            (Some(t), None) => self
                .model
                .tendons
                .iter()
                .position(|x| x.name == t)
                .map(Transmission::Tendon)
                .ok_or_else(|| e.src.err(format!("<{}>: no tendon named '{t}'", e.name))),
            (None, Some(j)) => {
                let id = self
                    .model
                    .joint(j)
                    .ok_or_else(|| e.src.err(format!("<{}>: no joint named '{j}'", e.name)))?;
                if self.model.joints[id].kind == JointKind::Free {
                    return Err(e
                        .src
                        .err(format!("<{}>: cannot drive the free joint '{j}'", e.name)));
                }
                Ok(Transmission::Joint(id))
            }
            (Some(_), Some(_)) => Err(e.src.err(format!(
                "<{}>: give either 'tendon' or 'joint', not both",
                e.name
            ))),
            (None, None) => Err(e
                .src
                .err(format!("<{}> needs a 'tendon' or a 'joint'", e.name))),
        }
    }

    fn ctrlrange(&self, a: &Attrs, default_limited: Option<[f64; 2]>) -> Result<Option<[f64; 2]>> {
        let range = a.arr::<2>("ctrlrange")?;
        let limited = match a.bool_auto("ctrllimited")? {
            Some(l) => l,
            None => {
                range.is_some() && self.autolimits || (range.is_none() && default_limited.is_some())
            }
        };
        if !limited {
            return Ok(None);
        }
        let r = range
            .or(default_limited)
            .ok_or_else(|| a.elem.src.err("ctrllimited without ctrlrange"))?;
        if r[0] >= r[1] {
            return Err(a.elem.src.err(format!(
                "<{}> ctrlrange: lower must be below upper",
                a.elem.name
            )));
        }
        Ok(Some(r))
    }

    fn actuators(&mut self, e: &Elem) -> Result<()> {
        e.check_attrs(&[])?;
        for act in &e.children {
            let actuator = match act.name.as_str() {
                "muscle" => self.muscle(act)?,
                "position" => self.position(act)?,
                "general" => self.general(act)?,
                _ => return Err(act.unsupported("actuator")),
            };
            if actuator.name.is_empty() {
                return Err(act.src.err(format!("<{}> needs a name", act.name)));
            }
            if self.model.actuator(&actuator.name).is_some() {
                return Err(act.src.err(format!(
                    "<{}>: duplicate name '{}'",
                    act.name, actuator.name
                )));
            }
            self.model.actuators.push(actuator);
        }
        Ok(())
    }

    fn lengthrange(&self, a: &Attrs) -> Result<Option<[f64; 2]>> {
        match a.arr::<2>("lengthrange")? {
            Some(r) if r[0] < r[1] && r[0] >= 0.0 => Ok(Some(r)),
            Some(_) => Err(a
                .elem
                .src
                .err(format!("<{}> lengthrange: need 0 ≤ min < max", a.elem.name))),
            None => Ok(None),
        }
    }

    fn muscle(&self, e: &Elem) -> Result<Actuator> {
        e.check_attrs(&[
            "name",
            "class",
            "tendon",
            "joint",
            "ctrlrange",
            "ctrllimited",
            "force",
            "scale",
            "lmin",
            "lmax",
            "vmax",
            "fpmax",
            "fvmax",
            "timeconst",
            "tausmooth",
            "range",
            "lengthrange",
            "group",
        ])?;
        let a = self.attrs(e, "muscle", None)?;
        let d = MuscleParams::DEFAULT;
        let range = a.arr::<2>("range")?.unwrap_or(d.range);
        let p = MuscleParams {
            range,
            force: a.f64_or("force", d.force)?,
            scale: a.f64_or("scale", d.scale)?,
            lmin: a.f64_or("lmin", d.lmin)?,
            lmax: a.f64_or("lmax", d.lmax)?,
            vmax: a.f64_or("vmax", d.vmax)?,
            fpmax: a.f64_or("fpmax", d.fpmax)?,
            fvmax: a.f64_or("fvmax", d.fvmax)?,
        };
        check_muscle(e, &p)?;
        let tc = a.arr::<2>("timeconst")?.unwrap_or([0.01, 0.04]);
        if tc[0] <= 0.0 || tc[1] <= 0.0 {
            return Err(e.src.err("<muscle> timeconst: both must be positive"));
        }
        let lr = self.lengthrange(&a)?;
        Ok(Actuator {
            name: e.attr("name").unwrap_or("").to_string(),
            transmission: self.transmission(&a)?,
            dynamics: Dynamics::Muscle(ActivationParams {
                tau_act: tc[0],
                tau_deact: tc[1],
                smoothing: a.f64_or("tausmooth", 0.0)?,
            }),
            gain: Gain::Muscle(p),
            bias: Bias::Muscle(p),
            ctrlrange: self.ctrlrange(&a, Some([0.0, 1.0]))?,
            lengthrange: lr.unwrap_or([0.0, 0.0]),
            lengthrange_given: lr.is_some(),
        })
    }

    fn position(&self, e: &Elem) -> Result<Actuator> {
        e.check_attrs(&[
            "name",
            "class",
            "joint",
            "tendon",
            "kp",
            "kv",
            "ctrlrange",
            "ctrllimited",
            "group",
        ])?;
        let a = self.attrs(e, "position", None)?;
        let kp = a.f64_or("kp", 1.0)?;
        let kv = a.f64_or("kv", 0.0)?;
        if kp < 0.0 || kv < 0.0 {
            return Err(e.src.err("<position> kp and kv must not be negative"));
        }
        Ok(Actuator {
            name: e.attr("name").unwrap_or("").to_string(),
            transmission: self.transmission(&a)?,
            dynamics: Dynamics::None,
            gain: Gain::Fixed(kp),
            bias: Bias::Affine([0.0, -kp, -kv]),
            ctrlrange: self.ctrlrange(&a, None)?,
            lengthrange: [0.0, 0.0],
            lengthrange_given: false,
        })
    }

    fn general(&self, e: &Elem) -> Result<Actuator> {
        e.check_attrs(&[
            "name",
            "class",
            "joint",
            "tendon",
            "dyntype",
            "gaintype",
            "biastype",
            "dynprm",
            "gainprm",
            "biasprm",
            "ctrlrange",
            "ctrllimited",
            "lengthrange",
            "group",
        ])?;
        let a = self.attrs(e, "general", None)?;
        let dynprm =
            a.prefix::<10>("dynprm", [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])?;
        let gainprm = a.prefix::<10>(
            "gainprm",
            [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        )?;
        let biasprm = a.prefix::<10>("biasprm", [0.0; 10])?;
        let dynamics = match a.choice("dyntype", &["none", "muscle"], "none")? {
            "none" => Dynamics::None,
            _ => Dynamics::Muscle(ActivationParams {
                tau_act: dynprm[0],
                tau_deact: dynprm[1],
                smoothing: dynprm[2],
            }),
        };
        let gain = match a.choice("gaintype", &["fixed", "muscle"], "fixed")? {
            "fixed" => Gain::Fixed(gainprm[0]),
            _ => {
                let p = MuscleParams::from_prm(&gainprm);
                check_muscle(e, &p)?;
                Gain::Muscle(p)
            }
        };
        let bias = match a.choice("biastype", &["none", "affine", "muscle"], "none")? {
            "none" => Bias::None,
            "affine" => Bias::Affine([biasprm[0], biasprm[1], biasprm[2]]),
            _ => Bias::Muscle(MuscleParams::from_prm(&biasprm)),
        };
        let lr = self.lengthrange(&a)?;
        Ok(Actuator {
            name: e.attr("name").unwrap_or("").to_string(),
            transmission: self.transmission(&a)?,
            dynamics,
            gain,
            bias,
            ctrlrange: self.ctrlrange(&a, None)?,
            lengthrange: lr.unwrap_or([0.0, 0.0]),
            lengthrange_given: lr.is_some(),
        })
    }

    fn equalities(&mut self, e: &Elem) -> Result<()> {
        e.check_attrs(&[])?;
        for q in &e.children {
            if q.name != "joint" {
                return Err(q.unsupported("equality"));
            }
            q.check_attrs(&[
                "name", "class", "joint1", "joint2", "polycoef", "active", "solref", "solimp",
            ])?;
            let a = Attrs {
                elem: q,
                defaults: None,
            };
            if a.choice("active", &["true", "false"], "true")? == "false" {
                continue;
            }
            let find = |key: &str| -> Result<usize> {
                let name = q
                    .attr(key)
                    .ok_or_else(|| q.src.err(format!("<joint> equality needs '{key}'")))?;
                let id = self.model.joint(name).ok_or_else(|| {
                    q.src
                        .err(format!("<joint> equality {key}: no joint named '{name}'"))
                })?;
                if self.model.joints[id].kind == JointKind::Free {
                    return Err(q
                        .src
                        .err(format!("<joint> equality {key}: '{name}' is a free joint")));
                }
                Ok(id)
            };
            let dependent = find("joint1")?;
            let independent = find("joint2")?;
            if dependent == independent {
                return Err(q
                    .src
                    .err("<joint> equality: joint1 and joint2 are the same joint"));
            }
            let coef = a.prefix::<5>("polycoef", [0.0, 1.0, 0.0, 0.0, 0.0])?;
            let c = Coupling {
                dependent,
                independent,
                coef,
            };
            let name = |j: usize| self.model.joints[j].name.clone();
            if self
                .model
                .couplings
                .iter()
                .any(|x| x.dependent == dependent)
            {
                return Err(q.src.err(format!(
                    "joint '{}' already follows another coupling",
                    name(dependent)
                )));
            }
            if self
                .model
                .couplings
                .iter()
                .any(|x| x.dependent == independent || x.independent == dependent)
            {
                return Err(q.src.err(format!(
                    "coupling chains are not supported: '{}' → '{}' links to another coupling; couple every dependent joint to an independent one",
                    name(independent),
                    name(dependent)
                )));
            }
            self.model.couplings.push(c);
        }
        Ok(())
    }

    fn keyframes(&mut self, e: &Elem) -> Result<()> {
        e.check_attrs(&[])?;
        for k in &e.children {
            if k.name != "key" {
                return Err(k.unsupported("keyframe"));
            }
            k.check_attrs(&["name", "qpos", "qvel"])?;
            let a = Attrs {
                elem: k,
                defaults: None,
            };
            let qpos = match a.nums("qpos")? {
                Some(q) if q.len() == self.model.nq => q,
                Some(q) => {
                    return Err(k.src.err(format!(
                        "<key> qpos: {} numbers for a model with nq = {}",
                        q.len(),
                        self.model.nq
                    )))
                }
                None => self.model.qpos0.clone(),
            };
            let qvel = match a.nums("qvel")? {
                Some(v) if v.len() == self.model.nv => v,
                Some(v) => {
                    return Err(k.src.err(format!(
                        "<key> qvel: {} numbers for a model with nv = {}",
                        v.len(),
                        self.model.nv
                    )))
                }
                None => vec![0.0; self.model.nv],
            };
            self.model.keyframes.push(Keyframe {
                name: k.attr("name").unwrap_or("").to_string(),
                qpos,
                qvel,
            });
        }
        Ok(())
    }

    /// Body inertia from geoms for bodies without `<inertial>` (MuJoCo's `inertiafromgeom="auto"`),
    /// then the moving-body mass check.
    fn finish_inertia(&mut self) -> Result<()> {
        for b in 1..self.model.bodies.len() {
            if !self.body_has_inertial[b] {
                let geoms: Vec<&Geom> = self.model.geoms.iter().filter(|g| g.body == b).collect();
                let (mass, com, inertia) = combine_geom_inertia(&geoms);
                let body = &mut self.model.bodies[b];
                body.mass = mass;
                body.com = com;
                body.inertia = inertia;
            }
            let body = &self.model.bodies[b];
            if body.joint_count > 0 {
                let eig = SymmetricEigen::new(body.inertia).eigenvalues;
                if body.mass <= 0.0 || eig.iter().any(|x| *x <= 0.0) {
                    return Err(MjcfError {
                        file: body.source.rsplit_once(':').map(|s| s.0).unwrap_or("").to_string(),
                        line: body.source.rsplit_once(':').and_then(|s| s.1.parse().ok()).unwrap_or(0),
                        message: format!(
                            "body '{}' moves (it has joints) but its mass ({}) or inertia is not positive: give it an <inertial> or geoms",
                            body.name, body.mass
                        ),
                    });
                }
            }
        }
        Ok(())
    }

    fn finish_dofs(&mut self) {
        let m = &mut self.model;
        m.qpos0 = vec![0.0; m.nq];
        m.dof_joint = vec![0; m.nv];
        m.dof_body = vec![0; m.nv];
        m.dof_parent = vec![None; m.nv];
        let mut last_dof_of_body: Vec<Option<usize>> = vec![None; m.bodies.len()];
        for b in 1..m.bodies.len() {
            let parent = m.bodies[b].parent.expect("non-world body");
            let mut prev = last_dof_of_body[parent];
            let (first, count) = (m.bodies[b].first_joint, m.bodies[b].joint_count);
            for j in first..first + count {
                let joint = &m.joints[j];
                match joint.kind {
                    JointKind::Free => {
                        let body = &m.bodies[b];
                        let q = body.quat.quaternion();
                        m.qpos0[joint.qpos_adr..joint.qpos_adr + 7].copy_from_slice(&[
                            body.pos.x, body.pos.y, body.pos.z, q.w, q.i, q.j, q.k,
                        ]);
                    }
                    _ => m.qpos0[joint.qpos_adr] = joint.reference,
                }
                for d in joint.dof_adr..joint.dof_adr + joint.kind.nv() {
                    m.dof_joint[d] = j;
                    m.dof_body[d] = b;
                    m.dof_parent[d] = prev;
                    prev = Some(d);
                }
            }
            last_dof_of_body[b] = prev;
        }
    }
}

fn check_mass(e: &Elem, mass: f64, inertia: &Matrix3<f64>) -> Result<()> {
    if mass <= 0.0 {
        return Err(e
            .src
            .err(format!("<inertial> mass {mass}: must be positive")));
    }
    let eig = SymmetricEigen::new(*inertia).eigenvalues;
    if eig.iter().any(|x| *x <= 0.0) {
        return Err(e
            .src
            .err("<inertial>: the inertia must be positive definite"));
    }
    Ok(())
}

fn check_muscle(e: &Elem, p: &MuscleParams) -> Result<()> {
    let bad = |what: &str| Err(e.src.err(format!("<{}>: {what}", e.name)));
    if p.range[0] >= p.range[1] || p.range[0] <= 0.0 {
        return bad("range: need 0 < range0 < range1");
    }
    if !(p.lmin < 1.0 && p.lmax > 1.0) {
        return bad("need lmin < 1 < lmax");
    }
    if p.vmax <= 0.0 || p.fpmax < 0.0 || p.fvmax < 1.0 {
        return bad("need vmax > 0, fpmax ≥ 0, fvmax ≥ 1");
    }
    if p.force == 0.0 {
        return bad("force must not be zero");
    }
    Ok(())
}

fn geom_volume(kind: GeomKind, s: &[f64; 3]) -> f64 {
    use std::f64::consts::PI;
    match kind {
        GeomKind::Sphere => 4.0 / 3.0 * PI * s[0].powi(3),
        GeomKind::Capsule => PI * s[0] * s[0] * (2.0 * s[1]) + 4.0 / 3.0 * PI * s[0].powi(3),
        GeomKind::Cylinder => PI * s[0] * s[0] * 2.0 * s[1],
        GeomKind::Box => 8.0 * s[0] * s[1] * s[2],
        GeomKind::Plane => 0.0,
    }
}

/// Principal inertia of a geom about its own centre, in its own frame (MuJoCo's formulas).
fn geom_inertia(g: &Geom) -> V3 {
    let s = &g.size;
    let m = g.mass;
    match g.kind {
        GeomKind::Sphere => V3::repeat(0.4 * m * s[0] * s[0]),
        GeomKind::Capsule => {
            let (r, h) = (s[0], 2.0 * s[1]);
            let vol = geom_volume(GeomKind::Capsule, s);
            let sphere = m * (4.0 / 3.0 * std::f64::consts::PI * r.powi(3)) / vol;
            let cyl = m - sphere;
            let ix = cyl * (3.0 * r * r + h * h) / 12.0
                + sphere * (0.4 * r * r + h * h / 4.0 + 3.0 * h * r / 8.0);
            let iz = cyl * r * r / 2.0 + sphere * 0.4 * r * r;
            V3::new(ix, ix, iz)
        }
        GeomKind::Cylinder => {
            let (r, h) = (s[0], 2.0 * s[1]);
            let ix = m * (3.0 * r * r + h * h) / 12.0;
            V3::new(ix, ix, m * r * r / 2.0)
        }
        GeomKind::Box => V3::new(
            m * (s[1] * s[1] + s[2] * s[2]) / 3.0,
            m * (s[0] * s[0] + s[2] * s[2]) / 3.0,
            m * (s[0] * s[0] + s[1] * s[1]) / 3.0,
        ),
        GeomKind::Plane => V3::zeros(),
    }
}

/// Mass, centre of mass and inertia about it (body frame) of a set of geoms.
fn combine_geom_inertia(geoms: &[&Geom]) -> (f64, V3, Matrix3<f64>) {
    let mass: f64 = geoms.iter().map(|g| g.mass).sum();
    if mass <= 0.0 {
        return (0.0, V3::zeros(), Matrix3::zeros());
    }
    let com = geoms.iter().map(|g| g.pos * g.mass).sum::<V3>() / mass;
    let mut inertia = Matrix3::zeros();
    for g in geoms {
        let r = g.quat.to_rotation_matrix();
        let local = Matrix3::from_diagonal(&geom_inertia(g));
        let d = g.pos - com;
        inertia += r.matrix() * local * r.matrix().transpose()
            + g.mass * (Matrix3::identity() * d.norm_squared() - d * d.transpose());
    }
    (mass, com, inertia)
}

fn compile(root: &Elem) -> Result<Model> {
    root.check_attrs(&["model"])?;
    let mut c = Compiler {
        degrees: true,
        autolimits: true,
        defaults: HashMap::new(),
        model: Model {
            name: root.attr("model").unwrap_or("").to_string(),
            timestep: 0.002,
            gravity: V3::new(0.0, 0.0, -9.81),
            bodies: vec![Body {
                name: "world".into(),
                parent: None,
                pos: V3::zeros(),
                quat: UnitQuaternion::identity(),
                mass: 0.0,
                com: V3::zeros(),
                inertia: Matrix3::zeros(),
                first_joint: 0,
                joint_count: 0,
                source: String::new(),
            }],
            joints: vec![],
            sites: vec![],
            geoms: vec![],
            tendons: vec![],
            actuators: vec![],
            couplings: vec![],
            keyframes: vec![],
            nq: 0,
            nv: 0,
            qpos0: vec![],
            dof_joint: vec![],
            dof_body: vec![],
            dof_parent: vec![],
        },
        body_has_inertial: vec![true],
    };
    // Settings first, wherever they appear.
    for e in &root.children {
        match e.name.as_str() {
            "compiler" => {
                e.check_attrs(&["angle", "autolimits", "eulerseq", "inertiafromgeom"])?;
                let a = Attrs {
                    elem: e,
                    defaults: None,
                };
                c.degrees = a.choice(
                    "angle",
                    &["degree", "radian"],
                    if c.degrees { "degree" } else { "radian" },
                )? == "degree";
                c.autolimits = a.choice("autolimits", &["true", "false"], "true")? == "true";
                a.choice("eulerseq", &["xyz"], "xyz")?;
                a.choice("inertiafromgeom", &["auto"], "auto")?;
            }
            "option" => {
                e.check_attrs(&["timestep", "gravity", "integrator"])?;
                let a = Attrs {
                    elem: e,
                    defaults: None,
                };
                a.choice("integrator", &["Euler"], "Euler")?;
                if let Some(ts) = a.f64("timestep")? {
                    if ts <= 0.0 {
                        return Err(e.src.err("<option> timestep must be positive"));
                    }
                    c.model.timestep = ts;
                }
                if let Some(g) = a.arr::<3>("gravity")? {
                    c.model.gravity = V3::from(g);
                }
                if let Some(child) = e.children.first() {
                    return Err(child.unsupported("option"));
                }
            }
            "default" => {
                let mut defaults = HashMap::new();
                collect_defaults(e, &ClassDefaults::default(), &mut defaults, true)?;
                for (k, v) in defaults {
                    if c.defaults.insert(k.clone(), v).is_some() {
                        return Err(e.src.err(format!("default class '{k}' is defined twice")));
                    }
                }
            }
            "worldbody" | "tendon" | "actuator" | "equality" | "keyframe" => {}
            _ => return Err(e.unsupported("mujoco")),
        }
    }
    for e in root.children.iter().filter(|e| e.name == "worldbody") {
        e.check_attrs(&[])?;
        // As MuJoCo orders them: the world's own geoms and sites first, then the bodies.
        for child in &e.children {
            match child.name.as_str() {
                "body" => {}
                "geom" => c.geom(child, 0, None)?,
                "site" => c.site(child, 0, None)?,
                _ => return Err(child.unsupported("worldbody")),
            }
        }
        for child in e.children.iter().filter(|c| c.name == "body") {
            c.body(child, 0, None)?;
        }
    }
    c.finish_inertia()?;
    c.finish_dofs();
    for e in &root.children {
        match e.name.as_str() {
            "tendon" => c.tendons(e)?,
            "actuator" => c.actuators(e)?,
            "equality" => c.equalities(e)?,
            "keyframe" => c.keyframes(e)?,
            _ => {}
        }
    }
    let mut model = c.model;
    crate::kinematics::fill_lengthranges(&mut model);
    Ok(model)
}
