//! Text from outside (LLM replies, server bodies, programs an LLM wrote) made safe to print: a
//! terminal obeys control characters, so an ANSI sequence in a reply could clear the screen,
//! recolour or retitle it, or overwrite earlier lines with a carriage return.

use std::borrow::Cow;

/// `text` with every control character except newline and tab written as a Rust escape
/// (`\u{1b}`, `\r`, `\u{9b}`), and the bidirectional overrides that reorder what a terminal shows
/// (U+202A–U+202E, U+2066–U+2069) likewise; borrowed when there is nothing to escape.
pub fn escape_controls(text: &str) -> Cow<'_, str> {
    if !text.chars().any(needs_escape) {
        return Cow::Borrowed(text);
    }
    let mut escaped = String::with_capacity(text.len() + 16);
    for c in text.chars() {
        if needs_escape(c) {
            escaped.extend(c.escape_default());
        } else {
            escaped.push(c);
        }
    }
    Cow::Owned(escaped)
}

fn needs_escape(c: char) -> bool {
    (c.is_control() && c != '\n' && c != '\t') || matches!(c, '\u{202a}'..='\u{202e}' | '\u{2066}'..='\u{2069}')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn controls_are_escaped_and_lines_stay_readable() {
        assert!(matches!(escape_controls("plain\ttext\nsó"), Cow::Borrowed("plain\ttext\nsó")));
        assert_eq!(escape_controls("\u{1b}[31mred\u{1b}[0m\r\u{7}"), r"\u{1b}[31mred\u{1b}[0m\r\u{7}");
        assert_eq!(escape_controls("c1 \u{9b}2J \u{7f}"), r"c1 \u{9b}2J \u{7f}");
        assert_eq!(escape_controls("abc\u{202e}fed"), r"abc\u{202e}fed");
    }
}
