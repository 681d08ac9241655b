#!/usr/bin/env python3
"""Compares a run that trained its field (a held run's unguided field, or the whole field of
an `auto` run that chose no guidance) with the same run given a finished `none` run as
`--baseline` (gb_inpaint::run::unguided), into one JSON: each run's `unguided_seconds`,
`unguided_from`, `field_from`, training seconds and wall time (`--wall`, from the caller's
timer), and whether their test-view metrics agree exactly.

    tools/diag/baseline_reuse.py OUT.json TRAINED_RUN_DIR REUSED_RUN_DIR [--command TEXT]
        [--wall TRAINED_S REUSED_S]

Standard library only.
"""
import argparse
import json
import platform


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("trained")
    ap.add_argument("reused")
    ap.add_argument("--command", default="")
    ap.add_argument("--wall", nargs=2, type=float, metavar=("TRAINED_S", "REUSED_S"))
    a = ap.parse_args()
    runs = {}
    for name, d in (("trained", a.trained), ("reused", a.reused)):
        with open(f"{d}/metrics.json") as f:
            runs[name] = json.load(f)
    t, r = runs["trained"], runs["reused"]
    differing = sorted(k for k in t["mean"] if t["mean"][k] != r["mean"].get(k))
    result = {
        "note": "the same run with and without a --baseline none run of the same preset, "
                "seed, scene and device, whose checkpoint it reads (unguided_from: the "
                "geometry term's unguided field; field_from: the whole field)",
        "command": a.command,
        "machine": {"arch": platform.machine(), "os": platform.system().lower()},
        "device": r["device"],
        "runs": {n: {"dir": d, "unguided_seconds": runs[n].get("unguided_seconds"),
                     "unguided_from": runs[n].get("unguided_from"),
                     "field_from": runs[n].get("field_from"),
                     "wall_seconds": a.wall[i] if a.wall else None,
                     "train_seconds_this_run": runs[n]["train_seconds_this_run"]}
                 for i, (n, d) in enumerate((("trained", a.trained), ("reused", a.reused)))},
        "mean_metrics_equal": not differing,
        "per_view_metrics_equal": t["views"] == r["views"],
        "differing_mean_metrics": differing,
        "mean": t["mean"],
    }
    with open(a.out, "w") as f:
        json.dump(result, f, indent=2)
        f.write("\n")
    print(json.dumps({k: result[k] for k in ("runs", "mean_metrics_equal",
                                             "per_view_metrics_equal")}, indent=2))


if __name__ == "__main__":
    main()
