//! `<inertial>`, inertia from geoms and the mass checks.

use super::*;

impl Compiler {
    pub(super) fn inertial(&mut self, e: &Elem, body: usize) -> Result<()> {
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
}

pub(super) fn check_mass(e: &Elem, mass: f64, inertia: &Matrix3<f64>) -> Result<()> {
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

pub(super) fn geom_volume(kind: GeomKind, s: &[f64; 3]) -> f64 {
    use std::f64::consts::PI;
    match kind {
        GeomKind::Sphere => 4.0 / 3.0 * PI * s[0].powi(3),
        GeomKind::Capsule => PI * s[0] * s[0] * (2.0 * s[1]) + 4.0 / 3.0 * PI * s[0].powi(3),
        GeomKind::Cylinder => PI * s[0] * s[0] * 2.0 * s[1],
        GeomKind::Box => 8.0 * s[0] * s[1] * s[2],
        GeomKind::Ellipsoid => 4.0 / 3.0 * PI * s[0] * s[1] * s[2],
        GeomKind::Plane => 0.0,
    }
}

/// Principal inertia of a geom about its own centre, in its own frame (MuJoCo's formulas).
pub(super) fn geom_inertia(g: &Geom) -> V3 {
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
        GeomKind::Ellipsoid => V3::new(
            0.2 * m * (s[1] * s[1] + s[2] * s[2]),
            0.2 * m * (s[0] * s[0] + s[2] * s[2]),
            0.2 * m * (s[0] * s[0] + s[1] * s[1]),
        ),
        GeomKind::Plane => V3::zeros(),
    }
}

/// Mass, centre of mass and inertia about it (body frame) of a set of geoms.
pub(super) fn combine_geom_inertia(geoms: &[&Geom]) -> (f64, V3, Matrix3<f64>) {
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
