#!/usr/bin/env python3
"""Issue 49's weight of the geometry term, judged pooled: for each weight, each tuning cell's
row of bench/results/geometry-seed-SEED/probe-SCENE-weights.json (tools/diag/geometry_weights.sh)
against the same cell's `none`, then the mean and sd over the cells. The built-in weight (1) is
the row itself (`reference-oracle`) or, for a row the grid does not run (`gb-nerf-unseen`), its
variant `ROW-w1`; another weight W is its variant (`reference-oracle-wW`).

Columns, each the row minus none: mask-box SSIM (up is better), ST-LPIPS (down is better),
D-PSNR (the bar: within -0.5 dB) and the PSNR over the whole image (the term's cost outside
the hole). A cell without the row is left out of that weight's mean and named. Standard
library only.

    tools/diag/geometry_weights_pool.py [--row reference-oracle] [--weights 0.1 0.3 1]
        [--cells stairs:100 fence:100 ...]
"""
import argparse
import json
import os
import statistics

CELLS = [f"{scene}:{seed}" for seed in (100, 101) for scene in ("stairs", "fence", "alcove")]
METRICS = [("ssim_bbox", "SSIM"), ("lpips_bbox", "ST-LPIPS"), ("d_psnr_bbox", "D-PSNR"),
           ("psnr", "whole PSNR")]


def row_name(row, weight, table):
    """The probe table's row for a weight: the built-in weight 1 is the row itself when the
    grid ran it (the oracles), else its variant `ROW-w1` (gb-nerf-unseen, which the grid does
    not run)."""
    if float(weight) == 1.0 and row in table:
        return row
    return f"{row}-w{weight}"


def mean_sd(values):
    """`mean ± sd` (sd 0 for a single value), or a dash."""
    if not values:
        return "—"
    sd = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{statistics.mean(values):+.3f} ± {sd:.3f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--row", default="reference-oracle")
    ap.add_argument("--weights", nargs="+", default=["0.1", "0.3", "1"])
    ap.add_argument("--cells", nargs="+", default=CELLS, help="SCENE:SEED")
    ap.add_argument("--results", default="bench/results")
    a = ap.parse_args()
    tables = {}
    for cell in a.cells:
        scene, seed = cell.split(":")
        path = os.path.join(a.results, f"geometry-seed-{seed}", f"probe-{scene}-weights.json")
        if os.path.exists(path):
            tables[cell] = json.load(open(path))
        else:
            print(f"(no {path})")
    print(f"| weight | cell | {' | '.join(f'{label} − none' for _, label in METRICS)} |")
    print("|---|---|" + "---:|" * len(METRICS))
    # each weight once, in the order given ("1" and "1.0" are the same weight)
    weights = []
    for w in a.weights:
        if all(float(w) != float(seen) for seen in weights):
            weights.append(w)
    for weight in weights:
        pooled = {key: [] for key, _ in METRICS}
        for cell, table in tables.items():
            name = row_name(a.row, weight, table)
            if name not in table or "none" not in table:
                print(f"| {weight} | {cell} | (no `{name}`) |")
                continue
            diffs = []
            for key, _ in METRICS:
                value, base = table[name].get(key), table["none"].get(key)
                if value is None or base is None:
                    diffs.append("—")
                    continue
                pooled[key].append(value - base)
                diffs.append(f"{value - base:+.3f}")
            print(f"| {weight} | {cell} | {' | '.join(diffs)} |")
        print(f"| **{weight}** | mean ± sd ({len(pooled['ssim_bbox'])} cells) | "
              + " | ".join(mean_sd(pooled[key]) for key, _ in METRICS) + " |")


if __name__ == "__main__":
    main()
