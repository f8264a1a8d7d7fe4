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
}
