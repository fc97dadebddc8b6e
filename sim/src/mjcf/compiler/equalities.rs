//! `<equality><joint polycoef>`: the joint couplings (`joint1` follows `joint2`, or is locked when
//! there is no `joint2`).

use super::*;

impl Compiler {
    pub(super) fn equalities(&mut self, e: &Elem) -> Result<()> {
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
            let independent = q.attr("joint2").map(|_| find("joint2")).transpose()?;
            if independent == Some(dependent) {
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
            if independent.is_none() && c.coef[1..].iter().any(|x| *x != 0.0) {
                return Err(q.src.err(format!(
                    "<joint> equality on '{}' alone: only polycoef's first number (the locked \
                     offset) may be non-zero",
                    name(dependent)
                )));
            }
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
                .any(|x| Some(x.dependent) == independent || x.independent == Some(dependent))
            {
                return Err(q.src.err(format!(
                    "coupling chains are not supported: '{}' links to another coupling; couple every dependent joint to an independent one",
                    name(dependent)
                )));
            }
            self.model.couplings.push(c);
        }
        Ok(())
    }
}
