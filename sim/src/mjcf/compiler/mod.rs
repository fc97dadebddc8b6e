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

pub(super) fn compile(root: &Elem) -> Result<Model> {
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
