//! Error messages as one line: a CLI prints every error on a single `error: ...` line.

use std::ops::Range;

/// `message` with its lines joined by single spaces (blank lines dropped, each line trimmed).
pub fn one_line(message: &str) -> String {
    message
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join(" ")
}

/// The longest source line quoted by [`at_line`], in characters.
const QUOTE_MAX: usize = 80;

/// A parser's `message` about the byte range `span` of `text`, as one line that quotes the
/// source line (so a wrongly typed value's key is named): ``line L, column C (`key = 1`):
/// message`` (1-based; just the message without a span).
pub fn at_line(text: &str, span: Option<Range<usize>>, message: &str) -> String {
    let message = one_line(message);
    let Some(span) = span else {
        return message;
    };
    let mut start = span.start.min(text.len());
    while !text.is_char_boundary(start) {
        start -= 1;
    }
    let before = &text[..start];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    let column = before[line_start..].chars().count() + 1;
    let source = text[line_start..].lines().next().unwrap_or("").trim();
    let mut quoted: String = source.chars().take(QUOTE_MAX).collect();
    if source.chars().count() > QUOTE_MAX {
        quoted.push_str("...");
    }
    if quoted.is_empty() {
        format!("line {line}, column {column}: {message}")
    } else {
        format!("line {line}, column {column} (`{quoted}`): {message}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn joins_lines_and_locates_spans() {
        assert_eq!(one_line("a\n  b  \n\n c\n"), "a b c");
        let text = "x = 1\nyy = \"q\"\n";
        assert_eq!(
            at_line(text, Some(8..10), "invalid\ntype"),
            "line 2, column 3 (`yy = \"q\"`): invalid type"
        );
        assert_eq!(at_line(text, None, "bad"), "bad");
        // a span past the end (or inside a multi-byte character) still gives a line
        assert_eq!(at_line(text, Some(99..100), "eof"), "line 3, column 1: eof");
        assert_eq!(
            at_line("é = 1", Some(1..2), "m"),
            "line 1, column 1 (`é = 1`): m"
        );
        let long = format!("k = \"{}\"", "a".repeat(200));
        assert!(at_line(&long, Some(0..1), "m").contains("...`): m"));
    }
}
