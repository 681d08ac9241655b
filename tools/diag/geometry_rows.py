#!/usr/bin/env python3
"""Issue 49's per-seed rows of docs/results.md ("Reporting seeds 2 to 4, with the term on by
default"): for one scene and seed, each run of the pooled probe table
bench/results/geometry-seed-SEED/probe-SCENE.json (tools/diag/geometry_collect.sh) with its
mask-box SSIM, ST-LPIPS, D-PSNR, D-PSNR on the true scale and share of hidden pixels within 5%
of the true depth, and beside each method the same seed's older run without the term (pooled
from the `bench quality` reports given with --before, as tools/diag/geometry_table.py pools
them). Standard library only.

    tools/diag/geometry_rows.py SCENE SEED --before REPORT... [--whole] [--table NAME.json]

--whole adds the PSNR over the whole image (the term's cost outside the hole) as a last column,
with the older run's beside it; --table reads another table of the seed's folder
(geometry_weights.sh writes probe-SCENE-weights.json).
"""
import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from rank_methods import pool  # noqa: E402

ORDER = ["none", "gb-nerf-unseen", "reference-oracle", "score-oracle"]


def num(v):
    """A value to two decimals, or a dash (older probe tables have no whole-image PSNR)."""
    return "—" if v is None else f"{v:.2f}"


def old_whole(old, seed):
    """` (X)`: the older run's whole-image PSNR, when the reports have it."""
    v = (old or {}).get("psnr", {}).get(seed)
    return "" if v is None else f" ({v:.2f})"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("seed", type=int)
    ap.add_argument("--before", nargs="+", required=True)
    ap.add_argument("--results", default="bench/results")
    ap.add_argument("--whole", action="store_true", help="add the whole-image PSNR")
    ap.add_argument("--table", help="the probe table's file name (default probe-SCENE.json)")
    a = ap.parse_args()
    table = a.table or f"probe-{a.scene}.json"
    path = os.path.join(a.results, f"geometry-seed-{a.seed}", table)
    probe = json.load(open(path))
    before = pool(a.before).get(a.scene, {})
    rows = [r for r in ORDER if r in probe] + sorted(r for r in probe if r not in ORDER)
    whole = " PSNR, whole image ↑ (no term) |" if a.whole else ""
    print("| seed | scene | row | SSIM ↑ | ST-LPIPS ↓ | D-PSNR ↑ | true scale ↑ | hidden within 5% "
          "| no term: SSIM / ST-LPIPS / D-PSNR |" + whole)
    print("|---|---|---|---:|---:|---:|---:|---:|---|" + ("---:|" if a.whole else ""))
    for row in rows:
        p = probe[row]
        old = before.get(row) if row != "none" else None
        was = ""
        if old and all(a.seed in old[k] for k in ("ssim_bbox", "lpips_bbox", "d_psnr_bbox")):
            was = (f"{old['ssim_bbox'][a.seed]:.3f} / {old['lpips_bbox'][a.seed]:.3f} / "
                   f"{old['d_psnr_bbox'][a.seed]:.2f}")
        print(f"| {a.seed} | `{a.scene}` | `{row}` | {p['ssim_bbox']:.3f} | {p['lpips_bbox']:.3f} | "
              f"{p['d_psnr_bbox']:.2f} | {p['disparity_scale.d_psnr_true_scale']:.2f} | "
              f"{100 * p['hidden.within_tolerance']:.0f}% | {was} |"
              + (f" {num(p.get('psnr'))}{old_whole(old, a.seed)} |" if a.whole else ""))


if __name__ == "__main__":
    main()
