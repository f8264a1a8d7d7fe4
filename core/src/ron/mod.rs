//! The subset of RON that relume graph files use, parsed with a position on every value.
//!
//! relume parses RON itself instead of going through the `ron` crate because every load error
//! must name the line of the node and parameter it is about, and `ron::Value` keeps no
//! positions; writing is done by `graph::save` in one canonical layout so that a file relume
//! saved loads and saves back byte-identical.

pub mod fields;
mod parse;
mod write;

pub use parse::{parse, parse_value};
pub use write::{write_f64, write_str};

use std::fmt;

/// A line/column position in a source text (both 1-based).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Pos {
    pub line: u32,
    pub col: u32,
}

impl fmt::Display for Pos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.line, self.col)
    }
}

/// A RON value with the position where it starts.
#[derive(Clone, Debug, PartialEq)]
pub struct Ron {
    pub pos: Pos,
    pub kind: RonKind,
}

/// A named field of a struct, with the position of its name.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    pub name: String,
    pub pos: Pos,
    pub value: Ron,
}

#[derive(Clone, Debug, PartialEq)]
pub enum RonKind {
    Int(i64),
    Float(f64),
    Str(String),
    Bool(bool),
    /// A bare identifier: an enum variant such as `PoissonDisk`.
    Ident(String),
    List(Vec<Ron>),
    Map(Vec<(Ron, Ron)>),
    /// `(a, b)` or `Name(a, b)`; `()` is an empty tuple.
    Tuple(Option<String>, Vec<Ron>),
    /// `(a: 1)` or `Name(a: 1)`.
    Struct(Option<String>, Vec<Field>),
}

impl Ron {
    /// A short description of what kind of value this is, for error messages.
    pub fn what(&self) -> &'static str {
        match &self.kind {
            RonKind::Int(_) => "an integer",
            RonKind::Float(_) => "a number",
            RonKind::Str(_) => "a string",
            RonKind::Bool(_) => "a boolean",
            RonKind::Ident(_) => "an identifier",
            RonKind::List(_) => "a list",
            RonKind::Map(_) => "a map",
            RonKind::Tuple(..) => "a tuple",
            RonKind::Struct(..) => "a struct",
        }
    }

    /// The fields of a struct; `()` counts as a struct with no fields.
    pub fn fields(&self) -> Option<&[Field]> {
        match &self.kind {
            RonKind::Struct(_, f) => Some(f),
            RonKind::Tuple(_, items) if items.is_empty() => Some(&[]),
            _ => None,
        }
    }

    pub fn as_str(&self) -> Option<&str> {
        match &self.kind {
            RonKind::Str(s) => Some(s),
            _ => None,
        }
    }

    /// Integers and floats as f64.
    pub fn as_f64(&self) -> Option<f64> {
        match self.kind {
            RonKind::Int(i) => Some(i as f64),
            RonKind::Float(f) => Some(f),
            _ => None,
        }
    }
}

/// A syntax error with its position.
#[derive(Clone, Debug, PartialEq)]
pub struct SyntaxError {
    pub pos: Pos,
    pub msg: String,
}

impl fmt::Display for SyntaxError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.pos, self.msg)
    }
}
