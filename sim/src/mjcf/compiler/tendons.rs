//! `<tendon><spatial>` through sites.

use super::*;

impl Compiler {
    pub(super) fn tendons(&mut self, e: &Elem) -> Result<()> {
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
}
