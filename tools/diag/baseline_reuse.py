#!/usr/bin/env python3
"""Compares a held run that trained its own unguided field with the same run given a finished
`none` run as `--baseline` (issue 49; gb_inpaint::run::unguided), into one JSON: each run's
`unguided_seconds` and `unguided_from`, and whether their test-view metrics agree exactly.

    tools/diag/baseline_reuse.py OUT.json TRAINED_RUN_DIR REUSED_RUN_DIR [--command TEXT]

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
    a = ap.parse_args()
    runs = {}
    for name, d in (("trained", a.trained), ("reused", a.reused)):
        with open(f"{d}/metrics.json") as f:
            runs[name] = json.load(f)
    t, r = runs["trained"], runs["reused"]
    differing = sorted(k for k in t["mean"] if t["mean"][k] != r["mean"].get(k))
    result = {
        "note": "the same held run with and without a --baseline none run of the same "
                "preset, seed, scene and device; the unguided pass reads its checkpoint",
        "command": a.command,
        "machine": {"arch": platform.machine(), "os": platform.system().lower()},
        "device": r["device"],
        "runs": {n: {"dir": d, "unguided_seconds": runs[n].get("unguided_seconds"),
                     "unguided_from": runs[n].get("unguided_from"),
                     "train_seconds_this_run": runs[n]["train_seconds_this_run"]}
                 for n, d in (("trained", a.trained), ("reused", a.reused))},
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
