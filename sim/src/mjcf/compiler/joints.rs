//! `<joint>` and `<freejoint>`: hinge, slide and free joints, ranges, damping, armature.

use super::*;

impl Compiler {
    pub(super) fn joint(
        &mut self,
        e: &Elem,
        body: usize,
        childclass: Option<&str>,
        free: bool,
    ) -> Result<()> {
        let a = self.joint_attrs(e, childclass, free)?;
        let kind = self.joint_kind(e, &a, body, free)?;
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
        let range = self.joint_range(e, &a, angular)?;
        let nonneg = |key: &str| -> Result<f64> {
            let v = a.f64_or(key, 0.0)?;
            if v < 0.0 {
                return Err(e.src.err(format!("<joint> {key}: must not be negative")));
            }
            Ok(v)
        };
        let reference = conv(a.f64_or("ref", 0.0)?);
        let (limit_solref, limit_solimp) = limit_solver(e, &a)?;
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

    /// The attributes a `<joint>` may have (with its defaults), or a `<freejoint>`'s name alone.
    fn joint_attrs<'a>(
        &'a self,
        e: &'a Elem,
        childclass: Option<&'a str>,
        free: bool,
    ) -> Result<Attrs<'a>> {
        Ok(if free {
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
        })
    }

    /// The joint's kind; a free joint must be the only joint of a child of the world.
    fn joint_kind(&self, e: &Elem, a: &Attrs, body: usize, free: bool) -> Result<JointKind> {
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
        Ok(kind)
    }

    /// The joint's range (converted to radians for a hinge in degrees), if it is limited.
    fn joint_range(&self, e: &Elem, a: &Attrs, angular: bool) -> Result<Option<[f64; 2]>> {
        let conv = |x: f64| if angular { self.angle(x) } else { x };
        let range = a.arr::<2>("range")?;
        let limited = match a.bool_auto("limited")? {
            Some(l) => l,
            None => self.autolimits && range.is_some(),
        };
        if limited && range.is_none() {
            return Err(e.src.err("<joint> is limited but has no range"));
        }
        Ok(match (limited, range) {
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
        })
    }
}

/// The joint limit's solver parameters: `solreflimit` in the standard form and `solimplimit`
/// with the default midpoint and power.
fn limit_solver(e: &Elem, a: &Attrs) -> Result<([f64; 2], [f64; 3])> {
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
            return Err(e
                .src
                .err("<joint> solimplimit: give d0 dwidth width (midpoint 0.5 and power 2 only)"))
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
    Ok((limit_solref, limit_solimp))
}
