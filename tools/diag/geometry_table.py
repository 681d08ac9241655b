#!/usr/bin/env python3
"""Issue 49's before/after table: the rows held by the geometry term against the same rows
without it, on the same scene seeds (standard library only).

    tools/diag/geometry_table.py --after REPORT... --before REPORT... [--out F.json] [--pairs]

Both lists are `bench quality` reports (`quality-<scene>-<time>.json`), pooled by scene, method
and seed as `rank_methods.py` pools them (a seed seen twice must agree). `--after`: the runs
with the term (tools/diag/geometry_seeds.sh, bench/results/geometry-seeds-2-4/); `--before`:
the older runs of the same seeds without it (bench/results/reporting-seeds-2-4/,
reference-seeds-2-4/, oracle-seeds-2-4/). Each scene is compared on the seeds its `--after`
runs cover, and only those (like for like): per method, the mask-box SSIM, ST-LPIPS and D-PSNR
means ± sd after and before, the D-PSNR gap to `none` after and before, and the share of the
SSIM and ST-LPIPS gain over `none` that the term keeps (after gain / before gain, where the
before gain is positive). Prints a Markdown table and, with --out, writes the JSON. With
--pairs the table is the README's instead: each held row without the term above the same row
with it, mean ± sd, and its D-PSNR gap to `none`.
"""
import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from rank_methods import pool, summary  # noqa: E402

BAR = [("ssim_bbox", True), ("lpips_bbox", False), ("d_psnr_bbox", True)]


def stats(per_seed, seeds):
    """Mean and sd over `seeds` of {seed: value}; None when a seed is missing."""
    if any(s not in per_seed for s in seeds):
        return None
    mean, sd = summary([per_seed[s] for s in seeds])
    return {"mean": mean, "sd": sd}


def gain(row, none, key, higher):
    """How much `row` beats `none` on `key` (positive: better)."""
    d = row[key]["mean"] - none[key]["mean"]
    return d if higher else -d


def compare(after, before):
    table = {}
    for scene, methods in sorted(after.items()):
        if "none" not in methods:
            sys.exit(f"{scene}: the --after reports have no none row")
        seeds = sorted(methods["none"]["d_psnr_bbox"])
        # the gaps and gains of both sides are taken against the --after none: the older none
        # runs must be the same runs reproduced
        old_none = before.get(scene, {}).get("none")
        for key, _ in BAR:
            for seed in seeds:
                if old_none is None or seed not in old_none[key]:
                    continue
                ours, theirs = methods["none"][key][seed], old_none[key][seed]
                if abs(ours - theirs) > 1e-6 * max(abs(ours), abs(theirs)):
                    sys.exit(f"{scene} seed {seed}: none's {key} differs before and after")
        rows = {}
        for method, metrics in methods.items():
            now = {k: stats(metrics[k], seeds) for k, _ in BAR}
            old_metrics = before.get(scene, {}).get(method)
            if method == "none":
                old_metrics = metrics
            old = {k: stats(old_metrics[k], seeds) for k, _ in BAR} if old_metrics else None
            if old and any(v is None for v in old.values()):
                old = None
            rows[method] = {"after": now, "before": old}
        none = rows["none"]["after"]
        for method, row in rows.items():
            if method == "none":
                continue
            row["d_psnr_gap_after"] = row["after"]["d_psnr_bbox"]["mean"] - none["d_psnr_bbox"]["mean"]
            if row["before"]:
                row["d_psnr_gap_before"] = row["before"]["d_psnr_bbox"]["mean"] - none["d_psnr_bbox"]["mean"]
                kept = {}
                for key, higher in BAR[:2]:
                    was = gain(row["before"], none, key, higher)
                    kept[key] = gain(row["after"], none, key, higher) / was if was > 0 else None
                row["gain_kept"] = kept
        table[scene] = {"seeds": seeds, "rows": rows}
    return table


def fmt(s, digits=3):
    return f"{s['mean']:.{digits}f} ± {s['sd']:.{digits}f}"


def print_pairs(table):
    """Each held row without the term above the same row with it (the README's oracle table)."""
    print("| scene (seeds) | row | geometry term | SSIM ↑ | ST-LPIPS ↓ | D-PSNR ↑ | D-PSNR gap to `none` |")
    print("|---|---|---|---:|---:|---:|---:|")
    for scene, t in table.items():
        seeds = ",".join(str(s) for s in t["seeds"])
        for method, row in t["rows"].items():
            sides = [("", row["after"], None)] if method == "none" else [
                ("off", row["before"], row.get("d_psnr_gap_before")),
                ("on", row["after"], row["d_psnr_gap_after"]),
            ]
            for term, side, gap in sides:
                if side is None:
                    continue
                cells = [fmt(side[k], 2 if k == "d_psnr_bbox" else 3) for k, _ in BAR]
                gap = "" if gap is None else f"{gap:+.2f}"
                print(f"| `{scene}` ({seeds}) | `{method}` | {term} | " + " | ".join(cells) + f" | {gap} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--after", nargs="+", required=True)
    ap.add_argument("--before", nargs="+", required=True)
    ap.add_argument("--out")
    ap.add_argument("--pairs", action="store_true", help="the README's table: each row off and on")
    a = ap.parse_args()
    table = compare(pool(a.after), pool(a.before))
    if a.pairs:
        print_pairs(table)
        write(a, table)
        return
    print("| scene (seeds) | row | SSIM | ST-LPIPS | D-PSNR | D-PSNR gap to none: before → after | gain kept: SSIM / ST-LPIPS |")
    print("|---|---|---:|---:|---:|---:|---:|")
    for scene, t in table.items():
        for method, row in t["rows"].items():
            cells = [fmt(row["after"][k]) for k, _ in BAR]
            gap = ""
            if "d_psnr_gap_after" in row:
                before = row.get("d_psnr_gap_before")
                gap = (f"{before:+.2f} → " if before is not None else "") + f"{row['d_psnr_gap_after']:+.2f}"
            kept = row.get("gain_kept") or {}
            share = " / ".join("—" if kept.get(k) is None else f"{100 * kept[k]:.0f}%" for k, _ in BAR[:2]) if kept else ""
            seeds = ",".join(str(s) for s in t["seeds"])
            print(f"| {scene} ({seeds}) | {method} | " + " | ".join(cells) + f" | {gap} | {share} |")
    write(a, table)


def write(a, table):
    """The pooled table as JSON, with the reports it came from (--out)."""
    if a.out:
        with open(a.out, "w") as f:
            json.dump({"after": a.after, "before": a.before, "table": table}, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
