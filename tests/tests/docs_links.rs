//! The docs stay true to the tree: every `bench/results/` and `configs/` path that `README.md`
//! and `docs/*.md` cite exists (a `*` or a `{a,b}` alternative must match at least one
//! file), and every `cargo xtask SUBCOMMAND` they show is one that the command's `--help`
//! lists (for `bench`, its own subcommands too).

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use gb_tests::{workspace_root, xtask};
use regex::Regex;

/// README.md and every docs/*.md, with their text.
fn documents() -> Vec<(PathBuf, String)> {
    let root = workspace_root();
    let mut paths = vec![root.join("README.md")];
    if let Ok(entries) = std::fs::read_dir(root.join("docs")) {
        let mut docs: Vec<PathBuf> = entries
            .flatten()
            .map(|e| e.path())
            .filter(|p| p.extension().is_some_and(|e| e == "md"))
            .collect();
        docs.sort();
        paths.extend(docs);
    }
    paths
        .into_iter()
        .map(|p| {
            let text = std::fs::read_to_string(&p)
                .unwrap_or_else(|e| panic!("cannot read {}: {e}", p.display()));
            (p, text)
        })
        .collect()
}

/// The cited `bench/results/...` and `configs/...` paths of `text`, as written.
fn cited_paths(text: &str) -> BTreeSet<String> {
    let re = Regex::new(r"(?:bench/results|configs)/(?:[A-Za-z0-9_.*+=-]|/|\{[^}\s]*\})*").unwrap();
    re.find_iter(text)
        .map(|m| m.as_str().trim_end_matches(['.', '-']).to_string())
        .collect()
}

/// `pattern` with each `{a,b,...}` expanded, left to right.
fn expand_braces(pattern: &str) -> Vec<String> {
    let Some(open) = pattern.find('{') else {
        return vec![pattern.to_string()];
    };
    let Some(len) = pattern[open..].find('}') else {
        return vec![pattern.to_string()];
    };
    let (head, inner, tail) = (
        &pattern[..open],
        &pattern[open + 1..open + len],
        &pattern[open + len + 1..],
    );
    inner
        .split(',')
        .flat_map(|alt| expand_braces(&format!("{head}{alt}{tail}")))
        .collect()
}

/// Whether `name` matches `pattern`, whose only wildcard is `*`.
fn wildcard(pattern: &str, name: &str) -> bool {
    match pattern.split_once('*') {
        None => pattern == name,
        Some((head, rest)) => {
            let Some(after) = name.strip_prefix(head) else {
                return false;
            };
            (0..=after.len()).any(|i| after.is_char_boundary(i) && wildcard(rest, &after[i..]))
        }
    }
}

/// Whether a path (segments may hold `*`) names at least one file or folder under `root`.
fn exists(root: &Path, path: &str) -> bool {
    let mut here = vec![root.to_path_buf()];
    for segment in path.split('/').filter(|s| !s.is_empty()) {
        let mut next = Vec::new();
        for dir in &here {
            if segment.contains('*') {
                let Ok(entries) = std::fs::read_dir(dir) else {
                    continue;
                };
                next.extend(entries.flatten().filter_map(|e| {
                    let name = e.file_name().to_string_lossy().into_owned();
                    wildcard(segment, &name).then(|| e.path())
                }));
            } else if dir.join(segment).exists() {
                next.push(dir.join(segment));
            }
        }
        here = next;
    }
    !here.is_empty()
}

/// The subcommands a `--help` text lists under "Commands:".
fn help_commands(args: &[&str]) -> BTreeSet<String> {
    let out = xtask(args);
    assert!(out.status.success(), "xtask {args:?} failed");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    text.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next().map(String::from))
        .collect()
}

#[test]
fn every_cited_results_and_configs_path_exists() {
    let root = workspace_root();
    let mut cited = 0;
    let mut missing = Vec::new();
    for (doc, text) in documents() {
        for path in cited_paths(&text) {
            cited += 1;
            for alt in expand_braces(&path) {
                if !exists(&root, &alt) {
                    missing.push(format!("{}: {alt}", doc.display()));
                }
            }
        }
    }
    assert!(
        cited > 10,
        "only {cited} cited paths found: is the pattern right?"
    );
    assert!(
        missing.is_empty(),
        "cited but not in the tree:\n{}",
        missing.join("\n")
    );
}

#[test]
fn every_shown_xtask_subcommand_is_one_help_lists() {
    let top = help_commands(&["--help"]);
    let bench = help_commands(&["bench", "--help"]);
    assert!(top.contains("inpaint") && top.contains("bench"), "{top:?}");
    assert!(!bench.is_empty(), "bench --help lists no subcommands");
    let re = Regex::new(r"cargo xtask ([a-z][a-z0-9-]*)(?: ([a-z][a-z0-9-]*))?").unwrap();
    let mut unknown = Vec::new();
    let mut shown = 0;
    for (doc, text) in documents() {
        for c in re.captures_iter(&text) {
            shown += 1;
            let sub = &c[1];
            if !top.contains(sub) {
                unknown.push(format!("{}: cargo xtask {sub}", doc.display()));
            } else if sub == "bench" {
                if let Some(b) = c.get(2) {
                    if !bench.contains(b.as_str()) {
                        unknown.push(format!(
                            "{}: cargo xtask bench {}",
                            doc.display(),
                            b.as_str()
                        ));
                    }
                }
            }
        }
    }
    assert!(shown > 5, "only {shown} xtask commands found");
    assert!(unknown.is_empty(), "not in --help:\n{}", unknown.join("\n"));
}

#[test]
fn the_path_helpers_expand_and_match() {
    assert_eq!(
        expand_braces("a-{100,101}{,.json}"),
        ["a-100", "a-100.json", "a-101", "a-101.json"]
    );
    assert!(wildcard(
        "quality-*-seed100.json",
        "quality-stairs-17-seed100.json"
    ));
    assert!(!wildcard("quality-*.json", "quality-stairs.txt"));
    let root = workspace_root();
    assert!(exists(&root, "configs/methods/*.toml"));
    assert!(!exists(&root, "configs/methods/no-such-*.toml"));
    let cited = cited_paths("see `bench/results/x-{1,2}.json`. And configs/presets/fast.toml.");
    assert_eq!(
        cited.into_iter().collect::<Vec<_>>(),
        ["bench/results/x-{1,2}.json", "configs/presets/fast.toml"]
    );
}
