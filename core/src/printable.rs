//! Text for a terminal: what a graph, a scene or a command line hands relume (a node id, a
//! kind, a path) is echoed in messages, and a control character in it would act on the
//! terminal — clear the screen, set the window title, ring the bell — while a bidirectional
//! override would make the message read otherwise than it is.

use std::borrow::Cow;

/// Whether `c` must not reach a terminal as it is: a control character other than the line
/// break and the tab, or a bidirectional-text control.
fn unsafe_char(c: char) -> bool {
    (c.is_control() && c != '\n' && c != '\t')
        || matches!(c, '\u{061c}' | '\u{200e}' | '\u{200f}' | '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}')
}

/// `s` with every control and bidirectional-control character written as its escape
/// (`\u{1b}`); line breaks and tabs kept. Borrowed when there is nothing to escape.
pub fn printable(s: &str) -> Cow<'_, str> {
    if !s.chars().any(unsafe_char) {
        return Cow::Borrowed(s);
    }
    Cow::Owned(s.chars().map(|c| if unsafe_char(c) { c.escape_unicode().to_string() } else { c.to_string() }).collect())
}

/// The longest line a message shows whole, in characters; a longer one (a megabyte-long path
/// from a graph) keeps its start and end.
pub const MAX_MESSAGE_LINE: usize = 2000;

/// `s` with every line longer than `MAX_MESSAGE_LINE` characters cut in the middle, saying how
/// much was left out: what an error or warning prints.
pub fn clipped(s: &str) -> Cow<'_, str> {
    if s.lines().all(|l| l.len() <= MAX_MESSAGE_LINE) {
        return Cow::Borrowed(s);
    }
    let (head, tail) = (MAX_MESSAGE_LINE * 3 / 4, MAX_MESSAGE_LINE / 5);
    let lines: Vec<String> = s
        .split('\n')
        .map(|l| {
            let n = l.chars().count();
            if n <= MAX_MESSAGE_LINE {
                return l.to_string();
            }
            let start: String = l.chars().take(head).collect();
            let end: String = l.chars().skip(n - tail).collect();
            format!("{start}…[{} characters left out]…{end}", n - head - tail)
        })
        .collect();
    Cow::Owned(lines.join("\n"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn controls_and_bidi_overrides_are_escaped_line_breaks_kept() {
        assert!(matches!(printable("plain node \"a\"\n\tok é ✓"), Cow::Borrowed(_)));
        let hostile = "a\x1b[2J\x1b]0;pwned\x07\0b\u{202e}cba\u{9b}";
        let p = printable(hostile);
        assert_eq!(p, "a\\u{1b}[2J\\u{1b}]0;pwned\\u{7}\\u{0}b\\u{202e}cba\\u{9b}");
        assert!(!p.chars().any(unsafe_char));
    }

    #[test]
    fn a_very_long_line_keeps_its_start_and_end() {
        let short = "error: short\nsecond line";
        assert!(matches!(clipped(short), Cow::Borrowed(_)));
        let path = format!("/a/{}/z.png", "x".repeat(1 << 20));
        let msg = format!("error: cannot read {path}: not found\nnext");
        let c = clipped(&msg);
        let first = c.lines().next().unwrap();
        assert!(first.starts_with("error: cannot read /a/xxx") && first.ends_with("xxx/z.png: not found"), "{}", &first[..80]);
        assert!(first.contains(&format!("…[{} characters left out]…", msg.lines().next().unwrap().len() - 1500 - 400)));
        assert!(first.chars().count() < MAX_MESSAGE_LINE + 50);
        assert_eq!(c.lines().nth(1), Some("next"));
    }
}
