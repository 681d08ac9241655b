#!/usr/bin/env python3
"""Issue 49: how far the hidden rays' weight spreads in depth, row by row, beside the mask box's
ST-LPIPS, from the probe tables of tools/diag/geometry_collect.sh and dpsnr_noise.sh
(bench/results/geometry-seed*/probe-*.json, noise-*.json). `hidden_weights.spread` is the
weighted standard deviation of the hidden rays' sample depths over the true depth
(gb_inpaint::run::probe); `hidden_weights.at_surface` their weight within 5% of it.
Prints one Markdown row per table and row. Standard library only.

    tools/diag/weight_spread.py TABLE.json [TABLE.json ...] [--rows PREFIX,...]
"""
import json
import os
import sys


def cells(path, prefixes):
    """(row, spread, at surface, ST-LPIPS) of each row of one probe table."""
    with open(path) as f:
        table = json.load(f)
    if not isinstance(table, dict):
        sys.exit(f"{path}: not a probe table (an object of rows)")
    out = []
    for row, r in table.items():
        # older probes wrote the weight measures as null
        if not isinstance(r, dict) or r.get("hidden_weights.spread") is None:
            continue
        if r.get("hidden_weights.at_surface") is None:
            continue
        if prefixes and not any(row.startswith(p) for p in prefixes):
            continue
        out.append(
            (row, r["hidden_weights.spread"], r["hidden_weights.at_surface"], r.get("lpips_bbox"))
        )
    return out


def main():
    args = sys.argv[1:]
    prefixes = []
    if "--rows" in args:
        i = args.index("--rows")
        if i + 1 >= len(args):
            sys.exit("--rows needs a comma-separated list of row prefixes")
        prefixes = [p for p in args[i + 1].split(",") if p]
        del args[i : i + 2]
    if not args:
        sys.exit(__doc__)
    print("| table | row | spread | weight at the surface | ST-LPIPS |")
    print("|---|---|---:|---:|---:|")
    for path in args:
        name = os.path.relpath(path, "bench/results") if path.startswith("bench/results") else path
        for row, spread, at, lpips in cells(path, prefixes):
            lp = "" if lpips is None else f"{lpips:.3f}"
            print(f"| {name} | {row} | {spread:.3f} | {at:.3f} | {lp} |")


if __name__ == "__main__":
    main()
