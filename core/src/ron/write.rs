//! Canonical text for scalars: the one place that decides how numbers and strings are written.

/// Writes a float so that it reads back to the same bits and always looks like a float
/// (`1.0`, `0.1`, `1e-7`). Non-finite values are never written (parameters reject them).
pub fn write_f64(out: &mut String, v: f64) {
    use std::fmt::Write;
    let _ = write!(out, "{v:?}");
}

/// Writes a quoted string with `\"`, `\\` and control characters escaped.
pub fn write_str(out: &mut String, s: &str) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\t' => out.push_str("\\t"),
            '\r' => out.push_str("\\r"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{{{:x}}}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ron::{parse_value, RonKind};

    #[test]
    fn floats_read_back_to_the_same_bits() {
        for v in [1.0, 0.1, 1e-7, 123456789.125, -2.5e300, 5e-324] {
            let mut s = String::new();
            write_f64(&mut s, v);
            match parse_value(&s).unwrap().kind {
                RonKind::Float(f) => assert_eq!(f.to_bits(), v.to_bits(), "{s}"),
                k => panic!("{s} read back as {k:?}"),
            }
        }
    }

    #[test]
    fn strings_with_quotes_and_newlines_read_back() {
        let original = "a \"quoted\"\n\\path\u{1}";
        let mut s = String::new();
        write_str(&mut s, original);
        assert_eq!(parse_value(&s).unwrap().as_str(), Some(original));
    }
}
