//! Typed reading of RON structs with positions in every error: used by file formats other
//! than graphs (scene files) so that they report the same `file:line:col` messages.

use super::{Field, Pos, Ron, RonKind, SyntaxError};

fn err(pos: Pos, msg: impl Into<String>) -> SyntaxError {
    SyntaxError { pos, msg: msg.into() }
}

/// The fields of one struct; unknown fields are reported by `finish`.
pub struct Fields<'a> {
    fields: &'a [Field],
    used: Vec<bool>,
    pos: Pos,
    what: String,
}

impl<'a> Fields<'a> {
    /// `what` names the struct in messages ("camera", "Obj shape").
    pub fn new(v: &'a Ron, what: &str) -> Result<Fields<'a>, SyntaxError> {
        let fields = v.fields().ok_or_else(|| err(v.pos, format!("{what} must be `( name: value, … )`, found {}", v.what())))?;
        Ok(Fields { fields, used: vec![false; fields.len()], pos: v.pos, what: what.to_string() })
    }

    pub fn opt(&mut self, name: &str) -> Option<&'a Ron> {
        let i = self.fields.iter().position(|f| f.name == name)?;
        self.used[i] = true;
        Some(&self.fields[i].value)
    }

    pub fn req(&mut self, name: &str) -> Result<&'a Ron, SyntaxError> {
        let what = self.what.clone();
        self.opt(name).ok_or_else(|| err(self.pos, format!("{what} needs `{name}`")))
    }

    /// Errors on the first field that was never asked for, listing the known ones.
    pub fn finish(self, known: &[&str]) -> Result<(), SyntaxError> {
        match self.fields.iter().zip(&self.used).find(|(_, u)| !**u) {
            Some((f, _)) => Err(err(f.pos, format!("unknown field `{}` in {} (it has: {})", f.name, self.what, known.join(", ")))),
            None => Ok(()),
        }
    }
}

pub fn f64_of(v: &Ron, what: &str) -> Result<f64, SyntaxError> {
    match v.as_f64() {
        Some(x) if x.is_finite() => Ok(x),
        _ => Err(err(v.pos, format!("{what} must be a finite number, found {}", v.what()))),
    }
}

/// A number in `[min, max]`.
pub fn f64_in(v: &Ron, what: &str, min: f64, max: f64) -> Result<f64, SyntaxError> {
    let x = f64_of(v, what)?;
    if x < min || x > max {
        return Err(err(v.pos, format!("{what} = {x} is out of range [{min}, {max}]")));
    }
    Ok(x)
}

pub fn usize_in(v: &Ron, what: &str, min: usize, max: usize) -> Result<usize, SyntaxError> {
    match v.kind {
        RonKind::Int(i) if i >= min as i64 && i <= max as i64 => Ok(i as usize),
        RonKind::Int(i) => Err(err(v.pos, format!("{what} = {i} is out of range [{min}, {max}]"))),
        _ => Err(err(v.pos, format!("{what} must be a whole number, found {}", v.what()))),
    }
}

pub fn bool_of(v: &Ron, what: &str) -> Result<bool, SyntaxError> {
    match v.kind {
        RonKind::Bool(b) => Ok(b),
        _ => Err(err(v.pos, format!("{what} must be true or false, found {}", v.what()))),
    }
}

pub fn str_of<'a>(v: &'a Ron, what: &str) -> Result<&'a str, SyntaxError> {
    v.as_str().ok_or_else(|| err(v.pos, format!("{what} must be a quoted string, found {}", v.what())))
}

/// `(x, y, z)` of finite numbers; a single number `x` means `(x, x, x)` when `allow_scalar`.
pub fn triple(v: &Ron, what: &str, allow_scalar: bool) -> Result<[f64; 3], SyntaxError> {
    if allow_scalar {
        if let Some(x) = v.as_f64() {
            return Ok([f64_of(v, what)?, x, x]);
        }
    }
    match &v.kind {
        RonKind::Tuple(None, items) if items.len() == 3 => {
            Ok([f64_of(&items[0], what)?, f64_of(&items[1], what)?, f64_of(&items[2], what)?])
        }
        _ => Err(err(v.pos, format!("{what} must be (x, y, z), found {}", v.what()))),
    }
}

/// A list's items.
pub fn list_of<'a>(v: &'a Ron, what: &str) -> Result<&'a [Ron], SyntaxError> {
    match &v.kind {
        RonKind::List(items) => Ok(items),
        _ => Err(err(v.pos, format!("{what} must be a list [ … ], found {}", v.what()))),
    }
}

/// A map with string keys.
pub fn map_of<'a>(v: &'a Ron, what: &str) -> Result<Vec<(&'a str, Pos, &'a Ron)>, SyntaxError> {
    match &v.kind {
        RonKind::Map(m) => m.iter().map(|(k, val)| Ok((str_of(k, &format!("a key of {what}"))?, k.pos, val))).collect(),
        _ => Err(err(v.pos, format!("{what} must be a map {{ \"name\": … }}, found {}", v.what()))),
    }
}

/// `Name(fields…)`, `Name` or `Name()`: the variant name and the value (for its fields).
pub fn variant<'a>(v: &'a Ron, what: &str, known: &[&str]) -> Result<(&'a str, &'a Ron), SyntaxError> {
    let name = match &v.kind {
        RonKind::Struct(Some(n), _) | RonKind::Tuple(Some(n), _) | RonKind::Ident(n) => n.as_str(),
        _ => return Err(err(v.pos, format!("{what} must be one of {}, found {}", known.join(", "), v.what()))),
    };
    if !known.contains(&name) {
        return Err(err(v.pos, format!("unknown {what} `{name}` (known: {})", known.join(", "))));
    }
    Ok((name, v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ron::parse;

    #[test]
    fn unknown_fields_and_bad_values_name_their_position() {
        let v = parse("(a: 1.5, b: (1, 2, 3),\n c: 9)").unwrap();
        let mut f = Fields::new(&v, "thing").unwrap();
        assert_eq!(f64_of(f.req("a").unwrap(), "a").unwrap(), 1.5);
        assert_eq!(triple(f.req("b").unwrap(), "b", false).unwrap(), [1.0, 2.0, 3.0]);
        assert!(f.req("zz").unwrap_err().msg.contains("thing needs `zz`"));
        let e = f.finish(&["a", "b"]).unwrap_err();
        assert_eq!((e.pos.line, e.pos.col), (2, 2));
        assert!(e.msg.contains("unknown field `c` in thing"));
        let v = parse("Sphere(radius: 1)").unwrap();
        assert_eq!(variant(&v, "shape", &["Obj", "Sphere"]).unwrap().0, "Sphere");
        assert!(variant(&v, "shape", &["Obj"]).unwrap_err().msg.contains("unknown shape `Sphere`"));
        assert!(usize_in(&parse("-1").unwrap(), "n", 0, 5).is_err());
    }
}
