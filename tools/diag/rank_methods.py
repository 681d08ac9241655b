#!/usr/bin/env python3
"""Rank method variants by the quality bar's metrics over several `bench quality` reports.

Each input is a `quality-<scene>-<time>.json` written by `cargo xtask bench quality`, for one
or more scene seeds. The reports are pooled by scene and method (a seed seen twice is an
error), and the variants other than `none` are ranked, per scene and per metric of the quality
bar (mask-box SSIM, ST-LPIPS, D-PSNR), by their mean over seeds. The variant with the lowest
rank sum wins; a tie keeps the incumbent (`--incumbent`), so a default moves only on evidence.
Every variant is also compared with `none`: for each scene and metric, whether its mean beats
`none`'s.

The rule is fixed before the runs are read; use it on tuning seeds only, and report the winner
on seeds no choice was made on.

    python3 tools/diag/rank_methods.py --incumbent gb-nerf-unseen [--methods A,B] --out F.json REPORT.json...

Standard library only.
"""

import argparse
import json
import statistics
import sys
from collections import defaultdict

BAR = [("ssim_bbox", True), ("lpips_bbox", False), ("d_psnr_bbox", True)]
# Shown beside the bar, not ranked. Training time is left out: a report scored by resuming
# finished checkpoints reads 0 s there.
SHOWN = BAR + [("psnr_bbox", True), ("psnr", True)]


def pool(paths, only=None):
    """{scene: {method: {metric: {seed: value}}}} from the reports' per-method value lists;
    with `only`, the methods in it and `none`. A seed seen twice is an error unless both
    reports hold the same value within a relative 1e-6 (the same run reproduced, as `none` is
    across sessions, up to the order of the metric network's float sums)."""
    pooled = defaultdict(lambda: defaultdict(lambda: defaultdict(dict)))
    for path in paths:
        with open(path) as f:
            report = json.load(f)
        scene = report["scene"].split()[0]
        seeds = report["scene_seeds"]
        for row in report["baselines"]["rows"]:
            method = row["method"]
            if only is not None and method != "none" and method not in only:
                continue
            for key, _ in SHOWN:
                values = row.get(f"{key}_values")
                if values is None:
                    sys.exit(f"{path}: row {method} has no {key}_values")
                if len(values) != len(seeds):
                    sys.exit(f"{path}: row {method}: {key}_values and scene_seeds differ in length")
                for seed, value in zip(seeds, values):
                    seen = pooled[scene][method][key].get(seed, value)
                    if abs(seen - value) > 1e-6 * max(abs(seen), abs(value)):
                        sys.exit(f"{path}: {scene} seed {seed} of {method} is in two reports with different values")
                    pooled[scene][method][key].setdefault(seed, value)
    return pooled


def summary(values):
    """Mean and sample sd (0 for one value) of a list."""
    mean = statistics.fmean(values)
    sd = statistics.stdev(values) if len(values) > 1 else 0.0
    return mean, sd


def rank(pooled, incumbent):
    """Rank sums of the variants over scenes and bar metrics, and their wins against none."""
    table = {}
    rank_sum = defaultdict(int)
    beats_none = defaultdict(dict)
    for scene, methods in sorted(pooled.items()):
        table[scene] = {}
        for method, metrics in methods.items():
            table[scene][method] = {}
            for key, _ in SHOWN:
                seeds = sorted(metrics[key])
                mean, sd = summary([metrics[key][s] for s in seeds])
                table[scene][method][key] = {"mean": mean, "sd": sd, "seeds": seeds}
        variants = [m for m in methods if m != "none"]
        for key, higher in BAR:
            ordered = sorted(
                variants,
                key=lambda m: -table[scene][m][key]["mean"] if higher else table[scene][m][key]["mean"],
            )
            for place, method in enumerate(ordered, start=1):
                rank_sum[method] += place
            if "none" in methods:
                base = table[scene]["none"][key]["mean"]
                for method in variants:
                    mine = table[scene][method][key]["mean"]
                    beats_none[method][f"{scene}/{key}"] = mine > base if higher else mine < base
    if not rank_sum:
        sys.exit("no method other than none in the reports: nothing to rank")
    best = min(rank_sum.values())
    leaders = [m for m, s in rank_sum.items() if s == best]
    winner = incumbent if incumbent in leaders else sorted(leaders)[0]
    return table, dict(rank_sum), dict(beats_none), winner


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("reports", nargs="+", help="bench quality JSON reports")
    parser.add_argument("--incumbent", required=True, help="the current default, kept on a tie")
    parser.add_argument("--out", help="write the ranking here as JSON")
    parser.add_argument(
        "--methods", help="comma-separated variants to rank (default: every one in the reports)"
    )
    args = parser.parse_args()
    pooled = pool(args.reports, args.methods.split(",") if args.methods else None)
    table, rank_sum, beats_none, winner = rank(pooled, args.incumbent)
    for scene, methods in table.items():
        print(f"\n{scene}")
        print("| method | " + " | ".join(k for k, _ in SHOWN) + " |")
        print("|---" * (len(SHOWN) + 1) + "|")
        for method, metrics in methods.items():
            cells = [f"{metrics[k]['mean']:.3f} ± {metrics[k]['sd']:.3f}" for k, _ in SHOWN]
            print(f"| {method} | " + " | ".join(cells) + " |")
    print("\nrank sums (lower is better):", json.dumps(rank_sum))
    for method, wins in beats_none.items():
        print(f"{method} beats none on {sum(wins.values())} of {len(wins)}")
    print("winner:", winner)
    if args.out:
        with open(args.out, "w") as f:
            json.dump(
                {
                    "rule": "rank the variants other than none per scene and per bar metric "
                    "(mask-box SSIM, ST-LPIPS, D-PSNR) by their mean over seeds; lowest rank sum "
                    "wins; a tie keeps the incumbent",
                    "incumbent": args.incumbent,
                    "reports": args.reports,
                    "table": table,
                    "rank_sum": rank_sum,
                    "beats_none": beats_none,
                    "winner": winner,
                },
                f,
                indent=1,
            )
        print("wrote", args.out)


if __name__ == "__main__":
    main()
