//! The method grid's Slurm array job under a real Slurm: a 2-cell grid is emitted, submitted
//! with `sbatch --wait`, each array task runs its cell by `$SLURM_ARRAY_TASK_ID`, and the
//! merge finds both cells finished.
//!
//! It needs a running Slurm (`tools/slurm/single_node.sh start DIR`, then
//! `SLURM_CONF=DIR/slurm.conf`); `.ci/run` starts one and sets `GB_TEST_SLURM=1`. Built with
//! neither variable set, the test is ignored with that reason (`tests/build.rs`); built with
//! either, a Slurm that does not answer is a failure.
//! With `GB_SLURM_RECORD=FILE` it writes what ran (jobs, states, times, the tables) to FILE.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use gb_tests::{
    assert_success, path_str as s, slurm_available, small_grid_flags, small_preset, small_stairs,
    xtask,
};

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
#[cfg_attr(
    gb_no_slurm,
    ignore = "needs a running Slurm: start one with tools/slurm/single_node.sh and set SLURM_CONF (or GB_TEST_SLURM=1)"
)]
fn the_slurm_array_job_runs_every_cell() {
    assert!(
        slurm_available(),
        "no Slurm answers (SLURM_CONF, sinfo): start one with tools/slurm/single_node.sh"
    );
    let dir = tempfile::tempdir().unwrap();
    let scene = small_stairs(dir.path(), 128, 96, 0);
    let preset = small_preset(dir.path(), None);
    let grid = dir.path().join("grid");
    let mut args = vec!["ablate"];
    args.extend(small_grid_flags(s(&scene), s(&preset)));
    args.extend(["--cpus", "1", "--emit", "slurm", "--out", s(&grid)]);
    let emitted = xtask(&args);
    assert_success(&emitted, "ablate --emit slurm");
    let start = Instant::now();
    let submitted = Command::new("sbatch")
        .args(["--wait", "--parsable"])
        .arg(grid.join("slurm.sh"))
        .current_dir(dir.path())
        .output()
        .unwrap();
    let seconds = start.elapsed().as_secs_f64();
    let logs: Vec<String> = (0..2)
        .map(|i| {
            std::fs::read_to_string(grid.join(format!("logs/cell-{i}.out"))).unwrap_or_default()
        })
        .collect();
    assert!(
        submitted.status.success(),
        "sbatch: {}\n{}\ncell logs:\n{}",
        String::from_utf8_lossy(&submitted.stdout),
        String::from_utf8_lossy(&submitted.stderr),
        logs.join("\n---\n")
    );
    let job = String::from_utf8_lossy(&submitted.stdout)
        .trim()
        .to_string();
    for (i, log) in logs.iter().enumerate() {
        assert!(log.contains(&format!("cell {i} (")), "cell {i} log: {log}");
    }
    assert_success(
        &xtask(&["ablate", "--grid", s(&grid), "--merge"]),
        "ablate --merge",
    );
    let baselines = json(&grid.join("baselines.json"));
    let rows = baselines["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{baselines:#}");
    assert!(
        rows.iter()
            .all(|r| r["error"].is_null() && r["steps"] == 2.0),
        "{baselines:#}"
    );

    if let Some(record) = std::env::var_os("GB_SLURM_RECORD") {
        let sinfo = Command::new("sinfo")
            .args(["-h", "-o", "%N %c %m %T"])
            .output()
            .unwrap();
        let version = Command::new("sbatch").arg("--version").output().unwrap();
        let report = serde_json::json!({
            "benchmark": "grid on Slurm (2-cell array job, tests/tests/grid_slurm.rs)",
            "slurm": String::from_utf8_lossy(&version.stdout).trim(),
            "node": String::from_utf8_lossy(&sinfo.stdout).trim(),
            "job": job,
            "sbatch_wait_seconds": seconds,
            "cells": planned_cells(&grid),
            "cell_logs": logs,
            "baselines": baselines,
        });
        std::fs::write(record, serde_json::to_vec_pretty(&report).unwrap()).unwrap();
    }
}

fn planned_cells(grid: &Path) -> serde_json::Value {
    let g = gb_grid::Grid::read(grid).unwrap();
    serde_json::to_value(&g.cells).unwrap()
}
