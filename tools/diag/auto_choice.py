#!/usr/bin/env python3
"""Issue 45, item 3: `gb-nerf-auto`'s choices on the tuning seeds, judged on the real holes.

Each input is a `quality-<scene>-<time>.json` of `tools/diag/auto_tuning.sh` (rows `none`,
`gb-nerf-auto` and, with GUIDED=1, `gb-nerf-unseen`, one seed a report). The runs' own
`metrics.json` (under the report's `per_seed[].runs` folder) give the auto choice: the
pseudo-holes, the trials and their wall time.

The rules are fixed before the runs are read (the issue's wording):
- **Which choice was right on the real hole**: the guided run (`gb-nerf-unseen`, the fixed
  weights 1e-5) against `none` on the quality bar (mask-box SSIM, ST-LPIPS, D-PSNR), by
  `rank_methods.py`'s rule for two variants: the guided run wins when it is better on at least
  two of the three metrics; otherwise `none` is the right choice. The auto choice is right when
  its run does not lose to the winner on two or more of the three (its (0, 0) choice is the
  `none` run exactly; a partial choice is judged by its own run).
- **Never clearly worse than `none`**, pooled over the seeds per scene: SSIM no more than 0.02
  lower, ST-LPIPS no more than 0.02 higher, D-PSNR no more than 1 dB lower.
- **Cost**: the trials' wall time (`auto.seconds`: placement, shared prefix, trials, scoring)
  against one guided run of the same scene and seed in the same benchmark run (the
  `gb-nerf-unseen` run's training, its geometry pass included); the target is at most half.
- The default becomes `gb-nerf-auto` when it is right on at least 5 of the 6 cells and never
  clearly worse on any scene.

    python3 tools/diag/auto_choice.py --out bench/results/auto-holes-tuning.json REPORT.json...

Several reports of one scene and seed make one cell: each method's row comes from the last
report given that has it (a re-run of `none` and `gb-nerf-auto` after a change, given after
the first report, keeps the first report's guided row). `--previous TUNING.json` supplies
the guided run's wall time of a cell whose run folder is gone (an earlier judgement's
`guided_run_seconds`).

Standard library only.
"""

import argparse
import json
import os
import statistics
import sys

BAR = [("ssim_bbox", True), ("lpips_bbox", False), ("d_psnr_bbox", True)]
CLEARLY_WORSE = {"ssim_bbox": 0.02, "lpips_bbox": 0.02, "d_psnr_bbox": 1.0}
AUTO, NONE, GUIDED = "gb-nerf-auto", "none", "gb-nerf-unseen"


def better_count(a, b):
    """How many bar metrics `a` is strictly better on than `b`."""
    return sum((a[k] > b[k]) if hi else (a[k] < b[k]) for k, hi in BAR)


def run_metrics(report_path, runs, method):
    """The run's metrics.json, or None. `runs` may be relative to the repository root (the
    folder the report's command ran in) or to the report."""
    for base in (os.getcwd(), os.path.dirname(report_path)):
        path = os.path.join(base, runs, method, "metrics.json")
        if os.path.exists(path):
            with open(path) as f:
                return json.load(f)
    return None


def read_report(path):
    """(scene, seed, rows by method, runs folder) of one report."""
    with open(path) as f:
        report = json.load(f)
    scene = report["scene"].split()[0]
    if len(report["scene_seeds"]) != 1:
        sys.exit(f"{path}: one seed a report expected")
    seed = report["scene_seeds"][0]
    rows = {r["method"]: r for r in report["baselines"]["rows"]}
    return scene, seed, rows, report["per_seed"][0]["runs"]


def cell(paths, previous):
    """One scene and seed from its reports (later reports' rows win), judged."""
    rows, source = {}, {}
    for p in paths:
        scene, seed, r, runs = read_report(p)
        for m, row in r.items():
            if m in rows and m == NONE:
                same = all(abs(rows[m][k] - row[k]) < 1e-9 for k, _ in BAR)
                if not same:
                    print(f"note: {scene} {seed}: `none` differs between the reports", file=sys.stderr)
            rows[m] = row
            source[m] = (p, runs)
    path = source.get(AUTO, (paths[-1], None))[0]
    for m in (NONE, AUTO):
        if m not in rows:
            sys.exit(f"{path}: no {m} row")
    runs = source[AUTO][1]
    bar = {m: {k: rows[m][k] for k, _ in BAR} for m in rows}
    auto_metrics = run_metrics(path, runs, AUTO)
    if auto_metrics is None or not auto_metrics.get("auto"):
        sys.exit(f"{path}: no auto choice in {runs}/{AUTO}/metrics.json")
    a = auto_metrics["auto"]
    out = {
        "scene": scene,
        "seed": seed,
        "report": path,
        "metrics": bar,
        "choice": [a["lambda_rgb"], a["lambda_normal"]],
        "holes": [
            {
                "side": h["side"],
                "resemblance": h["resemblance"],
                "whole_views": h["whole_views"],
                "box": h["hole"],
            }
            for h in a["holes"]
        ],
        "trials": [
            {
                "weights": [t["lambda_rgb"], t["lambda_normal"]],
                "rank_sum": t["rank_sum"],
                "scores": {k: t.get(k) for k, _ in BAR},
                "per_hole": t.get("per_hole", []),
                "seconds": t["seconds"],
            }
            for t in a["trials"]
        ],
        "ranked_by": a["ranked_by"],
        "trial_steps": a["trial_steps"],
        "prefix_steps": a.get("prefix_steps", 0),
        "prefix_seconds": a.get("prefix_seconds", 0.0),
        "trials_seconds": a["seconds"],
        "cached": a["cached"],
        "auto_run_train_seconds": auto_metrics["train_seconds_this_run"],
        "none_train_seconds": rows[NONE]["train_seconds"],
    }
    if GUIDED in rows:
        guided = bar[GUIDED]
        guided_wins = better_count(guided, bar[NONE]) >= 2
        winner = GUIDED if guided_wins else NONE
        out["right_choice"] = "guidance" if guided_wins else "none"
        out["auto_right"] = better_count(bar[winner], bar[AUTO]) < 2
        g = run_metrics(source[GUIDED][0], source[GUIDED][1], GUIDED)
        guided_seconds = None
        if g is not None:
            guided_seconds = g["train_seconds_this_run"] + (g.get("unguided_seconds") or 0.0)
            out["guided_unguided_pass_seconds"] = g.get("unguided_seconds")
        elif (scene, seed) in previous:
            guided_seconds = previous[(scene, seed)]
            out["guided_run_seconds_from"] = "--previous"
        if guided_seconds:
            out["guided_run_seconds"] = guided_seconds
            out["trials_over_guided_run"] = a["seconds"] / guided_seconds
    out["reports"] = list(paths)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("reports", nargs="+")
    ap.add_argument("--out", required=True)
    ap.add_argument("--previous", help="an earlier judgement, for guided runs' wall times")
    args = ap.parse_args()
    previous = {}
    if args.previous:
        with open(args.previous) as f:
            for c in json.load(f)["cells"]:
                if c.get("guided_run_seconds"):
                    previous[(c["scene"], c["seed"])] = c["guided_run_seconds"]
    groups = {}
    for p in args.reports:
        scene, seed, _, _ = read_report(p)
        groups.setdefault((scene, seed), []).append(p)
    cells = sorted(
        (cell(ps, previous) for ps in groups.values()), key=lambda c: (c["scene"], c["seed"])
    )
    scenes = {}
    for c in cells:
        scenes.setdefault(c["scene"], []).append(c)
    pooled = {}
    for scene, cs in scenes.items():
        means = {
            m: {k: statistics.mean(c["metrics"][m][k] for c in cs) for k, _ in BAR}
            for m in (NONE, AUTO)
        }
        worse = {
            k: (means[NONE][k] - means[AUTO][k] if hi else means[AUTO][k] - means[NONE][k])
            > CLEARLY_WORSE[k]
            for k, hi in BAR
        }
        pooled[scene] = {
            "seeds": [c["seed"] for c in cs],
            "means": means,
            "clearly_worse_than_none": worse,
        }
    judged = [c for c in cells if "auto_right" in c]
    right = sum(c["auto_right"] for c in judged)
    never_worse = not any(any(p["clearly_worse_than_none"].values()) for p in pooled.values())
    ratios = [c["trials_over_guided_run"] for c in cells if "trials_over_guided_run" in c]
    summary = {
        "cells": len(cells),
        "judged": len(judged),
        "right": right,
        "never_clearly_worse": never_worse,
        "trials_over_guided_run_max": max(ratios) if ratios else None,
        "default_switch": len(judged) == 6 and right >= 5 and never_worse,
    }
    doc = {
        "note": "gb-nerf-auto on the tuning seeds, judged on the real holes by the rules of "
        "tools/diag/auto_choice.py (fixed before the runs were read)",
        "rules": __doc__.split("\n\n")[2],
        "summary": summary,
        "pooled": pooled,
        "cells": cells,
    }
    with open(args.out, "w") as f:
        json.dump(doc, f, indent=2)
        f.write("\n")
    for c in cells:
        print(
            f"{c['scene']:7} {c['seed']:4} choice {c['choice']} right={c.get('right_choice', '?')}"
            f" auto_right={c.get('auto_right', '?')} trials {c['trials_seconds']:.0f} s"
            f" / guided {c.get('guided_run_seconds', float('nan')):.0f} s"
            f" = {c.get('trials_over_guided_run', float('nan')):.2f}"
        )
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
