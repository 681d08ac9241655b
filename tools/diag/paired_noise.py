#!/usr/bin/env python3
"""Issue 49's paired test over training seeds: from a table of tools/diag/dpsnr_noise.sh
(bench/results/geometry-seed-SEED/noise-SCENE.json, rows `ROW-seed-N`), each ROW against
`none` of the same training seed, per seed and as mean ± sd over the seeds both have. Without
ROW arguments, `none` alone: each metric per seed with its mean ± sd and range. Prints
Markdown (the tables of docs/results.md "How far `none` moves with the training seed alone").
Standard library only.

    tools/diag/paired_noise.py TABLE.json [ROW ...]
"""
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from rank_methods import summary  # noqa: E402

METRICS = [
    ("d_psnr_bbox", "D-PSNR", 2, 1),
    ("disparity_scale.d_psnr_true_scale", "true scale", 2, 1),
    ("hidden.within_tolerance", "hidden within 5%, points", 1, 100),
    ("ssim_bbox", "SSIM", 3, 1),
    ("lpips_bbox", "ST-LPIPS", 3, 1),
]


def rows_of(table, row):
    """{training seed: row} of `row` in `table`."""
    prefix = f"{row}-seed-"
    return {int(k[len(prefix):]): v for k, v in table.items() if k.startswith(prefix)}


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    with open(sys.argv[1]) as f:
        table = json.load(f)
    none = rows_of(table, "none")
    if not none:
        sys.exit(f"{sys.argv[1]}: no none-seed-N rows")
    rows = sys.argv[2:]
    if not rows:
        seeds = sorted(none)
        print("| metric | " + " | ".join(map(str, seeds)) + " | mean ± sd | range |")
        print("|---|" + "---:|" * (len(seeds) + 2))
        for key, title, digits, scale in METRICS:
            v = [scale * none[s][key] for s in seeds]
            m, sd = summary(v)
            cells = " | ".join(f"{x:.{digits}f}" for x in v)
            print(f"| {title} | {cells} | {m:.{digits}f} ± {sd:.{digits}f} | "
                  f"{max(v) - min(v):.{digits}f} |")
        return
    for row in rows:
        held = rows_of(table, row)
        seeds = sorted(set(held) & set(none))
        if not seeds:
            sys.exit(f"{sys.argv[1]}: no seed has both {row} and none")
        print(f"\n{row} − none, training seeds {', '.join(map(str, seeds))}\n")
        print("| metric | " + " | ".join(map(str, seeds)) + " | mean ± sd |")
        print("|---|" + "---:|" * (len(seeds) + 1))
        for key, title, digits, scale in METRICS:
            d = [scale * (held[s][key] - none[s][key]) for s in seeds]
            m, sd = summary(d)
            cells = " | ".join(f"{x:+.{digits}f}" for x in d)
            print(f"| {title} | {cells} | {m:+.{digits}f} ± {sd:.{digits}f} |")


if __name__ == "__main__":
    main()
