//! Recursive-descent parser for relume's RON subset.

use super::{Field, Pos, Ron, RonKind, SyntaxError};

/// Parses a whole document: exactly one value, then only whitespace and comments.
pub fn parse(text: &str) -> Result<Ron, SyntaxError> {
    let mut p = Parser::new(text);
    let v = p.value()?;
    p.skip_ws()?;
    if let Some(c) = p.peek() {
        return Err(p.err(format!("unexpected `{c}` after the end of the document")));
    }
    Ok(v)
}

/// Parses one value (used for `--set node.param=value`).
pub fn parse_value(text: &str) -> Result<Ron, SyntaxError> {
    parse(text)
}

/// How deeply lists, maps and parentheses may nest. Graph and scene files nest a handful of
/// levels; the limit keeps the recursive parser from overflowing its stack on hostile input.
pub const MAX_DEPTH: u32 = 128;

struct Parser<'a> {
    chars: std::iter::Peekable<std::str::Chars<'a>>,
    line: u32,
    col: u32,
    depth: u32,
}

impl<'a> Parser<'a> {
    fn new(text: &'a str) -> Self {
        Parser { chars: text.chars().peekable(), line: 1, col: 1, depth: 0 }
    }

    fn pos(&self) -> Pos {
        Pos { line: self.line, col: self.col }
    }

    fn err(&self, msg: String) -> SyntaxError {
        SyntaxError { pos: self.pos(), msg }
    }

    fn peek(&mut self) -> Option<char> {
        self.chars.peek().copied()
    }

    fn bump(&mut self) -> Option<char> {
        let c = self.chars.next()?;
        if c == '\n' {
            self.line += 1;
            self.col = 1;
        } else {
            self.col += 1;
        }
        Some(c)
    }

    fn skip_ws(&mut self) -> Result<(), SyntaxError> {
        loop {
            match self.peek() {
                Some(c) if c.is_whitespace() => {
                    self.bump();
                }
                Some('/') => {
                    let start = self.pos();
                    self.bump();
                    match self.bump() {
                        Some('/') => {
                            while let Some(c) = self.peek() {
                                if c == '\n' {
                                    break;
                                }
                                self.bump();
                            }
                        }
                        Some('*') => self.block_comment(start)?,
                        _ => return Err(SyntaxError { pos: start, msg: "stray `/`".into() }),
                    }
                }
                _ => return Ok(()),
            }
        }
    }

    fn block_comment(&mut self, start: Pos) -> Result<(), SyntaxError> {
        let mut depth = 1;
        while depth > 0 {
            match self.bump() {
                Some('*') if self.peek() == Some('/') => {
                    self.bump();
                    depth -= 1;
                }
                Some('/') if self.peek() == Some('*') => {
                    self.bump();
                    depth += 1;
                }
                Some(_) => {}
                None => return Err(SyntaxError { pos: start, msg: "unterminated `/*` comment".into() }),
            }
        }
        Ok(())
    }

    fn expect(&mut self, want: char) -> Result<(), SyntaxError> {
        self.skip_ws()?;
        match self.peek() {
            Some(c) if c == want => {
                self.bump();
                Ok(())
            }
            Some(c) => Err(self.err(format!("expected `{want}`, found `{c}`"))),
            None => Err(self.err(format!("expected `{want}`, found the end of the file"))),
        }
    }

    /// Runs `f` one nesting level deeper, refusing to go past `MAX_DEPTH`.
    fn nested<T>(&mut self, f: impl FnOnce(&mut Self) -> Result<T, SyntaxError>) -> Result<T, SyntaxError> {
        if self.depth >= MAX_DEPTH {
            return Err(self.err(format!("values nest more than {MAX_DEPTH} levels deep")));
        }
        self.depth += 1;
        let r = f(self);
        self.depth -= 1;
        r
    }

    fn value(&mut self) -> Result<Ron, SyntaxError> {
        self.skip_ws()?;
        let pos = self.pos();
        let kind = match self.peek() {
            None => return Err(self.err("expected a value, found the end of the file".into())),
            Some('"') => RonKind::Str(self.string()?),
            Some('[') => RonKind::List(self.nested(Self::list)?),
            Some('{') => RonKind::Map(self.nested(Self::map)?),
            Some('(') => self.nested(|p| p.parens(None))?,
            Some(c) if c == '-' || c == '+' || c.is_ascii_digit() || c == '.' => self.number()?,
            Some(c) if c.is_alphabetic() || c == '_' => {
                let id = self.ident();
                self.skip_ws()?;
                match id.as_str() {
                    "true" => RonKind::Bool(true),
                    "false" => RonKind::Bool(false),
                    _ if self.peek() == Some('(') => self.nested(|p| p.parens(Some(id)))?,
                    _ => RonKind::Ident(id),
                }
            }
            Some(c) => return Err(self.err(format!("expected a value, found `{c}`"))),
        };
        Ok(Ron { pos, kind })
    }

    fn ident(&mut self) -> String {
        let mut s = String::new();
        while let Some(c) = self.peek() {
            if c.is_alphanumeric() || c == '_' {
                s.push(c);
                self.bump();
            } else {
                break;
            }
        }
        s
    }

    fn string(&mut self) -> Result<String, SyntaxError> {
        let start = self.pos();
        self.bump();
        let mut s = String::new();
        loop {
            match self.bump() {
                None => return Err(SyntaxError { pos: start, msg: "unterminated string".into() }),
                Some('"') => return Ok(s),
                Some('\\') => s.push(self.escape()?),
                Some(c) => s.push(c),
            }
        }
    }

    fn escape(&mut self) -> Result<char, SyntaxError> {
        Ok(match self.bump() {
            Some('n') => '\n',
            Some('t') => '\t',
            Some('r') => '\r',
            Some('0') => '\0',
            Some('\\') => '\\',
            Some('"') => '"',
            Some('\'') => '\'',
            Some('u') => {
                self.expect('{')?;
                let mut hex = String::new();
                while let Some(c) = self.peek() {
                    if c == '}' {
                        break;
                    }
                    hex.push(c);
                    self.bump();
                }
                self.expect('}')?;
                u32::from_str_radix(&hex, 16)
                    .ok()
                    .and_then(char::from_u32)
                    .ok_or_else(|| self.err(format!("invalid unicode escape `\\u{{{hex}}}`")))?
            }
            Some(c) => return Err(self.err(format!("unknown escape `\\{c}`"))),
            None => return Err(self.err("unterminated string".into())),
        })
    }

    fn number(&mut self) -> Result<RonKind, SyntaxError> {
        let pos = self.pos();
        let mut s = String::new();
        while let Some(c) = self.peek() {
            let after_exp = matches!(s.chars().last(), Some('e' | 'E'));
            if c.is_ascii_digit() || c == '.' || c == 'e' || c == 'E' || c == '_' || ((c == '-' || c == '+') && (s.is_empty() || after_exp))
            {
                if c != '_' {
                    s.push(c);
                }
                self.bump();
            } else {
                break;
            }
        }
        let bad = || SyntaxError { pos, msg: format!("`{s}` is not a number") };
        if s.contains(['.', 'e', 'E']) {
            let v: f64 = s.parse().map_err(|_| bad())?;
            Ok(RonKind::Float(v))
        } else {
            let v: i64 = s.trim_start_matches('+').parse().map_err(|e: std::num::ParseIntError| match e.kind() {
                std::num::IntErrorKind::PosOverflow | std::num::IntErrorKind::NegOverflow => {
                    SyntaxError { pos, msg: format!("`{s}` is too large: whole numbers lie in {} ..= {}", i64::MIN, i64::MAX) }
                }
                _ => bad(),
            })?;
            Ok(RonKind::Int(v))
        }
    }

    /// Items separated by commas (a trailing comma allowed) up to `close`.
    fn items<T>(&mut self, close: char, mut item: impl FnMut(&mut Self) -> Result<T, SyntaxError>) -> Result<Vec<T>, SyntaxError> {
        let mut out = Vec::new();
        loop {
            self.skip_ws()?;
            if self.peek() == Some(close) {
                self.bump();
                return Ok(out);
            }
            out.push(item(self)?);
            self.skip_ws()?;
            match self.peek() {
                Some(',') => {
                    self.bump();
                }
                Some(c) if c == close => {}
                Some(c) => return Err(self.err(format!("expected `,` or `{close}`, found `{c}`"))),
                None => return Err(self.err(format!("expected `{close}`, found the end of the file"))),
            }
        }
    }

    fn list(&mut self) -> Result<Vec<Ron>, SyntaxError> {
        self.bump();
        self.items(']', |p| p.value())
    }

    fn map(&mut self) -> Result<Vec<(Ron, Ron)>, SyntaxError> {
        self.bump();
        self.items('}', |p| {
            let k = p.value()?;
            p.expect(':')?;
            let v = p.value()?;
            Ok((k, v))
        })
    }

    /// `( … )`: a struct when the first item is `ident:`, a tuple otherwise.
    fn parens(&mut self, name: Option<String>) -> Result<RonKind, SyntaxError> {
        self.bump();
        self.skip_ws()?;
        let is_struct = {
            let mut look = self.chars.clone();
            let mut seen_ident = false;
            loop {
                match look.next() {
                    Some(c) if c.is_alphanumeric() || c == '_' => seen_ident = true,
                    Some(c) if c.is_whitespace() && seen_ident => {}
                    Some(':') => break seen_ident,
                    _ => break false,
                }
            }
        };
        if is_struct {
            let fields = self.items(')', |p| {
                p.skip_ws()?;
                let pos = p.pos();
                let name = p.ident();
                p.expect(':')?;
                let value = p.value()?;
                Ok(Field { name, pos, value })
            })?;
            Ok(RonKind::Struct(name, fields))
        } else {
            Ok(RonKind::Tuple(name, self.items(')', |p| p.value())?))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_structs_maps_lists_and_scalars_with_positions() {
        let v = parse("Graph(\n  a: {\"x\": (k: 1, p: [1.5, -2, true, Foo])},\n  b: (),\n)").unwrap();
        let fields = v.fields().unwrap();
        assert_eq!(fields[0].name, "a");
        assert_eq!(fields[0].pos, Pos { line: 2, col: 3 });
        assert_eq!(fields[1].value.fields().unwrap().len(), 0);
        let RonKind::Map(m) = &fields[0].value.kind else { panic!() };
        assert_eq!(m[0].0.as_str(), Some("x"));
        let inner = m[0].1.fields().unwrap();
        let RonKind::List(items) = &inner[1].value.kind else { panic!() };
        assert_eq!(items[0].kind, RonKind::Float(1.5));
        assert_eq!(items[1].kind, RonKind::Int(-2));
        assert_eq!(items[2].kind, RonKind::Bool(true));
        assert_eq!(items[3].kind, RonKind::Ident("Foo".into()));
    }

    #[test]
    fn comments_are_skipped() {
        let v = parse("// head\n( /* a /* nested */ one */ a: 1, // tail\n)").unwrap();
        assert_eq!(v.fields().unwrap()[0].value.kind, RonKind::Int(1));
    }

    #[test]
    fn errors_carry_the_line_and_column() {
        let e = parse("(\n  a: 1\n  b: 2)").unwrap_err();
        assert_eq!(e.pos.line, 3);
        assert!(e.msg.contains("expected `,`"), "{e}");
        let e = parse("(a: \"open").unwrap_err();
        assert!(e.msg.contains("unterminated string"));
        let e = parse("(a: 1.2.3)").unwrap_err();
        assert!(e.msg.contains("not a number"), "{e}");
        assert!(parse("").is_err());
        assert!(parse("(a: 1) x").is_err());
    }

    /// A deeply nested value (200,000 open brackets) overflowed the recursive parser's stack:
    /// the process aborted instead of reporting an error.
    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        for open in ["[", "(", "{", "A(", "(a: "] {
            let text = open.repeat(200_000);
            let e = parse(&text).unwrap_err();
            assert!(e.msg.contains("nest more than 128 levels"), "{open}: {e}");
            assert_eq!(e.pos.line, 1);
        }
        let ok = format!("{}A{}", "[".repeat(MAX_DEPTH as usize), "]".repeat(MAX_DEPTH as usize));
        assert!(parse(&ok).is_ok(), "{MAX_DEPTH} levels are allowed");
    }

    #[test]
    fn tuples_and_named_tuples() {
        let v = parse("(\"a.b\", \"c.d\")").unwrap();
        assert!(matches!(v.kind, RonKind::Tuple(None, ref i) if i.len() == 2));
        let v = parse("Rgb(1, 2.5, 3)").unwrap();
        assert!(matches!(v.kind, RonKind::Tuple(Some(ref n), ref i) if n == "Rgb" && i.len() == 3));
    }

    #[test]
    fn a_whole_number_past_64_bits_is_too_large_not_malformed() {
        let e = parse("(n: 99999999999999999999)").unwrap_err();
        assert_eq!(e.msg, "`99999999999999999999` is too large: whole numbers lie in -9223372036854775808 ..= 9223372036854775807");
        assert_eq!((e.pos.line, e.pos.col), (1, 5));
        let RonKind::Struct(_, f) = parse("(n: -9223372036854775808)").unwrap().kind else { panic!() };
        assert_eq!(f[0].value.kind, RonKind::Int(i64::MIN));
    }
}
