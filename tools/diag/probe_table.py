#!/usr/bin/env python3
"""Pools the `probe/probe.json` of runs made with `--probe` (gb_inpaint::run::probe) into one
table: per run, the hidden region's depth error and where its rays' weight lies, averaged over
the test views, and the error of the observed surroundings.

Usage: tools/diag/probe_table.py [--keep] OUT.json LABEL=RUN_DIR [LABEL=RUN_DIR ...]

Each RUN_DIR is a run folder (with probe/probe.json and metrics.json). Writes OUT.json and
prints a Markdown table. With --keep, the rows of an existing OUT.json whose label is not given
stay (runs in out/ do not outlive a machine; the committed table does). Standard library only.
"""
import json
import sys
from pathlib import Path

FIELDS = [
    ("hidden", "mean_signed"),
    ("hidden", "mean_abs"),
    ("hidden", "within_tolerance"),
    ("hidden_weights", "in_front"),
    ("hidden_weights", "at_surface"),
    ("hidden_weights", "behind"),
    ("hidden_weights", "background"),
    ("hidden_weights", "spread"),
    ("hidden_weights", "two_surfaces"),
    ("surroundings", "mean_signed"),
    ("surroundings", "mean_abs"),
    ("surroundings", "within_tolerance"),
    # newer probes only (left empty for older ones)
    ("hidden", "rms"),
    ("surroundings", "rms"),
    ("disparity_scale", "rendered_max"),
    ("disparity_scale", "rendered_max_in_box"),
    ("disparity_scale", "true_max"),
    ("disparity_scale", "d_psnr_own_scale"),
    ("disparity_scale", "d_psnr_true_scale"),
]


def mean(xs):
    return sum(xs) / len(xs) if xs else float("nan")


def pool(run: Path) -> dict:
    probe = json.loads((run / "probe" / "probe.json").read_text())
    views = probe["views"]
    row = {"run": str(run), "views": len(views), "tolerance": probe["tolerance"]}
    for group, key in FIELDS:
        vals = [v[group][key] for v in views if key in v.get(group, {})]
        row[f"{group}.{key}"] = mean(vals) if vals else None
    metrics = run / "metrics.json"
    if metrics.is_file():
        m = json.loads(metrics.read_text())
        e = m.get("eval", {})
        row["d_psnr_bbox"] = e.get("d_psnr_bbox")
        row["lpips_bbox"] = e.get("lpips_bbox")
        row["ssim_bbox"] = m.get("mean", {}).get("ssim_bbox")
        row["psnr"] = e.get("psnr")
        row["lpips"] = e.get("lpips")
        row["train_seconds"] = m.get("train_seconds_this_run")
    return row


def main() -> int:
    args = sys.argv[1:]
    keep = bool(args) and args[0] == "--keep"
    if keep:
        args = args[1:]
    if len(args) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    out = Path(args[0])
    rows = json.loads(out.read_text()) if keep and out.is_file() else {}
    for arg in args[1:]:
        label, _, run = arg.partition("=")
        if not run:
            print(f"probe_table.py: {arg}: expected LABEL=RUN_DIR", file=sys.stderr)
            return 2
        try:
            rows[label] = pool(Path(run))
        except (OSError, KeyError, json.JSONDecodeError) as e:
            print(f"probe_table.py: {run}: {e}", file=sys.stderr)
            return 1
    out.write_text(json.dumps(rows, indent=2) + "\n")
    cols = [f"{g}.{k}" for g, k in FIELDS] + ["ssim_bbox", "lpips_bbox", "d_psnr_bbox"]
    print("| run | " + " | ".join(cols) + " |")
    print("|---|" + "---:|" * len(cols))
    for label, r in rows.items():
        cells = [f"{r[c]:.3f}" if isinstance(r.get(c), (int, float)) else "" for c in cols]
        print(f"| {label} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
