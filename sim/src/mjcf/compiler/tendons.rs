//! `<tendon><spatial>`: paths through sites, wrapping over sphere and cylinder geoms between them
//! (`<geom geom sidesite>`).

use super::*;

impl Compiler {
    pub(super) fn tendons(&mut self, e: &Elem) -> Result<()> {
        e.check_attrs(&[])?;
        for t in &e.children {
            if t.name != "spatial" {
                return Err(t.unsupported("tendon"));
            }
            // `springlength` only matters with a stiffness, which we do not support: ignored.
            t.check_attrs(&[
                "name",
                "class",
                "width",
                "rgba",
                "group",
                "springlength",
                "limited",
            ])?;
            let a = Attrs {
                elem: t,
                defaults: None,
            };
            if a.bool_auto("limited")? == Some(true) {
                return Err(t
                    .src
                    .err("<spatial> limited=\"true\": tendon limits are not supported"));
            }
            let name = t.attr("name").unwrap_or("").to_string();
            if name.is_empty() {
                return Err(t.src.err("<spatial> needs a name"));
            }
            if self.model.tendons.iter().any(|x| x.name == name) {
                return Err(t.src.err(format!("<spatial>: duplicate name '{name}'")));
            }
            let mut path = Vec::new();
            for p in &t.children {
                let point = match p.name.as_str() {
                    "site" => {
                        p.check_attrs(&["site"])?;
                        PathPoint::Site(self.path_site(p, &name, "site")?)
                    }
                    "geom" => self.wrap(p, &name)?,
                    "pulley" => {
                        return Err(p.src.err(format!(
                            "tendon '{name}': <pulley> is not supported (paths through sites and \
                             over spheres and cylinders only)"
                        )))
                    }
                    _ => return Err(p.unsupported("spatial")),
                };
                if let (Some(PathPoint::Wrap { .. }), PathPoint::Wrap { .. }) = (path.last(), point)
                {
                    return Err(p.src.err(format!(
                        "tendon '{name}': two wrapping geoms in a row; put a site between them"
                    )));
                }
                path.push(point);
            }
            let ends_at_sites = matches!(path.first(), Some(PathPoint::Site(_)))
                && matches!(path.last(), Some(PathPoint::Site(_)));
            if !ends_at_sites {
                return Err(t.src.err(format!(
                    "tendon '{name}': a path starts and ends at a site (a wrapping geom sits between two sites)"
                )));
            }
            if path.len() < 2 {
                return Err(t
                    .src
                    .err(format!("tendon '{name}': a path needs at least two sites")));
            }
            self.model.tendons.push(Tendon { name, path });
        }
        Ok(())
    }

    fn path_site(&self, p: &Elem, tendon: &str, key: &str) -> Result<usize> {
        let s = p
            .attr(key)
            .ok_or_else(|| p.src.err(format!("<{}> in a tendon needs '{key}'", p.name)))?;
        self.model
            .site(s)
            .ok_or_else(|| p.src.err(format!("tendon '{tendon}': no site named '{s}'")))
    }

    /// A wrapping geom of a path: a sphere or a cylinder (MuJoCo wraps over its radius), with an
    /// optional side site on the geom's own body.
    fn wrap(&self, p: &Elem, tendon: &str) -> Result<PathPoint> {
        p.check_attrs(&["geom", "sidesite"])?;
        let g = p
            .attr("geom")
            .ok_or_else(|| p.src.err("<geom> in a tendon needs 'geom'"))?;
        let geom = self
            .model
            .geoms
            .iter()
            .position(|x| x.name == g)
            .ok_or_else(|| p.src.err(format!("tendon '{tendon}': no geom named '{g}'")))?;
        let wrap_geom = &self.model.geoms[geom];
        if !matches!(wrap_geom.kind, GeomKind::Sphere | GeomKind::Cylinder) {
            return Err(p.src.err(format!(
                "tendon '{tendon}': geom '{g}' is a {}; paths wrap over spheres and cylinders only",
                format!("{:?}", wrap_geom.kind).to_lowercase()
            )));
        }
        // Sizes are checked positive when geoms load; a wrap needs a radius MuJoCo would not
        // treat as zero.
        if wrap_geom.size[0] < 1e-10 {
            return Err(p
                .src
                .err(format!("tendon '{tendon}': geom '{g}' has a zero radius")));
        }
        let sidesite = match p.attr("sidesite") {
            None => None,
            Some(_) => {
                let s = self.path_site(p, tendon, "sidesite")?;
                let on = self.model.sites[s].body;
                if on != wrap_geom.body {
                    return Err(p.src.err(format!(
                        "tendon '{tendon}': sidesite '{}' is on body '{}', its geom '{g}' on '{}'; \
                         a side site must move with its geom",
                        self.model.sites[s].name,
                        self.model.bodies[on].name,
                        self.model.bodies[wrap_geom.body].name
                    )));
                }
                Some(s)
            }
        };
        Ok(PathPoint::Wrap { geom, sidesite })
    }
}
