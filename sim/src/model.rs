//! The immutable description of a musculoskeletal robot (MuJoCo's `mjModel`, for the subset we
//! support): bodies, joints, sites, tendons, actuators, joint couplings and keyframes, as the MJCF
//! loader compiled them. Shared by `Arc` across threads; never mutated after loading.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};

use crate::muscle::{ActivationParams, MuscleParams};

type V3 = Vector3<f64>;

/// A rigid body of the kinematic tree. Body 0 is the world.
#[derive(Debug, Clone, PartialEq)]
pub struct Body {
    /// Name ("world" for body 0).
    pub name: String,
    /// Parent body; `None` only for the world.
    pub parent: Option<usize>,
    /// Position of the body frame in the parent frame, m.
    pub pos: V3,
    /// Orientation of the body frame in the parent frame.
    pub quat: UnitQuaternion<f64>,
    /// Mass, kg.
    pub mass: f64,
    /// Centre of mass in the body frame, m.
    pub com: V3,
    /// Inertia about the centre of mass, in the body frame, kg·m².
    pub inertia: Matrix3<f64>,
    /// Joints of this body, in order: `joints[first_joint .. first_joint + joint_count]`.
    pub first_joint: usize,
    /// Number of joints of this body.
    pub joint_count: usize,
    /// Where the body was declared (file:line), for messages.
    pub source: String,
}

/// Joint types.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// One rotational degree of freedom about `axis` through `pos`.
    Hinge,
    /// One translational degree of freedom along `axis`.
    Slide,
    /// Six degrees of freedom: position (3, world frame) and orientation (quaternion in qpos,
    /// angular velocity in the body frame in qvel), as MuJoCo's free joint.
    Free,
}

impl JointKind {
    /// Entries in `qpos`.
    pub fn nq(self) -> usize {
        match self {
            JointKind::Free => 7,
            _ => 1,
        }
    }

    /// Degrees of freedom (entries in `qvel`).
    pub fn nv(self) -> usize {
        match self {
            JointKind::Free => 6,
            _ => 1,
        }
    }

    /// MJCF name.
    pub fn name(self) -> &'static str {
        match self {
            JointKind::Hinge => "hinge",
            JointKind::Slide => "slide",
            JointKind::Free => "free",
        }
    }
}

/// A joint.
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    /// Name.
    pub name: String,
    /// Type.
    pub kind: JointKind,
    /// The body it moves.
    pub body: usize,
    /// Anchor in the body frame, m.
    pub pos: V3,
    /// Unit axis in the body frame.
    pub axis: V3,
    /// Limits `[lo, hi]` (rad or m) when the joint is limited.
    pub range: Option<[f64; 2]>,
    /// Viscous damping, N·m·s/rad or N·s/m.
    pub damping: f64,
    /// Armature (rotor inertia added to the mass matrix diagonal).
    pub armature: f64,
    /// Spring stiffness towards `springref`.
    pub stiffness: f64,
    /// Spring rest position.
    pub springref: f64,
    /// Reference position: the joint's value in the model's reference configuration (`qpos0`).
    pub reference: f64,
    /// Soft-limit reference (MuJoCo `solreflimit`: time constant s, damping ratio).
    pub limit_solref: [f64; 2],
    /// Soft-limit impedance (MuJoCo `solimplimit`: d0, dwidth, width; midpoint 0.5, power 2).
    pub limit_solimp: [f64; 3],
    /// First index in `qpos`.
    pub qpos_adr: usize,
    /// First index in `qvel`.
    pub dof_adr: usize,
}

/// A point fixed on a body: muscle path points, markers.
#[derive(Debug, Clone, PartialEq)]
pub struct Site {
    /// Name.
    pub name: String,
    /// The body it is fixed to.
    pub body: usize,
    /// Position in the body frame, m.
    pub pos: V3,
}

/// Geometric primitive kinds (for inertia from geoms, and for `model inspect`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GeomKind {
    /// `size = [radius]`.
    Sphere,
    /// `size = [radius, half-length]` along local z.
    Capsule,
    /// `size = [radius, half-length]` along local z.
    Cylinder,
    /// `size = [hx, hy, hz]`.
    Box,
    /// `size = [a, b, c]`: the semi-axes along local x, y, z.
    Ellipsoid,
    /// An infinite plane (world geoms only; no inertia).
    Plane,
}

/// A geometric primitive attached to a body.
#[derive(Debug, Clone, PartialEq)]
pub struct Geom {
    /// Name (may be empty).
    pub name: String,
    /// The body it belongs to.
    pub body: usize,
    /// Primitive type.
    pub kind: GeomKind,
    /// Size parameters (see [`GeomKind`]).
    pub size: [f64; 3],
    /// Position in the body frame.
    pub pos: V3,
    /// Orientation in the body frame.
    pub quat: UnitQuaternion<f64>,
    /// Mass, kg.
    pub mass: f64,
}

/// One element of a spatial tendon's path (MuJoCo's `wrap_type`/`wrap_objid`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PathPoint {
    /// The path passes through this site.
    Site(usize),
    /// Between the sites before and after it, the path wraps over this sphere or cylinder geom when
    /// the straight line would cross it, on the side of `sidesite` when one is given (a sidesite
    /// inside the geom makes the path pass through the geom's surface at one point: MuJoCo's inside
    /// wrap).
    Wrap {
        /// The sphere or cylinder.
        geom: usize,
        /// The site that picks the side of the wrap.
        sidesite: Option<usize>,
    },
}

/// A spatial tendon: a path through sites, wrapping over spheres and cylinders between them; its
/// length the sum of the straight segments and the arcs.
#[derive(Debug, Clone, PartialEq)]
pub struct Tendon {
    /// Name.
    pub name: String,
    /// The path, origin first: it starts and ends at a site, and a wrap sits between two sites.
    pub path: Vec<PathPoint>,
}

impl Tendon {
    /// The sites of the path, in order (wraps left out).
    pub fn sites(&self) -> impl Iterator<Item = usize> + '_ {
        self.path.iter().filter_map(|p| match p {
            PathPoint::Site(s) => Some(*s),
            PathPoint::Wrap { .. } => None,
        })
    }
}

/// What an actuator pulls on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Transmission {
    /// A tendon (its length is the actuator length).
    Tendon(usize),
    /// A single-DoF joint.
    Joint(usize),
}

/// Actuator activation dynamics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Dynamics {
    /// The control acts directly.
    None,
    /// MuJoCo's muscle activation dynamics.
    Muscle(ActivationParams),
}

/// Actuator gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Gain {
    /// `gain = g` (a position servo's `kp`).
    Fixed(f64),
    /// MuJoCo's muscle gain.
    Muscle(MuscleParams),
}

/// Actuator bias.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bias {
    /// No bias.
    None,
    /// `bias = b0 + b1·length + b2·velocity` (a position servo: `0, −kp, −kv`).
    Affine([f64; 3]),
    /// MuJoCo's passive muscle force.
    Muscle(MuscleParams),
}

/// An actuator: `force = gain·(act or ctrl) + bias`, applied through its transmission.
#[derive(Debug, Clone, PartialEq)]
pub struct Actuator {
    /// Name.
    pub name: String,
    /// What it pulls on.
    pub transmission: Transmission,
    /// Activation dynamics.
    pub dynamics: Dynamics,
    /// Gain.
    pub gain: Gain,
    /// Bias.
    pub bias: Bias,
    /// Control limits, when limited.
    pub ctrlrange: Option<[f64; 2]>,
    /// Range of the actuator length over the joint ranges `[min, max]`, m.
    pub lengthrange: [f64; 2],
    /// Whether `lengthrange` was stated in the model (else the loader computed it).
    pub lengthrange_given: bool,
}

impl Actuator {
    /// The muscle parameters, for a muscle.
    pub fn muscle(&self) -> Option<&MuscleParams> {
        match &self.gain {
            Gain::Muscle(p) => Some(p),
            Gain::Fixed(_) => None,
        }
    }
}

/// An exact joint coupling (MuJoCo `<equality><joint polycoef>`): the dependent joint follows
/// `q_dep = ref_dep + c0 + c1·Δ + c2·Δ² + c3·Δ³ + c4·Δ⁴`, `Δ = q_ind − ref_ind`; without an
/// independent joint it is locked at `ref_dep + c0` (MuJoCo's `joint1` alone).
#[derive(Debug, Clone, PartialEq)]
pub struct Coupling {
    /// The joint that follows.
    pub dependent: usize,
    /// The joint it follows; `None` locks the dependent joint.
    pub independent: Option<usize>,
    /// Polynomial coefficients c0..c4.
    pub coef: [f64; 5],
}

impl Coupling {
    /// `(q_dep, dq_dep/dq_ind, d²q_dep/dq_ind²)` at `q_ind`, given both joints' references.
    pub fn eval(&self, q_ind: f64, ref_ind: f64, ref_dep: f64) -> (f64, f64, f64) {
        let d = q_ind - ref_ind;
        let c = &self.coef;
        let q = ref_dep + c[0] + d * (c[1] + d * (c[2] + d * (c[3] + d * c[4])));
        let dq = c[1] + d * (2.0 * c[2] + d * (3.0 * c[3] + d * 4.0 * c[4]));
        let ddq = 2.0 * c[2] + d * (6.0 * c[3] + d * 12.0 * c[4]);
        (q, dq, ddq)
    }

    /// [`Coupling::eval`] on a model's `qpos`: the dependent's position and its first and second
    /// derivatives by the independent joint (zero for a lock).
    pub fn at(&self, model: &Model, qpos: &[f64]) -> (f64, f64, f64) {
        let dep = &model.joints[self.dependent];
        match self.independent {
            Some(i) => {
                let ind = &model.joints[i];
                self.eval(qpos[ind.qpos_adr], ind.reference, dep.reference)
            }
            None => (dep.reference + self.coef[0], 0.0, 0.0),
        }
    }
}

/// A named state.
#[derive(Debug, Clone, PartialEq)]
pub struct Keyframe {
    /// Name.
    pub name: String,
    /// Joint positions (length `nq`).
    pub qpos: Vec<f64>,
    /// Joint velocities (length `nv`; zero when the key gives none).
    pub qvel: Vec<f64>,
}

/// A compiled model.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    /// Model name (`<mujoco model>`).
    pub name: String,
    /// Physics timestep, s.
    pub timestep: f64,
    /// Gravity, m/s².
    pub gravity: V3,
    /// Bodies, parents before children; body 0 is the world.
    pub bodies: Vec<Body>,
    /// Joints, in body order.
    pub joints: Vec<Joint>,
    /// Sites.
    pub sites: Vec<Site>,
    /// Geoms.
    pub geoms: Vec<Geom>,
    /// Spatial tendons.
    pub tendons: Vec<Tendon>,
    /// Actuators.
    pub actuators: Vec<Actuator>,
    /// Exact joint couplings.
    pub couplings: Vec<Coupling>,
    /// Keyframes.
    pub keyframes: Vec<Keyframe>,
    /// Size of `qpos`.
    pub nq: usize,
    /// Degrees of freedom (size of `qvel`).
    pub nv: usize,
    /// Reference configuration (`qpos0`): joint references, free joints at their declared pose.
    pub qpos0: Vec<f64>,
    /// For each degree of freedom, its joint.
    pub dof_joint: Vec<usize>,
    /// For each degree of freedom, its body.
    pub dof_body: Vec<usize>,
    /// For each degree of freedom, the previous dof on the path to the root (`None` at the root):
    /// the tree structure that CRBA and RNEA walk (MuJoCo's `dof_parentid`).
    pub dof_parent: Vec<Option<usize>>,
}

impl Model {
    /// Index of the body called `name`.
    pub fn body(&self, name: &str) -> Option<usize> {
        self.bodies.iter().position(|b| b.name == name)
    }

    /// Index of the joint called `name`.
    pub fn joint(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Index of the site called `name`.
    pub fn site(&self, name: &str) -> Option<usize> {
        self.sites.iter().position(|s| s.name == name)
    }

    /// Index of the actuator called `name`.
    pub fn actuator(&self, name: &str) -> Option<usize> {
        self.actuators.iter().position(|a| a.name == name)
    }

    /// Muscles: actuators with MuJoCo's muscle gain.
    pub fn muscles(&self) -> impl Iterator<Item = (usize, &Actuator)> {
        self.actuators
            .iter()
            .enumerate()
            .filter(|(_, a)| a.muscle().is_some())
    }

    /// Whether joint `j` follows a coupling.
    pub fn is_dependent(&self, j: usize) -> bool {
        self.couplings.iter().any(|c| c.dependent == j)
    }

    /// Applies every coupling to `qpos` in place: dependent joints take their polynomial's value.
    pub fn apply_couplings(&self, qpos: &mut [f64]) {
        for c in &self.couplings {
            let (q, _, _) = c.at(self, qpos);
            qpos[self.joints[c.dependent].qpos_adr] = q;
        }
    }
}
