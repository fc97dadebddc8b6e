//! The MJCF compiler: from elements to the immutable `Model`, with MuJoCo's compile semantics
//! (defaults applied, angles in degrees unless told, inertia from geoms, limits from ranges,
//! actuator parameter layouts). One file per part of the model.

mod actuators;
mod equalities;
mod geoms;
mod inertia;
mod joints;
mod keyframes;
mod tendons;

use std::collections::HashMap;

use nalgebra::{Matrix3, Quaternion, SymmetricEigen, UnitQuaternion, Vector3};

use super::reader::*;
use super::{MjcfError, Result};
use crate::model::*;
use crate::muscle::{ActivationParams, MuscleParams};
use inertia::{combine_geom_inertia, geom_volume};

type V3 = Vector3<f64>;

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

/// The minimal rotation taking local z onto `v` (MuJoCo's `zaxis` and `fromto`); a half turn about
/// x when `v` points along −z.
fn z_to(v: &V3) -> UnitQuaternion<f64> {
    crate::math::quat_rotation_between(&V3::z(), v)
        .unwrap_or_else(|| crate::math::quat_from_axis_angle(&V3::x_axis(), std::f64::consts::PI))
}

/// The attributes of a `<body>` and of a `<frame>`: a name, a placement and a default class for
/// what is inside.
const PLACED_ATTRS: [&str; 8] = [
    "name",
    "pos",
    "quat",
    "euler",
    "axisangle",
    "xyaxes",
    "zaxis",
    "childclass",
];

/// Where a `<frame>` places the elements inside it, in the frame of the body that holds them;
/// `None` outside any frame (poses are then taken exactly as written). Frames nest: an inner
/// frame is placed by the outer one.
#[derive(Debug, Clone, Copy)]
struct Frame(Option<(V3, UnitQuaternion<f64>)>);

impl Frame {
    const IDENTITY: Frame = Frame(None);

    /// A pose given inside this frame, in the body's frame.
    fn place(&self, pos: V3, quat: UnitQuaternion<f64>) -> (V3, UnitQuaternion<f64>) {
        match self.0 {
            Some((fpos, fquat)) => (fpos + fquat * pos, fquat * quat),
            None => (pos, quat),
        }
    }
}

/// An element met while walking a body's children through its frames: the element, the frame it
/// sits in and the default class its kind falls back to.
struct Placed<'e> {
    elem: &'e Elem,
    frame: Frame,
    childclass: Option<&'e str>,
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

    /// Orientation from `quat`, `euler` (intrinsic xyz), `axisangle`, `xyaxes` or `zaxis`; identity
    /// if none.
    fn orientation(&self, a: &Attrs) -> Result<UnitQuaternion<f64>> {
        let given: Vec<&str> = ["quat", "euler", "axisangle", "xyaxes", "zaxis"]
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
            let rx = crate::math::quat_from_axis_angle(&V3::x_axis(), self.angle(e[0]));
            let ry = crate::math::quat_from_axis_angle(&V3::y_axis(), self.angle(e[1]));
            let rz = crate::math::quat_from_axis_angle(&V3::z_axis(), self.angle(e[2]));
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
            return Ok(crate::math::quat_from_scaled_axis(
                axis / n * self.angle(aa[3]),
            ));
        }
        if let Some(z) = a.arr::<3>("zaxis")? {
            let z = V3::from(z);
            if z.norm() < 1e-12 {
                return Err(a
                    .elem
                    .src
                    .err(format!("<{}> zaxis: zero vector", a.elem.name)));
            }
            return Ok(z_to(&z));
        }
        if let Some(xy) = a.arr::<6>("xyaxes")? {
            // MuJoCo: x normalised, y made orthogonal to it and normalised, z = x × y.
            let x = V3::new(xy[0], xy[1], xy[2]);
            let y = V3::new(xy[3], xy[4], xy[5]);
            let bad = || {
                a.elem.src.err(format!(
                    "<{}> xyaxes: the two axes must be non-zero and not parallel",
                    a.elem.name
                ))
            };
            let x = x.try_normalize(1e-12).ok_or_else(bad)?;
            let y = (y - x * x.dot(&y)).try_normalize(1e-12).ok_or_else(bad)?;
            let m = Matrix3::from_columns(&[x, y, x.cross(&y)]);
            return Ok(UnitQuaternion::from_rotation_matrix(
                &nalgebra::Rotation3::from_matrix_unchecked(m),
            ));
        }
        Ok(UnitQuaternion::identity())
    }

    /// The `childclass` an element gives its children (checked to exist), else the inherited one.
    fn childclass<'e>(&self, e: &'e Elem, inherited: Option<&'e str>) -> Result<Option<&'e str>> {
        if let Some(c) = e.attr("childclass") {
            if c != "main" && !self.defaults.contains_key(c) {
                return Err(e.src.err(format!("<{}>: unknown childclass '{c}'", e.name)));
            }
        }
        Ok(e.attr("childclass").or(inherited))
    }

    /// The children of a body (or of the world) with the `<frame>`s between them unwrapped, in
    /// document order.
    fn unwrap_frames<'e>(
        &self,
        children: &'e [Elem],
        frame: Frame,
        childclass: Option<&'e str>,
        out: &mut Vec<Placed<'e>>,
    ) -> Result<()> {
        for c in children {
            if c.name != "frame" {
                out.push(Placed {
                    elem: c,
                    frame,
                    childclass,
                });
                continue;
            }
            c.check_attrs(&PLACED_ATTRS)?;
            let a = Attrs {
                elem: c,
                defaults: None,
            };
            let (pos, quat) = frame.place(
                V3::from(a.arr::<3>("pos")?.unwrap_or([0.0; 3])),
                self.orientation(&a)?,
            );
            let inner = self.childclass(c, childclass)?;
            for k in &c.children {
                if matches!(k.name.as_str(), "joint" | "freejoint" | "inertial") {
                    return Err(k.src.err(format!(
                        "<{}> cannot be inside a <frame>: it belongs to its body",
                        k.name
                    )));
                }
            }
            self.unwrap_frames(&c.children, Frame(Some((pos, quat))), inner, out)?;
        }
        Ok(())
    }

    fn body(
        &mut self,
        e: &Elem,
        parent: usize,
        childclass: Option<&str>,
        frame: Frame,
    ) -> Result<()> {
        e.check_attrs(&PLACED_ATTRS)?;
        let a = Attrs {
            elem: e,
            defaults: None,
        };
        let childclass = self.childclass(e, childclass)?;
        let id = self.model.bodies.len();
        let name = e.attr("name").unwrap_or("").to_string();
        if !name.is_empty() && self.model.bodies.iter().any(|b| b.name == name) {
            return Err(e.src.err(format!("<body>: duplicate name '{name}'")));
        }
        let (pos, quat) = frame.place(
            V3::from(a.arr::<3>("pos")?.unwrap_or([0.0; 3])),
            self.orientation(&a)?,
        );
        self.model.bodies.push(Body {
            name,
            parent: Some(parent),
            pos,
            quat,
            mass: 0.0,
            com: V3::zeros(),
            inertia: Matrix3::zeros(),
            first_joint: self.model.joints.len(),
            joint_count: 0,
            source: format!("{}:{}", e.src.file, e.src.line),
        });
        self.body_has_inertial.push(false);
        let mut placed = Vec::new();
        self.unwrap_frames(&e.children, Frame::IDENTITY, childclass, &mut placed)?;
        for p in &placed {
            let (c, cc) = (p.elem, p.childclass);
            match c.name.as_str() {
                "inertial" => self.inertial(c, id)?,
                "joint" => self.joint(c, id, cc, false)?,
                "freejoint" => self.joint(c, id, cc, true)?,
                "geom" => self.geom(c, id, cc, p.frame)?,
                "site" => self.site(c, id, cc, p.frame)?,
                "body" => {}
                _ => return Err(c.unsupported("body")),
            }
        }
        for p in placed.iter().filter(|p| p.elem.name == "body") {
            self.body(p.elem, id, p.childclass, p.frame)?;
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
        }
        for b in 1..self.model.bodies.len() {
            let body = &self.model.bodies[b];
            if body.joint_count > 0 && !self.carries_mass(b) {
                return Err(MjcfError {
                        file: body.source.rsplit_once(':').map(|s| s.0).unwrap_or("").to_string(),
                        line: body.source.rsplit_once(':').and_then(|s| s.1.parse().ok()).unwrap_or(0),
                        message: format!(
                            "body '{}' moves (it has joints) but neither it nor a body welded to it has a positive mass and inertia: give it an <inertial> or geoms",
                            body.name
                        ),
                    });
            }
        }
        Ok(())
    }

    /// Whether body `b`, or a body welded to it (a descendant reached through bodies without
    /// joints), has a positive mass and inertia: MuJoCo's condition for a moving body.
    fn carries_mass(&self, b: usize) -> bool {
        let body = &self.model.bodies[b];
        let eig = SymmetricEigen::new(body.inertia).eigenvalues;
        if body.mass >= 1e-15 && eig.iter().all(|x| *x >= 1e-15) {
            return true;
        }
        (b + 1..self.model.bodies.len()).any(|c| {
            let child = &self.model.bodies[c];
            child.parent == Some(b) && child.joint_count == 0 && self.carries_mass(c)
        })
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

pub(super) fn compile(root: &Elem) -> Result<Model> {
    root.check_attrs(&["model"])?;
    let mut c = Compiler::new(root.attr("model").unwrap_or(""));
    // Settings first, wherever they appear.
    for e in &root.children {
        match e.name.as_str() {
            "compiler" => c.compiler_settings(e)?,
            "option" => c.option(e)?,
            "default" => c.default_classes(e)?,
            "worldbody" | "tendon" | "actuator" | "equality" | "keyframe" => {}
            _ => return Err(e.unsupported("mujoco")),
        }
    }
    for e in root.children.iter().filter(|e| e.name == "worldbody") {
        c.worldbody(e)?;
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

impl Compiler {
    /// A compiler at MuJoCo's settings, with the world body alone.
    fn new(name: &str) -> Compiler {
        Compiler {
            degrees: true,
            autolimits: true,
            defaults: HashMap::new(),
            model: Model {
                name: name.to_string(),
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
        }
    }

    /// `<compiler>`: angles in degrees or radians, automatic limits.
    fn compiler_settings(&mut self, e: &Elem) -> Result<()> {
        e.check_attrs(&["angle", "autolimits", "eulerseq", "inertiafromgeom"])?;
        let a = Attrs {
            elem: e,
            defaults: None,
        };
        self.degrees = a.choice(
            "angle",
            &["degree", "radian"],
            if self.degrees { "degree" } else { "radian" },
        )? == "degree";
        self.autolimits = a.choice("autolimits", &["true", "false"], "true")? == "true";
        a.choice("eulerseq", &["xyz"], "xyz")?;
        a.choice("inertiafromgeom", &["auto"], "auto")?;
        Ok(())
    }

    /// `<option>`: the timestep and gravity (Euler integration only).
    fn option(&mut self, e: &Elem) -> Result<()> {
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
            self.model.timestep = ts;
        }
        if let Some(g) = a.arr::<3>("gravity")? {
            self.model.gravity = V3::from(g);
        }
        if let Some(child) = e.children.first() {
            return Err(child.unsupported("option"));
        }
        Ok(())
    }

    /// `<default>`: the default classes, each defined once.
    fn default_classes(&mut self, e: &Elem) -> Result<()> {
        let mut defaults = HashMap::new();
        collect_defaults(e, &ClassDefaults::default(), &mut defaults, true)?;
        for (k, v) in defaults {
            if self.defaults.insert(k.clone(), v).is_some() {
                return Err(e.src.err(format!("default class '{k}' is defined twice")));
            }
        }
        Ok(())
    }

    /// `<worldbody>`: the world's own geoms and sites, then its bodies.
    fn worldbody(&mut self, e: &Elem) -> Result<()> {
        e.check_attrs(&[])?;
        // As MuJoCo orders them: the world's own geoms and sites first, then the bodies.
        let mut placed = Vec::new();
        self.unwrap_frames(&e.children, Frame::IDENTITY, None, &mut placed)?;
        for p in &placed {
            match p.elem.name.as_str() {
                "body" => {}
                "geom" => self.geom(p.elem, 0, p.childclass, p.frame)?,
                "site" => self.site(p.elem, 0, p.childclass, p.frame)?,
                _ => return Err(p.elem.unsupported("worldbody")),
            }
        }
        for p in placed.iter().filter(|p| p.elem.name == "body") {
            self.body(p.elem, 0, p.childclass, p.frame)?;
        }
        Ok(())
    }
}
