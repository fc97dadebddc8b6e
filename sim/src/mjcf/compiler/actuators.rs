//! `<actuator>`: `<muscle>`, `<position>` and `<general>` with MuJoCo's parameter layouts.

use super::*;

impl Compiler {
    pub(super) fn transmission(&self, a: &Attrs) -> Result<Transmission> {
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

    pub(super) fn ctrlrange(
        &self,
        a: &Attrs,
        default_limited: Option<[f64; 2]>,
    ) -> Result<Option<[f64; 2]>> {
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

    pub(super) fn actuators(&mut self, e: &Elem) -> Result<()> {
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

    pub(super) fn lengthrange(&self, a: &Attrs) -> Result<Option<[f64; 2]>> {
        match a.arr::<2>("lengthrange")? {
            Some(r) if r[0] < r[1] && r[0] >= 0.0 => Ok(Some(r)),
            Some(_) => Err(a
                .elem
                .src
                .err(format!("<{}> lengthrange: need 0 ≤ min < max", a.elem.name))),
            None => Ok(None),
        }
    }

    pub(super) fn muscle(&self, e: &Elem) -> Result<Actuator> {
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

    pub(super) fn position(&self, e: &Elem) -> Result<Actuator> {
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

    pub(super) fn general(&self, e: &Elem) -> Result<Actuator> {
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
}

pub(super) fn check_muscle(e: &Elem, p: &MuscleParams) -> Result<()> {
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
