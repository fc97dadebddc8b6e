//! The XML side of the MJCF loader, as MuJoCo separates its parser from its compiler: elements with
//! their source (file and line), `<include>` expansion, attribute access with `<default>` classes,
//! number lists. Nothing here knows what a body or a muscle is.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use super::{MjcfError, Result};

/// Where an element came from.
#[derive(Debug, Clone)]
pub(crate) struct Src {
    pub(crate) file: Rc<str>,
    pub(crate) line: u32,
}

impl Src {
    pub(crate) fn err(&self, message: impl Into<String>) -> MjcfError {
        MjcfError {
            file: self.file.to_string(),
            line: self.line,
            message: message.into(),
        }
    }
}

/// An owned XML element with includes already spliced in.
#[derive(Debug, Clone)]
pub(crate) struct Elem {
    pub(crate) name: String,
    pub(crate) attrs: Vec<(String, String)>,
    pub(crate) children: Vec<Elem>,
    pub(crate) src: Src,
}

impl Elem {
    pub(crate) fn attr(&self, key: &str) -> Option<&str> {
        self.attrs
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
    }

    pub(crate) fn check_attrs(&self, allowed: &[&str]) -> Result<()> {
        for (k, _) in &self.attrs {
            if !allowed.contains(&k.as_str()) {
                return Err(self.src.err(format!(
                    "<{}>: unsupported attribute '{k}' (supported: {})",
                    self.name,
                    allowed.join(", ")
                )));
            }
        }
        Ok(())
    }

    pub(crate) fn unsupported(&self, parent: &str) -> MjcfError {
        self.src.err(format!(
            "<{}> inside <{parent}> is not supported by muscle-rally's MJCF loader",
            self.name
        ))
    }
}

pub(crate) const MAX_INCLUDE_DEPTH: usize = 16;

/// The most files one load may read through `<include>` in all. Depth alone does not bound the
/// work: a file that includes the next one ten times, sixteen levels down, asks for 10¹⁶ reads.
pub(crate) const MAX_INCLUDED_FILES: usize = 256;

/// Where an element sits among includes: how deep, and how many files the load has read so far.
#[derive(Clone, Copy)]
pub(crate) struct Nesting<'a> {
    pub(crate) depth: usize,
    pub(crate) files: &'a std::cell::Cell<usize>,
}

pub(crate) fn read_tree(
    path: &Path,
    read: &dyn Fn(&Path) -> std::io::Result<String>,
    nest: Nesting,
    from: Option<&Src>,
) -> Result<Elem> {
    let text = read(path).map_err(|e| {
        let msg = format!("cannot read {}: {e}", path.display());
        match from {
            Some(src) => src.err(msg),
            None => MjcfError {
                file: path.display().to_string(),
                line: 0,
                message: msg,
            },
        }
    })?;
    parse_tree(&text, path, read, nest)
}

pub(crate) fn parse_tree(
    text: &str,
    path: &Path,
    read: &dyn Fn(&Path) -> std::io::Result<String>,
    nest: Nesting,
) -> Result<Elem> {
    let file: Rc<str> = Rc::from(path.display().to_string());
    let doc = roxmltree::Document::parse(text).map_err(|e| MjcfError {
        file: file.to_string(),
        line: e.pos().row,
        message: format!("malformed XML: {e}"),
    })?;
    let root = doc.root_element();
    let lines = LineIndex::new(text);
    let src = Src {
        file: file.clone(),
        line: lines.line(root.range().start),
    };
    if root.tag_name().name() != "mujoco" {
        return Err(src.err(format!(
            "the root element is <{}>; an MJCF model starts with <mujoco>",
            root.tag_name().name()
        )));
    }
    convert(&lines, root, &file, path, read, nest)
}

/// Byte offset → 1-based line, by binary search over the line starts (roxmltree's own lookup scans
/// the text from the start each time).
pub(crate) struct LineIndex(pub(crate) Vec<usize>);

impl LineIndex {
    pub(crate) fn new(text: &str) -> LineIndex {
        LineIndex(
            std::iter::once(0)
                .chain(text.match_indices('\n').map(|(i, _)| i + 1))
                .collect(),
        )
    }

    pub(crate) fn line(&self, offset: usize) -> u32 {
        self.0.partition_point(|&start| start <= offset) as u32
    }
}

pub(crate) fn convert(
    lines: &LineIndex,
    node: roxmltree::Node,
    file: &Rc<str>,
    path: &Path,
    read: &dyn Fn(&Path) -> std::io::Result<String>,
    nest: Nesting,
) -> Result<Elem> {
    let src = Src {
        file: file.clone(),
        line: lines.line(node.range().start),
    };
    let mut children = Vec::new();
    for child in node.children().filter(|n| n.is_element()) {
        if child.tag_name().name() == "include" {
            let csrc = Src {
                file: file.clone(),
                line: lines.line(child.range().start),
            };
            let Some(f) = child.attribute("file") else {
                return Err(csrc.err("<include> needs a 'file' attribute"));
            };
            if let Some(a) = child.attributes().find(|a| a.name() != "file") {
                return Err(csrc.err(format!("<include>: unsupported attribute '{}'", a.name())));
            }
            if nest.depth >= MAX_INCLUDE_DEPTH {
                return Err(csrc.err(format!("<include file=\"{f}\">: includes nested more than {MAX_INCLUDE_DEPTH} deep (a cycle?)")));
            }
            if nest.files.get() >= MAX_INCLUDED_FILES {
                return Err(csrc.err(format!(
                    "<include file=\"{f}\">: the model includes more than {MAX_INCLUDED_FILES} files in all"
                )));
            }
            nest.files.set(nest.files.get() + 1);
            let target: PathBuf = path.parent().unwrap_or(Path::new("")).join(f);
            let inner = Nesting {
                depth: nest.depth + 1,
                files: nest.files,
            };
            let included = read_tree(&target, read, inner, Some(&csrc))?;
            children.extend(included.children);
        } else {
            children.push(convert(lines, child, file, path, read, nest)?);
        }
    }
    Ok(Elem {
        name: node.tag_name().name().to_string(),
        attrs: node
            .attributes()
            .map(|a| (a.name().to_string(), a.value().to_string()))
            .collect(),
        children,
        src,
    })
}

// ---------------------------------------------------------------------------------------------
// Attribute parsing

pub(crate) fn parse_numbers(e: &Elem, key: &str, value: &str) -> Result<Vec<f64>> {
    value
        .split_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    e.src.err(format!(
                        "<{}> {key}=\"{value}\": '{t}' is not a finite number",
                        e.name
                    ))
                })
        })
        .collect()
}

/// Attributes of an element, falling back to its default class.
pub(crate) struct Attrs<'a> {
    pub(crate) elem: &'a Elem,
    pub(crate) defaults: Option<&'a HashMap<String, String>>,
}

impl<'a> Attrs<'a> {
    pub(crate) fn raw(&self, key: &str) -> Option<&'a str> {
        self.elem
            .attr(key)
            .or_else(|| self.defaults.and_then(|d| d.get(key)).map(|s| s.as_str()))
    }

    pub(crate) fn nums(&self, key: &str) -> Result<Option<Vec<f64>>> {
        self.raw(key)
            .map(|v| parse_numbers(self.elem, key, v))
            .transpose()
    }

    pub(crate) fn arr<const N: usize>(&self, key: &str) -> Result<Option<[f64; N]>> {
        match self.nums(key)? {
            None => Ok(None),
            Some(v) if v.len() == N => Ok(Some(std::array::from_fn(|i| v[i]))),
            Some(v) => Err(self.elem.src.err(format!(
                "<{}> {key}: expected {N} numbers, got {}",
                self.elem.name,
                v.len()
            ))),
        }
    }

    /// Up to N numbers; missing trailing entries keep the values underneath (MuJoCo's rule for prm
    /// arrays): `init`, overlaid by the default class's numbers, overlaid by the element's own.
    pub(crate) fn prefix<const N: usize>(&self, key: &str, init: [f64; N]) -> Result<[f64; N]> {
        let mut out = init;
        let class = self.defaults.and_then(|d| d.get(key));
        for text in class
            .map(String::as_str)
            .into_iter()
            .chain(self.elem.attr(key))
        {
            let v = parse_numbers(self.elem, key, text)?;
            if v.len() > N {
                return Err(self.elem.src.err(format!(
                    "<{}> {key}: at most {N} numbers, got {}",
                    self.elem.name,
                    v.len()
                )));
            }
            out[..v.len()].copy_from_slice(&v);
        }
        Ok(out)
    }

    pub(crate) fn f64(&self, key: &str) -> Result<Option<f64>> {
        Ok(self.arr::<1>(key)?.map(|a| a[0]))
    }

    pub(crate) fn f64_or(&self, key: &str, default: f64) -> Result<f64> {
        Ok(self.f64(key)?.unwrap_or(default))
    }

    pub(crate) fn bool_auto(&self, key: &str) -> Result<Option<bool>> {
        match self.raw(key) {
            None | Some("auto") => Ok(None),
            Some("true") => Ok(Some(true)),
            Some("false") => Ok(Some(false)),
            Some(v) => Err(self.elem.src.err(format!(
                "<{}> {key}=\"{v}\": expected true, false or auto",
                self.elem.name
            ))),
        }
    }

    pub(crate) fn choice<'c>(
        &self,
        key: &str,
        options: &[&'c str],
        default: &'c str,
    ) -> Result<&'c str> {
        match self.raw(key) {
            None => Ok(default),
            Some(v) => options.iter().copied().find(|o| *o == v).ok_or_else(|| {
                self.elem.src.err(format!(
                    "<{}> {key}=\"{v}\": supported values are {}",
                    self.elem.name,
                    options.join(", ")
                ))
            }),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Defaults

/// Attribute defaults of one class, per element kind.
#[derive(Debug, Clone, Default)]
pub(crate) struct ClassDefaults {
    pub(crate) kinds: HashMap<String, HashMap<String, String>>,
}

pub(crate) const DEFAULTABLE: [&str; 7] = [
    "joint", "geom", "site", "muscle", "general", "position", "tendon",
];

pub(crate) fn collect_defaults(
    e: &Elem,
    parent: &ClassDefaults,
    out: &mut HashMap<String, ClassDefaults>,
    top: bool,
) -> Result<()> {
    e.check_attrs(&["class"])?;
    let class = match (e.attr("class"), top) {
        (Some(c), _) => c.to_string(),
        (None, true) => "main".to_string(),
        (None, false) => return Err(e.src.err("a nested <default> needs a 'class' attribute")),
    };
    if out.contains_key(&class) {
        return Err(e
            .src
            .err(format!("default class '{class}' is defined twice")));
    }
    let mut mine = parent.clone();
    for child in &e.children {
        if DEFAULTABLE.contains(&child.name.as_str()) {
            let map = mine.kinds.entry(child.name.clone()).or_default();
            for (k, v) in &child.attrs {
                if k == "class" || k == "name" {
                    return Err(child
                        .src
                        .err(format!("<{}> in a <default> cannot have '{k}'", child.name)));
                }
                map.insert(k.clone(), v.clone());
            }
        } else if child.name != "default" {
            return Err(child.unsupported("default"));
        }
    }
    out.insert(class.clone(), mine.clone());
    for child in e.children.iter().filter(|c| c.name == "default") {
        collect_defaults(child, &mine, out, false)?;
    }
    Ok(())
}
