//! [`merge`]: the tables of a grid from its finished cells.
//!
//! Writes into the grid folder `baselines.md` / `.json`, `ablation.md` / `.json` and
//! `w3_sweep.md` / `.json` with its figures `w3_sweep.svg` and `w3_sweep_psnr.svg`. A cell
//! that has not finished is a row marked failed with that reason, and is listed.

use std::path::Path;

use serde_json::json;

use super::{read_outcome, Grid};
use crate::ablate::{self, RunOutcome, ABLATION_ROWS, BASELINE_ROWS};
use gb_inpaint::InpaintError;

/// What [`merge`] found and wrote.
#[derive(Debug, Clone)]
pub struct MergeReport {
    /// The tables as markdown, one after the other.
    pub markdown: String,
    /// Indices of the cells that have not finished.
    pub missing: Vec<usize>,
    /// Run folders of the cells that failed, with their errors.
    pub failed: Vec<(String, String)>,
}

fn write_text(path: &Path, text: &str) -> Result<(), InpaintError> {
    gb_core::write_atomic(path, text.as_bytes()).map_err(|e| InpaintError::io(path, e))
}

fn write_table(
    dir: &Path,
    stem: &str,
    title: &str,
    rows: &[(String, &RunOutcome)],
) -> Result<String, InpaintError> {
    let (md, js) = ablate::table(title, rows);
    write_text(&dir.join(format!("{stem}.md")), &md)?;
    let path = dir.join(format!("{stem}.json"));
    let text = serde_json::to_string_pretty(&js)
        .map_err(|e| InpaintError::io(&path, std::io::Error::other(e)))?;
    write_text(&path, &(text + "\n"))?;
    Ok(md)
}

/// Reads every cell's outcome in `grid_dir` and writes the tables (see the module docs).
pub fn merge(grid_dir: &Path) -> Result<MergeReport, InpaintError> {
    let grid = Grid::read(grid_dir)?;
    let mut runs: Vec<RunOutcome> = Vec::new();
    let mut missing = Vec::new();
    for (i, cell) in grid.cells.iter().enumerate() {
        let (outcome, is_missing) = read_outcome(grid_dir, i, cell);
        if is_missing {
            missing.push(i);
        }
        runs.push(outcome);
    }
    let failed = runs
        .iter()
        .enumerate()
        .filter(|(i, _)| !missing.contains(i))
        .filter_map(|(_, r)| r.result.as_ref().err().map(|e| (r.dir.clone(), e.clone())))
        .collect();
    let find = |dir: &str| runs.iter().find(|r| r.dir == dir);
    let in_tables = |dir: &str| {
        BASELINE_ROWS
            .iter()
            .chain(ABLATION_ROWS)
            .any(|(_, m)| *m == dir)
    };
    // the sweep's own runs (csd-w3=X) have their table; csd itself is a baseline row
    let swept: Vec<&str> = grid.sweep.iter().map(|p| p.dir.as_str()).collect();
    let mut baseline_rows: Vec<(String, &RunOutcome)> = BASELINE_ROWS
        .iter()
        .filter_map(|(label, m)| find(m).map(|r| (label.to_string(), r)))
        .collect();
    for r in runs
        .iter()
        .filter(|r| !in_tables(&r.dir) && !swept.contains(&r.dir.as_str()))
    {
        baseline_rows.push((r.dir.clone(), r));
    }
    let ablation_rows: Vec<(String, &RunOutcome)> = ABLATION_ROWS
        .iter()
        .filter_map(|(label, m)| find(m).map(|r| (label.to_string(), r)))
        .collect();
    let scene = grid.settings.scene.display().to_string();
    let mut markdown = write_table(
        grid_dir,
        "baselines",
        &format!("Baseline comparison on {scene}"),
        &baseline_rows,
    )?;
    markdown.push_str(&write_table(
        grid_dir,
        "ablation",
        &format!("Ablation (origin / +LoRA / +BSD / +LoRA+BSD) on {scene}"),
        &ablation_rows,
    )?);
    if grid.sweep.is_empty() {
        let text =
            "## CSD w3 sweep\n\nNot run: csd is not among --methods and no --w3 was given.\n";
        write_text(&grid_dir.join("w3_sweep.md"), text)?;
        let js = json!({"title": "CSD w3 sweep", "rows": [], "note": "not run"});
        write_text(&grid_dir.join("w3_sweep.json"), &format!("{js:#}\n"))?;
        markdown.push_str(text);
    } else {
        let points: Vec<(f64, &RunOutcome)> = grid
            .sweep
            .iter()
            .filter_map(|p| find(&p.dir).map(|r| (p.w3, r)))
            .collect();
        let rows: Vec<(String, &RunOutcome)> = points
            .iter()
            .map(|(w3, r)| (format!("w3 = {w3}"), *r))
            .collect();
        let mut md = write_table(
            grid_dir,
            "w3_sweep",
            &format!("CSD w3 sweep on {scene} (w1, w2 of csd.toml; w3 = 0 is BSD)"),
            &rows,
        )?;
        for (stem, chart) in ablate::w3_charts(&points) {
            write_text(&grid_dir.join(format!("{stem}.svg")), &chart.to_svg())?;
            md.push_str(&format!("\n![{}]({stem}.svg)\n", chart.title));
        }
        write_text(&grid_dir.join("w3_sweep.md"), &md)?;
        markdown.push_str(&md);
    }
    Ok(MergeReport {
        markdown,
        missing,
        failed,
    })
}
