//! A reader for the subset of YAML that OpenCV's `cv::FileStorage` writes: the `%YAML:1.0`
//! directive (which YAML 1.2 parsers reject), block maps and sequences, flow sequences and
//! maps that span lines, and tags such as `!!opencv-matrix` (kept out of the value; a tagged
//! `opencv-matrix` is read with [`YamlValue::opencv_matrix`]).

use std::path::Path;

use super::error::BrisqueError;

/// A parsed YAML node.
#[derive(Debug, Clone, PartialEq)]
pub enum YamlValue {
    /// A scalar, unquoted.
    Scalar(String),
    /// A sequence.
    Seq(Vec<YamlValue>),
    /// A map, in file order.
    Map(Vec<(String, YamlValue)>),
}

/// The deepest nesting of blocks or flow collections accepted (OpenCV's BRISQUE files nest
/// 4 levels); deeper documents are an error instead of a stack overflow.
pub const MAX_DEPTH: usize = 64;

/// One logical line: flow collections that span lines are joined into one.
struct Line {
    number: usize,
    indent: usize,
    text: String,
}

/// Parses an OpenCV FileStorage YAML document; `path` only names the file in errors.
pub fn parse_opencv_yaml(text: &str, path: &Path) -> Result<YamlValue, BrisqueError> {
    let lines = logical_lines(text, path)?;
    if lines.is_empty() {
        return Ok(YamlValue::Map(Vec::new()));
    }
    let mut parser = BlockParser {
        lines,
        pos: 0,
        depth: 0,
        path,
    };
    let indent = parser.lines[0].indent;
    let value = parser.block(indent)?;
    if let Some(line) = parser.lines.get(parser.pos) {
        return Err(parse_err(path, line.number, "unexpected indentation"));
    }
    Ok(value)
}

fn parse_err(path: &Path, line: usize, message: impl Into<String>) -> BrisqueError {
    BrisqueError::Parse {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// Splits the text into logical lines, dropping directives, document markers, blank lines
/// and comments, and joining lines while a flow collection is open.
fn logical_lines(text: &str, path: &Path) -> Result<Vec<Line>, BrisqueError> {
    let mut out: Vec<Line> = Vec::new();
    let mut depth: i64 = 0;
    for (idx, raw) in text.lines().enumerate() {
        let number = idx + 1;
        let trimmed = raw.trim_end();
        let content = trimmed.trim_start();
        if depth == 0 {
            if content.is_empty()
                || content.starts_with('#')
                || content.starts_with('%')
                || content == "---"
                || content == "..."
            {
                continue;
            }
            out.push(Line {
                number,
                indent: trimmed.len() - content.len(),
                text: content.to_string(),
            });
        } else if let Some(last) = out.last_mut() {
            last.text.push(' ');
            last.text.push_str(content);
        }
        let mut quote: Option<char> = None;
        for c in content.chars() {
            match (quote, c) {
                (Some(q), c) if c == q => quote = None,
                (Some(_), _) => {}
                (None, '"') | (None, '\'') => quote = Some(c),
                (None, '[') | (None, '{') => depth += 1,
                (None, ']') | (None, '}') => depth -= 1,
                _ => {}
            }
        }
        if depth < 0 {
            return Err(parse_err(path, number, "unbalanced ']' or '}'"));
        }
    }
    if depth != 0 {
        let line = out.last().map(|l| l.number).unwrap_or(0);
        return Err(parse_err(path, line, "unclosed '[' or '{'"));
    }
    Ok(out)
}

struct BlockParser<'a> {
    lines: Vec<Line>,
    pos: usize,
    /// Blocks open around the current line.
    depth: usize,
    path: &'a Path,
}

impl BlockParser<'_> {
    fn block(&mut self, indent: usize) -> Result<YamlValue, BrisqueError> {
        let first = &self.lines[self.pos];
        if first.text == "-" || first.text.starts_with("- ") {
            self.sequence(indent)
        } else {
            self.map(indent)
        }
    }

    /// Runs `f` one nesting level deeper, or fails past [`MAX_DEPTH`].
    fn nested(
        &mut self,
        f: impl FnOnce(&mut Self) -> Result<YamlValue, BrisqueError>,
    ) -> Result<YamlValue, BrisqueError> {
        if self.depth >= MAX_DEPTH {
            let line = self.lines.get(self.pos).map_or(0, |l| l.number);
            return Err(too_deep(self.path, line));
        }
        self.depth += 1;
        let value = f(self);
        self.depth -= 1;
        value
    }

    fn sequence(&mut self, indent: usize) -> Result<YamlValue, BrisqueError> {
        self.nested(|p| p.sequence_items(indent))
    }

    fn sequence_items(&mut self, indent: usize) -> Result<YamlValue, BrisqueError> {
        let mut items = Vec::new();
        while let Some(line) = self.lines.get(self.pos) {
            if line.indent != indent || !(line.text == "-" || line.text.starts_with("- ")) {
                break;
            }
            let rest = line.text[1..].trim_start().to_string();
            let number = line.number;
            if rest.is_empty() {
                self.pos += 1;
                items.push(self.child(indent)?);
            } else if is_map_entry(&rest) {
                // `- key: value`: the map starts on this line, at the column of its key.
                let col = line.indent + line.text.len() - rest.len();
                self.lines[self.pos] = Line {
                    number,
                    indent: col,
                    text: rest,
                };
                items.push(self.map(col)?);
            } else {
                self.pos += 1;
                items.push(parse_flow(&rest, self.path, number, self.depth)?);
            }
        }
        Ok(YamlValue::Seq(items))
    }

    fn map(&mut self, indent: usize) -> Result<YamlValue, BrisqueError> {
        self.nested(|p| p.map_entries(indent))
    }

    fn map_entries(&mut self, indent: usize) -> Result<YamlValue, BrisqueError> {
        let mut entries = Vec::new();
        while let Some(line) = self.lines.get(self.pos) {
            if line.indent != indent {
                if line.indent > indent {
                    return Err(parse_err(self.path, line.number, "unexpected indentation"));
                }
                break;
            }
            let number = line.number;
            let (key, value) = split_entry(&line.text).ok_or_else(|| {
                parse_err(
                    self.path,
                    number,
                    format!("expected 'key: value', found '{}'", line.text),
                )
            })?;
            let value = strip_tag(value);
            self.pos += 1;
            let parsed = if value.is_empty() {
                self.child(indent)?
            } else {
                parse_flow(value, self.path, number, self.depth)?
            };
            entries.push((key, parsed));
        }
        Ok(YamlValue::Map(entries))
    }

    /// The block that belongs to a key or dash on the previous line: deeper lines, or a
    /// sequence at the same indentation (YAML allows `key:` followed by `- item`).
    fn child(&mut self, parent_indent: usize) -> Result<YamlValue, BrisqueError> {
        match self.lines.get(self.pos) {
            Some(next) if next.indent > parent_indent => {
                let indent = next.indent;
                self.block(indent)
            }
            Some(next)
                if next.indent == parent_indent
                    && (next.text == "-" || next.text.starts_with("- ")) =>
            {
                self.sequence(parent_indent)
            }
            _ => Ok(YamlValue::Scalar(String::new())),
        }
    }
}

fn too_deep(path: &Path, line: usize) -> BrisqueError {
    parse_err(
        path,
        line,
        format!("nested more than {MAX_DEPTH} levels deep"),
    )
}

/// Drops a leading tag such as `!!opencv-matrix` or `!<tag:...>`.
fn strip_tag(value: &str) -> &str {
    let value = value.trim();
    if value.starts_with('!') {
        match value.find(char::is_whitespace) {
            Some(end) => value[end..].trim_start(),
            None => "",
        }
    } else {
        value
    }
}

fn is_map_entry(text: &str) -> bool {
    !text.starts_with('[') && !text.starts_with('{') && split_entry(text).is_some()
}

/// Splits `key: value` (or `key:` alone); keys may be quoted.
fn split_entry(text: &str) -> Option<(String, &str)> {
    if let Some(q) = text.chars().next().filter(|c| *c == '"' || *c == '\'') {
        let end = text[1..].find(q)? + 1;
        let key = text[1..end].to_string();
        let rest = text[end + 1..].trim_start();
        let rest = rest.strip_prefix(':')?;
        return Some((key, rest.trim()));
    }
    let bytes = text.as_bytes();
    for (i, b) in bytes.iter().enumerate() {
        if *b == b':' && (i + 1 == bytes.len() || bytes[i + 1] == b' ') {
            return Some((text[..i].trim().to_string(), text[i + 1..].trim()));
        }
    }
    None
}

/// Parses a flow value: `[a, b]`, `{ k: v }` (OpenCV also writes `{ k:v }`), or a scalar;
/// `depth` is the nesting of the blocks around it.
fn parse_flow(
    text: &str,
    path: &Path,
    line: usize,
    depth: usize,
) -> Result<YamlValue, BrisqueError> {
    let chars: Vec<char> = text.chars().collect();
    let mut pos = 0;
    let value = flow_value(&chars, &mut pos, path, line, depth)?;
    skip_ws(&chars, &mut pos);
    if pos != chars.len() {
        return Err(parse_err(
            path,
            line,
            format!("unexpected text after value: '{}'", text),
        ));
    }
    Ok(value)
}

fn skip_ws(chars: &[char], pos: &mut usize) {
    while *pos < chars.len() && chars[*pos].is_whitespace() {
        *pos += 1;
    }
}

fn flow_value(
    chars: &[char],
    pos: &mut usize,
    path: &Path,
    line: usize,
    depth: usize,
) -> Result<YamlValue, BrisqueError> {
    skip_ws(chars, pos);
    // Tags (`!!opencv-matrix`, `!<...>`) are dropped.
    while chars.get(*pos) == Some(&'!') {
        while *pos < chars.len() && !chars[*pos].is_whitespace() {
            *pos += 1;
        }
        skip_ws(chars, pos);
    }
    if depth >= MAX_DEPTH && matches!(chars.get(*pos), Some('[' | '{')) {
        return Err(too_deep(path, line));
    }
    match chars.get(*pos) {
        Some('[') => {
            *pos += 1;
            let mut items = Vec::new();
            loop {
                skip_ws(chars, pos);
                match chars.get(*pos) {
                    Some(']') => {
                        *pos += 1;
                        return Ok(YamlValue::Seq(items));
                    }
                    Some(',') => *pos += 1,
                    // A stray '}' is no value: without this the loop would never advance.
                    Some('}') => {
                        return Err(parse_err(path, line, "unexpected '}' in a '[' sequence"))
                    }
                    Some(_) => items.push(flow_value(chars, pos, path, line, depth + 1)?),
                    None => return Err(parse_err(path, line, "unclosed '['")),
                }
            }
        }
        Some('{') => {
            *pos += 1;
            let mut entries = Vec::new();
            loop {
                skip_ws(chars, pos);
                match chars.get(*pos) {
                    Some('}') => {
                        *pos += 1;
                        return Ok(YamlValue::Map(entries));
                    }
                    Some(',') => *pos += 1,
                    Some(_) => {
                        let key = scalar_token(chars, pos, &[':', ',', '}']);
                        if chars.get(*pos) != Some(&':') {
                            return Err(parse_err(
                                path,
                                line,
                                format!("expected ':' after key '{key}'"),
                            ));
                        }
                        *pos += 1;
                        let value = flow_value(chars, pos, path, line, depth + 1)?;
                        entries.push((key, value));
                    }
                    None => return Err(parse_err(path, line, "unclosed '{'")),
                }
            }
        }
        Some(_) => Ok(YamlValue::Scalar(scalar_token(
            chars,
            pos,
            &[',', ']', '}'],
        ))),
        None => Ok(YamlValue::Scalar(String::new())),
    }
}

fn scalar_token(chars: &[char], pos: &mut usize, stops: &[char]) -> String {
    skip_ws(chars, pos);
    if let Some(&q) = chars.get(*pos).filter(|c| **c == '"' || **c == '\'') {
        let start = *pos + 1;
        let mut end = start;
        while end < chars.len() && chars[end] != q {
            end += 1;
        }
        *pos = (end + 1).min(chars.len());
        return chars[start..end.min(chars.len())].iter().collect();
    }
    let start = *pos;
    while *pos < chars.len() && !stops.contains(&chars[*pos]) {
        *pos += 1;
    }
    chars[start..*pos]
        .iter()
        .collect::<String>()
        .trim()
        .to_string()
}

impl YamlValue {
    /// The value of `key` in a map.
    pub fn get(&self, key: &str) -> Option<&YamlValue> {
        match self {
            YamlValue::Map(entries) => entries.iter().find(|(k, _)| k == key).map(|(_, v)| v),
            _ => None,
        }
    }

    /// A scalar as text.
    pub fn as_str(&self) -> Option<&str> {
        match self {
            YamlValue::Scalar(s) => Some(s),
            _ => None,
        }
    }

    /// A scalar as a number (`.Inf`, `-.Inf` and `.Nan` as OpenCV writes them).
    pub fn as_f64(&self) -> Option<f64> {
        let s = self.as_str()?.trim();
        match s {
            ".Inf" | ".inf" | "+.Inf" => Some(f64::INFINITY),
            "-.Inf" | "-.inf" => Some(f64::NEG_INFINITY),
            ".Nan" | ".nan" | ".NaN" => Some(f64::NAN),
            _ => s.parse().ok(),
        }
    }

    /// A sequence of scalars as numbers (nested sequences are flattened).
    pub fn as_f64_vec(&self) -> Option<Vec<f64>> {
        match self {
            YamlValue::Seq(items) => {
                let mut out = Vec::with_capacity(items.len());
                for item in items {
                    match item {
                        YamlValue::Seq(_) => out.extend(item.as_f64_vec()?),
                        _ => out.push(item.as_f64()?),
                    }
                }
                Some(out)
            }
            _ => None,
        }
    }

    /// An `!!opencv-matrix` node (`rows`, `cols`, `dt`, `data`) as (rows, cols, row-major data).
    pub fn opencv_matrix(&self) -> Option<(usize, usize, Vec<f64>)> {
        let rows = self.get("rows")?.as_f64()? as usize;
        let cols = self.get("cols")?.as_f64()? as usize;
        let data = self.get("data")?.as_f64_vec()?;
        if Some(data.len()) != rows.checked_mul(cols) {
            return None;
        }
        Some((rows, cols, data))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_opencv_directive_tags_and_multiline_flow() {
        let text = "%YAML:1.0\n---\nroot:\n   kernel:\n      type: RBF\n      gamma: 5.0e-02\n   term: { epsilon:1.0e-03 }\n   m: !!opencv-matrix\n      rows: 2\n      cols: 2\n      dt: f\n      data: [ 1., 2.,\n          3., -4.5e+00 ]\n   list:\n      - [ 1, 2 ]\n      -\n         a: 7\n      - b: 8\n        c: \"x y\"\n";
        let v = parse_opencv_yaml(text, Path::new("t.yml")).unwrap();
        let root = v.get("root").unwrap();
        assert_eq!(
            root.get("kernel").unwrap().get("type").unwrap().as_str(),
            Some("RBF")
        );
        assert_eq!(
            root.get("kernel").unwrap().get("gamma").unwrap().as_f64(),
            Some(0.05)
        );
        assert_eq!(
            root.get("term").unwrap().get("epsilon").unwrap().as_f64(),
            Some(1e-3)
        );
        assert_eq!(
            root.get("m").unwrap().opencv_matrix(),
            Some((2, 2, vec![1.0, 2.0, 3.0, -4.5]))
        );
        let YamlValue::Seq(items) = root.get("list").unwrap() else {
            panic!("list is not a sequence")
        };
        assert_eq!(items.len(), 3);
        assert_eq!(items[0].as_f64_vec(), Some(vec![1.0, 2.0]));
        assert_eq!(items[1].get("a").unwrap().as_f64(), Some(7.0));
        assert_eq!(items[2].get("c").unwrap().as_str(), Some("x y"));
    }

    #[test]
    fn unclosed_flow_is_an_error_with_the_line() {
        let err = parse_opencv_yaml("a: [1, 2\nb: 3\n", Path::new("bad.yml")).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("bad.yml") && msg.contains("unclosed"), "{msg}");
    }

    /// Found by `cargo xtask-fuzz`: a stray '}' in a flow sequence used to be read as an
    /// empty item again and again, without end, until memory ran out.
    #[test]
    fn a_stray_brace_in_a_sequence_is_an_error() {
        let err = parse_opencv_yaml("a: [ 1, } ]\n", Path::new("bad.yml")).unwrap_err();
        let text = err.to_string();
        assert!(text.contains("bad.yml") && text.contains("'}'"), "{text}");
        assert!(parse_opencv_yaml("a: [1, {b: 2}]\n", Path::new("ok.yml")).is_ok());
    }
}
