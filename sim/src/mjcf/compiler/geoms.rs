//! `<geom>` and `<site>`.

use super::*;

impl Compiler {
    pub(super) fn geom(
        &mut self,
        e: &Elem,
        body: usize,
        childclass: Option<&str>,
        frame: Frame,
    ) -> Result<()> {
        e.check_attrs(&[
            "name",
            "class",
            "type",
            "size",
            "pos",
            "quat",
            "euler",
            "axisangle",
            "xyaxes",
            "zaxis",
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
        if a.raw("type") == Some("mesh") {
            return Err(e.src.err(
                "<geom type=\"mesh\">: meshes are not loaded; give the body an <inertial> and leave \
                 the mesh out (`rally model import myosuite` writes MyoSuite's robot that way)",
            ));
        }
        let kind = match a.choice(
            "type",
            &["sphere", "capsule", "cylinder", "box", "ellipsoid", "plane"],
            "sphere",
        )? {
            "sphere" => GeomKind::Sphere,
            "capsule" => GeomKind::Capsule,
            "cylinder" => GeomKind::Cylinder,
            "box" => GeomKind::Box,
            "ellipsoid" => GeomKind::Ellipsoid,
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
            quat = z_to(&d);
            size[1] = 0.5 * d.norm();
        }
        let (pos, quat) = frame.place(pos, quat);
        let needed = match kind {
            GeomKind::Sphere => 1,
            GeomKind::Capsule | GeomKind::Cylinder => 2,
            GeomKind::Box | GeomKind::Ellipsoid => 3,
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

    pub(super) fn site(
        &mut self,
        e: &Elem,
        body: usize,
        childclass: Option<&str>,
        frame: Frame,
    ) -> Result<()> {
        e.check_attrs(&[
            "name",
            "class",
            "type",
            "size",
            "pos",
            "quat",
            "euler",
            "axisangle",
            "xyaxes",
            "zaxis",
            "rgba",
            "group",
        ])?;
        let a = self.attrs(e, "site", childclass)?;
        self.orientation(&a)?;
        let name = e.attr("name").unwrap_or("").to_string();
        if !name.is_empty() && self.model.sites.iter().any(|s| s.name == name) {
            return Err(e.src.err(format!("<site>: duplicate name '{name}'")));
        }
        let (pos, _) = frame.place(
            V3::from(a.arr::<3>("pos")?.unwrap_or([0.0; 3])),
            UnitQuaternion::identity(),
        );
        self.model.sites.push(Site { name, body, pos });
        Ok(())
    }
}
