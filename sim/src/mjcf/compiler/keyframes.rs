//! `<keyframe><key>`.

use super::*;

impl Compiler {
    pub(super) fn keyframes(&mut self, e: &Elem) -> Result<()> {
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
}
