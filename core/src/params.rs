//! Parameter schemas (type, default, range, unit, help), values, validation and typed access.

use crate::error::NodeError;
use crate::hash::Hasher;
use crate::ron::{write_f64, write_str, Ron, RonKind};
use std::path::{Path, PathBuf};

/// What a parameter holds and which values are allowed.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamKind {
    Float {
        min: f64,
        max: f64,
    },
    Int {
        min: i64,
        max: i64,
    },
    Bool,
    Text,
    /// A file the node reads; the cache key hashes its content, not just its name.
    InputFile,
    /// A file the node writes.
    OutputFile,
    Enum(&'static [&'static str]),
    /// Three floats in `[min, max]` (a colour for the editor).
    Rgb {
        min: f64,
        max: f64,
    },
    /// Three finite floats (a position or direction).
    Vec3,
}

impl ParamKind {
    pub fn type_name(&self) -> &'static str {
        match self {
            ParamKind::Float { .. } => "float",
            ParamKind::Int { .. } => "int",
            ParamKind::Bool => "bool",
            ParamKind::Text => "text",
            ParamKind::InputFile => "input file",
            ParamKind::OutputFile => "output file",
            ParamKind::Enum(_) => "enum",
            ParamKind::Rgb { .. } => "rgb",
            ParamKind::Vec3 => "vec3",
        }
    }

    /// The allowed range or variants as text, e.g. `[0, 64]` or `Clamp | Reinhard`.
    pub fn range_text(&self) -> String {
        match self {
            ParamKind::Float { min, max } | ParamKind::Rgb { min, max } => format!("[{min}, {max}]"),
            ParamKind::Int { min, max } => format!("[{min}, {max}]"),
            ParamKind::Enum(v) => v.join(" | "),
            _ => String::new(),
        }
    }
}

/// One parameter of a node.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamSpec {
    pub name: &'static str,
    pub kind: ParamKind,
    /// `None`: the parameter is required.
    pub default: Option<ParamValue>,
    pub unit: &'static str,
    pub help: &'static str,
    /// The value tests, CI and the benches' test mode run at (`#[param(test = …)]`): the
    /// expensive knobs turned down so that every graph runs in seconds. `None`: the graph's own
    /// value is cheap enough.
    pub test: Option<ParamValue>,
    /// For a file parameter, the extensions it takes (lower case, without the dot; empty: any),
    /// checked when the graph loads so that a file the node cannot read or write is refused
    /// before anything runs.
    pub extensions: &'static [&'static str],
    /// For an input file that names more files (a scene: its meshes and maps), the function
    /// that lists them, joined to the file's folder, without reading them
    /// (`#[param(also_reads = f)]`): the run's reads include them (`RunFiles`).
    pub also_reads: Option<FileList>,
}

/// The files an input file names, found by reading it alone (`ParamSpec::also_reads`).
#[derive(Clone, Copy)]
pub struct FileList(pub fn(&Path) -> Vec<PathBuf>);

impl std::fmt::Debug for FileList {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("FileList(..)")
    }
}

impl PartialEq for FileList {
    fn eq(&self, other: &Self) -> bool {
        self.0 as usize == other.0 as usize
    }
}

/// A parameter value as written in a graph file.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamValue {
    Float(f64),
    Int(i64),
    Bool(bool),
    Text(String),
    /// An enum variant (a bare identifier in RON).
    Ident(String),
    Tuple(Vec<ParamValue>),
}

impl ParamValue {
    /// Converts a parsed RON value; structs, maps and lists are not parameter values.
    pub fn from_ron(v: &Ron) -> Result<ParamValue, String> {
        Ok(match &v.kind {
            RonKind::Int(i) => ParamValue::Int(*i),
            RonKind::Float(f) => ParamValue::Float(*f),
            RonKind::Bool(b) => ParamValue::Bool(*b),
            RonKind::Str(s) => ParamValue::Text(s.clone()),
            RonKind::Ident(s) => ParamValue::Ident(s.clone()),
            RonKind::Tuple(None, items) => ParamValue::Tuple(items.iter().map(ParamValue::from_ron).collect::<Result<_, _>>()?),
            _ => return Err(format!("{} is not a parameter value (numbers, strings, booleans, identifiers and tuples are)", v.what())),
        })
    }

    /// Canonical RON text.
    pub fn write(&self, out: &mut String) {
        match self {
            ParamValue::Float(f) => write_f64(out, *f),
            ParamValue::Int(i) => out.push_str(&i.to_string()),
            ParamValue::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
            ParamValue::Text(s) => write_str(out, s),
            ParamValue::Ident(s) => out.push_str(s),
            ParamValue::Tuple(items) => {
                out.push('(');
                for (i, v) in items.iter().enumerate() {
                    if i > 0 {
                        out.push_str(", ");
                    }
                    v.write(out);
                }
                out.push(')');
            }
        }
    }

    pub fn to_text(&self) -> String {
        let mut s = String::new();
        self.write(&mut s);
        s
    }

    fn hash_into(&self, h: &mut Hasher) {
        match self {
            ParamValue::Float(f) => h.tag(1).f64(*f),
            ParamValue::Int(i) => h.tag(2).i64(*i),
            ParamValue::Bool(b) => h.tag(3).u64(*b as u64),
            ParamValue::Text(s) => h.tag(4).str(s),
            ParamValue::Ident(s) => h.tag(5).str(s),
            ParamValue::Tuple(items) => {
                h.tag(6).u64(items.len() as u64);
                for v in items {
                    v.hash_into(h);
                }
                h
            }
        };
    }
}

impl ParamSpec {
    /// A value written as text for this parameter, as `--set` takes it: RON, or the bare
    /// text for string and file parameters (unchecked: `check` follows).
    pub fn read_text(&self, value: &str) -> Result<ParamValue, String> {
        match crate::ron::parse_value(value).ok().and_then(|r| ParamValue::from_ron(&r).ok()) {
            Some(v) => Ok(v),
            None if matches!(self.kind, ParamKind::Text | ParamKind::InputFile | ParamKind::OutputFile) => {
                Ok(ParamValue::Text(value.to_string()))
            }
            None => Err(format!("cannot read `{value}` as a value")),
        }
    }

    /// Checks a value against the schema and normalises it (an integer given for a float
    /// parameter becomes a float). The error says what was expected.
    pub fn check(&self, v: &ParamValue) -> Result<ParamValue, String> {
        let num = |v: &ParamValue| match v {
            ParamValue::Float(f) => Some(*f),
            ParamValue::Int(i) => Some(*i as f64),
            _ => None,
        };
        let unit = if self.unit.is_empty() { String::new() } else { format!(" {}", self.unit) };
        match &self.kind {
            ParamKind::Float { min, max } => {
                let f = num(v).ok_or_else(|| format!("expected a number, found `{}`", v.to_text()))?;
                if !f.is_finite() || f < *min || f > *max {
                    return Err(format!("{} is out of range [{min}, {max}]{unit}", v.to_text()));
                }
                // -0 and 0 are one value: one cache key.
                Ok(ParamValue::Float(f + 0.0))
            }
            ParamKind::Int { min, max } => match v {
                ParamValue::Int(i) if i >= min && i <= max => Ok(v.clone()),
                ParamValue::Int(i) => Err(format!("{i} is out of range [{min}, {max}]{unit}")),
                _ => Err(format!("expected an integer, found `{}`", v.to_text())),
            },
            ParamKind::Bool => match v {
                ParamValue::Bool(_) => Ok(v.clone()),
                _ => Err(format!("expected `true` or `false`, found `{}`", v.to_text())),
            },
            ParamKind::Text | ParamKind::InputFile | ParamKind::OutputFile => match v {
                ParamValue::Text(s) if s.is_empty() && self.kind != ParamKind::Text => {
                    Err("expected a file path, found an empty string".into())
                }
                ParamValue::Text(s) if !self.extensions.is_empty() => {
                    let ext = Path::new(s).extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
                    if self.extensions.contains(&ext.as_str()) {
                        Ok(v.clone())
                    } else {
                        let takes: Vec<String> = self.extensions.iter().map(|e| format!(".{e}")).collect();
                        let has = if ext.is_empty() { "no extension".to_string() } else { format!("the extension .{ext}") };
                        Err(format!("\"{s}\" has {has}; this parameter takes a {} file", takes.join(" or ")))
                    }
                }
                ParamValue::Text(_) => Ok(v.clone()),
                _ => Err(format!("expected a quoted string, found `{}`", v.to_text())),
            },
            ParamKind::Enum(variants) => match v {
                ParamValue::Ident(s) | ParamValue::Text(s) if variants.contains(&s.as_str()) => Ok(ParamValue::Ident(s.clone())),
                _ => Err(format!("`{}` is not one of {}", v.to_text(), variants.join(", "))),
            },
            ParamKind::Rgb { .. } | ParamKind::Vec3 => {
                let ParamValue::Tuple(items) = v else {
                    return Err(format!("expected a tuple of three numbers, found `{}`", v.to_text()));
                };
                let (min, max) = match self.kind {
                    ParamKind::Rgb { min, max } => (min, max),
                    _ => (f64::MIN, f64::MAX),
                };
                let vals: Option<Vec<f64>> = items.iter().map(num).collect();
                match vals {
                    Some(vals) if vals.len() == 3 => {
                        if vals.iter().any(|x| !x.is_finite() || *x < min || *x > max) {
                            return Err(format!("{} has a component out of range [{min}, {max}]{unit}", v.to_text()));
                        }
                        Ok(ParamValue::Tuple(vals.into_iter().map(|x| ParamValue::Float(x + 0.0)).collect()))
                    }
                    _ => Err(format!("expected a tuple of three numbers, found `{}`", v.to_text())),
                }
            }
        }
    }
}

/// A node's parameter schema, built with a chain of calls:
/// `Schema::new().float("sigma", 1.0, 0.0, 64.0).unit("px").help("…")`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Schema(pub Vec<ParamSpec>);

impl Schema {
    pub fn new() -> Self {
        Schema(Vec::new())
    }
    fn push(mut self, name: &'static str, kind: ParamKind, default: Option<ParamValue>) -> Self {
        debug_assert!(self.get(name).is_none(), "parameter {name} declared twice");
        self.0.push(ParamSpec { name, kind, default, unit: "", help: "", test: None, extensions: &[], also_reads: None });
        self
    }
    pub fn float(self, name: &'static str, default: f64, min: f64, max: f64) -> Self {
        self.push(name, ParamKind::Float { min, max }, Some(ParamValue::Float(default)))
    }
    pub fn int(self, name: &'static str, default: i64, min: i64, max: i64) -> Self {
        self.push(name, ParamKind::Int { min, max }, Some(ParamValue::Int(default)))
    }
    pub fn bool(self, name: &'static str, default: bool) -> Self {
        self.push(name, ParamKind::Bool, Some(ParamValue::Bool(default)))
    }
    pub fn text(self, name: &'static str, default: &str) -> Self {
        self.push(name, ParamKind::Text, Some(ParamValue::Text(default.into())))
    }
    /// A required file the node reads (hashed by content for the cache key).
    pub fn input_file(self, name: &'static str) -> Self {
        self.push(name, ParamKind::InputFile, None)
    }
    /// A required file the node writes.
    pub fn output_file(self, name: &'static str) -> Self {
        self.push(name, ParamKind::OutputFile, None)
    }
    pub fn enumeration(self, name: &'static str, variants: &'static [&'static str], default: &str) -> Self {
        debug_assert!(variants.contains(&default));
        self.push(name, ParamKind::Enum(variants), Some(ParamValue::Ident(default.into())))
    }
    pub fn rgb(self, name: &'static str, default: [f64; 3], min: f64, max: f64) -> Self {
        let d = ParamValue::Tuple(default.iter().map(|&x| ParamValue::Float(x)).collect());
        self.push(name, ParamKind::Rgb { min, max }, Some(d))
    }
    pub fn vec3(self, name: &'static str, default: [f64; 3]) -> Self {
        let d = ParamValue::Tuple(default.iter().map(|&x| ParamValue::Float(x)).collect());
        self.push(name, ParamKind::Vec3, Some(d))
    }
    /// Sets the unit of the last parameter.
    pub fn unit(mut self, unit: &'static str) -> Self {
        self.0.last_mut().expect("unit() after a parameter").unit = unit;
        self
    }
    /// Sets the one-line help of the last parameter.
    pub fn help(mut self, help: &'static str) -> Self {
        self.0.last_mut().expect("help() after a parameter").help = help;
        self
    }
    pub fn get(&self, name: &str) -> Option<&ParamSpec> {
        self.0.iter().find(|p| p.name == name)
    }
}

/// The full, checked parameter set of one node for one run: every schema parameter with its
/// value (defaults filled in), file paths resolved against the graph's folder.
#[derive(Clone, Debug)]
pub struct ParamValues {
    values: Vec<(&'static str, ParamValue)>,
    base_dir: PathBuf,
}

impl ParamValues {
    /// Fills defaults and normalises every value once through the schema (`2` for a float
    /// parameter becomes `2.0`, an enum given as a string becomes an identifier, −0 becomes 0),
    /// so that equal values give one cache key however they were written. The explicit values
    /// must already have been checked by the loader. Returns the names of required parameters
    /// that are missing.
    pub fn resolve(schema: &Schema, explicit: &[(String, ParamValue)], base_dir: &Path) -> Result<ParamValues, Vec<&'static str>> {
        let mut values = Vec::with_capacity(schema.0.len());
        let mut missing = Vec::new();
        for spec in &schema.0 {
            match explicit.iter().find(|(n, _)| n == spec.name).map(|(_, v)| v).or(spec.default.as_ref()) {
                Some(v) => values.push((spec.name, spec.check(v).unwrap_or_else(|_| v.clone()))),
                None => missing.push(spec.name),
            }
        }
        if missing.is_empty() {
            Ok(ParamValues { values, base_dir: base_dir.to_path_buf() })
        } else {
            Err(missing)
        }
    }

    /// Every parameter with its value, in schema order.
    pub fn iter(&self) -> impl Iterator<Item = (&'static str, &ParamValue)> {
        self.values.iter().map(|(n, v)| (*n, v))
    }

    /// Canonical RON text of every value, defaults included: `(sigma: 1.0, op: Aces)`.
    pub fn to_text(&self) -> String {
        let items: Vec<String> = self.iter().map(|(n, v)| format!("{n}: {}", v.to_text())).collect();
        format!("({})", items.join(", "))
    }

    fn get(&self, name: &str) -> &ParamValue {
        match self.values.iter().find(|(n, _)| *n == name) {
            Some((_, v)) => v,
            None => panic!("node asked for parameter `{name}` that its schema does not declare"),
        }
    }

    pub fn float(&self, name: &str) -> f64 {
        match self.get(name) {
            ParamValue::Float(f) => *f,
            ParamValue::Int(i) => *i as f64,
            v => panic!("parameter `{name}` is {v:?}, not a float"),
        }
    }
    pub fn int(&self, name: &str) -> i64 {
        match self.get(name) {
            ParamValue::Int(i) => *i,
            v => panic!("parameter `{name}` is {v:?}, not an integer"),
        }
    }
    pub fn bool(&self, name: &str) -> bool {
        match self.get(name) {
            ParamValue::Bool(b) => *b,
            v => panic!("parameter `{name}` is {v:?}, not a bool"),
        }
    }
    pub fn text(&self, name: &str) -> &str {
        match self.get(name) {
            ParamValue::Text(s) | ParamValue::Ident(s) => s,
            v => panic!("parameter `{name}` is {v:?}, not text"),
        }
    }
    /// An enum parameter's variant name.
    pub fn variant(&self, name: &str) -> &str {
        self.text(name)
    }
    /// A file parameter resolved against the graph file's folder.
    pub fn path(&self, name: &str) -> PathBuf {
        self.base_dir.join(self.text(name))
    }
    pub fn triple(&self, name: &str) -> [f64; 3] {
        match self.get(name) {
            ParamValue::Tuple(items) if items.len() == 3 => {
                let f = |v: &ParamValue| match v {
                    ParamValue::Float(f) => *f,
                    ParamValue::Int(i) => *i as f64,
                    _ => panic!("parameter `{name}` has a non-numeric component"),
                };
                [f(&items[0]), f(&items[1]), f(&items[2])]
            }
            v => panic!("parameter `{name}` is {v:?}, not a triple"),
        }
    }

    /// Canonical hash of the values in schema order; input files are hashed by content.
    pub fn canonical_hash(&self, schema: &Schema, h: &mut Hasher) -> Result<(), String> {
        h.u64(self.values.len() as u64);
        for (spec, (name, v)) in schema.0.iter().zip(&self.values) {
            h.str(name);
            v.hash_into(h);
            if spec.kind == ParamKind::InputFile {
                let path = self.path(name);
                let content = crate::content_hash(&path).map_err(|e| format!("parameter `{name}`: cannot read {}: {e}", path.display()))?;
                h.hash(&content);
            }
        }
        Ok(())
    }
}

/// A node's typed parameters, built from the checked values (`#[derive(Params)]`).
pub trait Params: Sized + Send + Sync + 'static {
    fn schema() -> Schema;
    fn from_values(v: &ParamValues) -> Result<Self, NodeError>;
}

/// A choice parameter (`#[derive(ParamEnum)]`): variants listed once, in order.
pub trait ParamEnum: Sized + Copy {
    const VARIANTS: &'static [&'static str];
    fn from_name(name: &str) -> Option<Self>;
    fn name(&self) -> &'static str;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn schema() -> Schema {
        Schema::new()
            .float("sigma", 1.0, 0.0, 64.0)
            .unit("px")
            .help("blur")
            .int("n", 3, 1, 10)
            .enumeration("op", &["A", "B"], "A")
            .rgb("c", [1.0, 1.0, 1.0], 0.0, 1.0)
            .input_file("path")
    }

    #[test]
    fn ranges_units_and_types_are_checked() {
        let s = schema();
        assert_eq!(s.get("sigma").unwrap().check(&ParamValue::Int(2)), Ok(ParamValue::Float(2.0)));
        let e = s.get("sigma").unwrap().check(&ParamValue::Float(65.0)).unwrap_err();
        assert!(e.contains("out of range [0, 64] px"), "{e}");
        assert!(s.get("n").unwrap().check(&ParamValue::Float(2.0)).is_err());
        assert!(s.get("op").unwrap().check(&ParamValue::Ident("C".into())).unwrap_err().contains("A, B"));
        let bad_rgb = ParamValue::Tuple(vec![ParamValue::Float(0.5), ParamValue::Float(2.0), ParamValue::Int(0)]);
        assert!(s.get("c").unwrap().check(&bad_rgb).is_err());
        assert!(s.get("path").unwrap().check(&ParamValue::Text(String::new())).is_err());
    }

    #[test]
    fn defaults_fill_in_and_required_parameters_are_reported_missing() {
        let s = schema();
        let missing = ParamValues::resolve(&s, &[], Path::new(".")).unwrap_err();
        assert_eq!(missing, vec!["path"]);
        let v = ParamValues::resolve(&s, &[("path".into(), ParamValue::Text("a.exr".into()))], Path::new("/g")).unwrap();
        assert_eq!(v.float("sigma"), 1.0);
        assert_eq!(v.int("n"), 3);
        assert_eq!(v.variant("op"), "A");
        assert_eq!(v.triple("c"), [1.0; 3]);
        assert_eq!(v.path("path"), PathBuf::from("/g/a.exr"));
    }

    #[test]
    fn a_file_parameter_with_extensions_takes_only_those() {
        let spec = ParamSpec { extensions: &["exr", "png"], ..Schema::new().output_file("path").0.remove(0) };
        assert!(spec.check(&ParamValue::Text("out/a.PNG".into())).is_ok());
        assert_eq!(
            spec.check(&ParamValue::Text("x.ron".into())).unwrap_err(),
            "\"x.ron\" has the extension .ron; this parameter takes a .exr or .png file"
        );
        assert_eq!(
            spec.check(&ParamValue::Text("x".into())).unwrap_err(),
            "\"x\" has no extension; this parameter takes a .exr or .png file"
        );
        let any = Schema::new().output_file("path").0.remove(0);
        assert!(any.check(&ParamValue::Text("x.ron".into())).is_ok());
    }
}
