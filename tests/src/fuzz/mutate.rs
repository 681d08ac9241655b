//! Structure-aware mutations of a valid file: truncation, byte flips, inserted or replaced
//! spans, numbers and words swapped for "interesting" tokens (huge, negative, NaN, wrong
//! types), and deep nesting. Positions are drawn as `u32` and taken modulo the length, so one
//! mutation applies to a file of any size.

use proptest::prelude::*;

/// Tokens that break numeric fields: huge, negative, zero, non-finite, out of range.
pub const NUMBERS: &[&str] = &[
    "0",
    "-1",
    "-0",
    "1",
    "2",
    "255",
    "65536",
    "4294967296",
    "9223372036854775807",
    "-9223372036854775808",
    "18446744073709551615",
    "18446744073709551616",
    "99999999999999999999999999999",
    "1e308",
    "1e309",
    "-1e309",
    "1e-400",
    "3.5",
    "-2.5e10",
    "NaN",
    "nan",
    "inf",
    "-inf",
    ".Inf",
    ".Nan",
    "0x10",
    "1_000",
];

/// Tokens of the wrong type for most fields.
pub const WRONG_TYPES: &[&str] = &[
    "\"text\"",
    "'text'",
    "true",
    "false",
    "null",
    "[]",
    "{}",
    "[1, 2]",
    "{ a: 1 }",
    "{\"a\": 1}",
    "\"\"",
    "",
    " ",
    ":",
    ",",
    "\n",
    "#",
    "\u{0}",
    "\u{feff}",
    "é",
    "-",
    "- ",
    "=",
    "[[",
    "]]",
];

/// One edit of a file.
#[derive(Debug, Clone)]
pub enum Mutation {
    /// Keep the first `per_mille / 1000` of the bytes.
    Truncate(u16),
    /// Flip one bit.
    FlipBit { at: u32, bit: u8 },
    /// Overwrite one byte.
    SetByte { at: u32, byte: u8 },
    /// Insert bytes.
    Insert { at: u32, bytes: Vec<u8> },
    /// Remove `len` bytes.
    Remove { at: u32, len: u16 },
    /// Replace the `nth` number (a run of digits, signs, dots and exponents) by `with`.
    ReplaceNumber { nth: u32, with: String },
    /// Replace the `nth` word (a run of letters, digits and `_`) by `with`.
    ReplaceWord { nth: u32, with: String },
    /// Insert `depth` copies of `open` and then of `close` (deep nesting).
    Nest {
        at: u32,
        open: String,
        close: String,
        depth: u32,
    },
    /// Repeat the `nth` line `times` times.
    RepeatLine { nth: u32, times: u16 },
    /// Indent the `nth` line by `by` more spaces.
    Indent { nth: u32, by: u16 },
}

fn pos(at: u32, len: usize) -> usize {
    at as usize % (len + 1)
}

/// Byte ranges of the maximal runs of bytes for which `inside` holds.
fn runs(bytes: &[u8], inside: impl Fn(u8) -> bool) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, &b) in bytes.iter().enumerate() {
        match (inside(b), start) {
            (true, None) => start = Some(i),
            (false, Some(s)) => {
                out.push((s, i));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((s, bytes.len()));
    }
    out
}

fn replace_run(bytes: &mut Vec<u8>, spans: &[(usize, usize)], nth: u32, with: &str) {
    if let Some(&(s, e)) = spans.get(nth as usize % spans.len().max(1)) {
        bytes.splice(s..e, with.bytes());
    }
}

/// Line ranges `[start, end)` including the line break.
fn lines(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, &b) in bytes.iter().enumerate() {
        if b == b'\n' {
            out.push((start, i + 1));
            start = i + 1;
        }
    }
    if start < bytes.len() {
        out.push((start, bytes.len()));
    }
    out
}

impl Mutation {
    /// Applies the mutation to `bytes`.
    pub fn apply(&self, bytes: &mut Vec<u8>) {
        let len = bytes.len();
        match self {
            Mutation::Truncate(per_mille) => {
                bytes.truncate(len * (*per_mille as usize).min(1000) / 1000)
            }
            Mutation::FlipBit { at, bit } => {
                if len > 0 {
                    bytes[*at as usize % len] ^= 1 << (bit % 8);
                }
            }
            Mutation::SetByte { at, byte } => {
                if len > 0 {
                    bytes[*at as usize % len] = *byte;
                }
            }
            Mutation::Insert { at, bytes: ins } => {
                let p = pos(*at, len);
                bytes.splice(p..p, ins.iter().copied());
            }
            Mutation::Remove { at, len: n } => {
                let p = pos(*at, len);
                bytes.drain(p..(p + *n as usize).min(len));
            }
            Mutation::ReplaceNumber { nth, with } => {
                let spans = runs(bytes, |b| b.is_ascii_digit() || b"+-.eE_".contains(&b));
                let spans: Vec<_> = spans
                    .into_iter()
                    .filter(|&(s, e)| bytes[s..e].iter().any(u8::is_ascii_digit))
                    .collect();
                replace_run(bytes, &spans, *nth, with);
            }
            Mutation::ReplaceWord { nth, with } => {
                let spans = runs(bytes, |b| b.is_ascii_alphanumeric() || b == b'_');
                replace_run(bytes, &spans, *nth, with);
            }
            Mutation::Nest {
                at,
                open,
                close,
                depth,
            } => {
                let p = pos(*at, len);
                let mut ins = open.repeat(*depth as usize).into_bytes();
                ins.extend(close.repeat(*depth as usize).bytes());
                bytes.splice(p..p, ins);
            }
            Mutation::RepeatLine { nth, times } => {
                let ls = lines(bytes);
                if let Some(&(s, e)) = ls.get(*nth as usize % ls.len().max(1)) {
                    let line = bytes[s..e].to_vec();
                    let rep: Vec<u8> = line.repeat(*times as usize);
                    bytes.splice(e..e, rep);
                }
            }
            Mutation::Indent { nth, by } => {
                let ls = lines(bytes);
                if let Some(&(s, _)) = ls.get(*nth as usize % ls.len().max(1)) {
                    bytes.splice(s..s, std::iter::repeat_n(b' ', *by as usize));
                }
            }
        }
    }
}

/// Applies `mutations` in order to a copy of `valid`.
pub fn mutated(valid: &[u8], mutations: &[Mutation]) -> Vec<u8> {
    let mut bytes = valid.to_vec();
    for m in mutations {
        m.apply(&mut bytes);
    }
    bytes
}

/// A short arbitrary string (any Unicode scalar values).
pub fn any_short_string() -> impl Strategy<Value = String> {
    proptest::collection::vec(any::<char>(), 0..10).prop_map(String::from_iter)
}

/// A replacement token: an interesting number, a wrong type, one of `extra`, or any string.
pub fn token(extra: &'static [&'static str]) -> impl Strategy<Value = String> {
    let pick = |list: &'static [&'static str]| {
        proptest::sample::select(if list.is_empty() { &[""][..] } else { list })
            .prop_map(str::to_string)
    };
    prop_oneof![
        4 => pick(NUMBERS),
        3 => pick(WRONG_TYPES),
        3 => pick(extra),
        1 => any_short_string(),
    ]
}

/// One mutation; `extra` adds format-specific tokens (key names, brackets, tags).
pub fn mutation(extra: &'static [&'static str]) -> impl Strategy<Value = Mutation> {
    let nest = prop_oneof![
        Just(("[", "]")),
        Just(("{", "}")),
        Just(("(", ")")),
        Just(("[", "")),
        Just(("{\"a\":", "}")),
        Just(("a = [", "]")),
        Just(("- ", "")),
        Just(("-\n", "")),
    ];
    prop_oneof![
        2 => (0u16..1000).prop_map(Mutation::Truncate),
        2 => (any::<u32>(), any::<u8>()).prop_map(|(at, bit)| Mutation::FlipBit { at, bit }),
        1 => (any::<u32>(), any::<u8>()).prop_map(|(at, byte)| Mutation::SetByte { at, byte }),
        1 => (any::<u32>(), proptest::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(at, bytes)| Mutation::Insert { at, bytes }),
        1 => (any::<u32>(), token(extra))
            .prop_map(|(at, t)| Mutation::Insert { at, bytes: t.into_bytes() }),
        1 => (any::<u32>(), 1u16..64).prop_map(|(at, len)| Mutation::Remove { at, len }),
        4 => (any::<u32>(), token(extra))
            .prop_map(|(nth, with)| Mutation::ReplaceNumber { nth, with }),
        3 => (any::<u32>(), token(extra))
            .prop_map(|(nth, with)| Mutation::ReplaceWord { nth, with }),
        1 => (any::<u32>(), nest, prop_oneof![1u32..64, 64u32..20_000])
            .prop_map(|(at, (o, c), depth)| Mutation::Nest {
                at,
                open: o.into(),
                close: c.into(),
                depth
            }),
        1 => (any::<u32>(), 1u16..200).prop_map(|(nth, times)| Mutation::RepeatLine { nth, times }),
        1 => (any::<u32>(), 1u16..40).prop_map(|(nth, by)| Mutation::Indent { nth, by }),
    ]
}

/// One to four mutations.
pub fn mutations(extra: &'static [&'static str]) -> impl Strategy<Value = Vec<Mutation>> {
    proptest::collection::vec(mutation(extra), 1..5)
}

/// Arbitrary bytes, up to `max` long.
pub fn any_bytes(max: usize) -> impl Strategy<Value = Vec<u8>> {
    proptest::collection::vec(any::<u8>(), 0..max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn number_and_word_replacement_hit_the_nth_token() {
        let mut b = b"a = 12\nb = -3.5e2\n".to_vec();
        Mutation::ReplaceNumber {
            nth: 1,
            with: "NaN".into(),
        }
        .apply(&mut b);
        assert_eq!(b, b"a = 12\nb = NaN\n");
        Mutation::ReplaceWord {
            nth: 2,
            with: "zz".into(),
        }
        .apply(&mut b);
        assert_eq!(b, b"a = 12\nzz = NaN\n");
        Mutation::Nest {
            at: 0,
            open: "[".into(),
            close: "]".into(),
            depth: 2,
        }
        .apply(&mut b);
        assert!(b.starts_with(b"[[]]a"));
        let before = b.len();
        Mutation::Truncate(500).apply(&mut b);
        assert_eq!(b.len(), before / 2);
    }
}
