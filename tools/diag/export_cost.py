#!/usr/bin/env python3
"""Issue 47, item 4: the export's cost against the run's own renders, from one run folder.

Reads RUN/metrics.json (the scene, the training time and the time of the run's renders of its
shown views: the test views, or on a capture without them its first three masked training
views) and the last `export` step of tools/diag/statue_fast.sh's steps.log ("wrote N views
(WxH) to ... in S s"), and writes OUT.json: seconds per view and per megapixel of both (the
run's renders are taken at the export's resolution, the training views'), and their ratio.
The machine recorded is the one this script runs on: run it where the run ran.

Usage: export_cost.py RUN_DIR STEPS_LOG OUT.json
"""
import json
import os
import platform
import re
import sys


def main():
    run, log, out = sys.argv[1:4]
    metrics = json.load(open(os.path.join(run, "metrics.json")))
    text = open(log).read()
    found = re.findall(r"wrote (\d+) views \((\d+)x(\d+)\) to \S+ in ([0-9.]+) s", text)
    if not found:
        sys.exit(f"{log}: no 'wrote N views' line of the export step")
    m = (None,) + found[-1]
    views, w, h, seconds = int(m[1]), int(m[2]), int(m[3]), float(m[4])
    shown = metrics["eval"]["n_images"]
    render = metrics["render_seconds"]
    mpx = w * h / 1e6
    export_view = seconds / views
    render_view = render / shown
    cpu = next((l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo")
                if l.startswith("model name")), platform.processor())
    report = {
        "benchmark": "the nerfstudio export of a finished run (cargo xtask export --run) "
                     "against the same run's renders of its shown views (issue 47, item 4)",
        "run": run,
        "scene": metrics["scene"],
        "preset": metrics["preset"],
        "device": metrics["device"],
        "machine": {"cpu": cpu, "logical_cores": os.cpu_count(), "os": platform.system().lower()},
        "commands": [l[3:].split(" (")[0] for l in text.splitlines() if l.startswith(("== none: ", "== export: "))
                     and " exit " not in l],
        "train_seconds": metrics["train_seconds_this_run"],
        "export": {"views": views, "width": w, "height": h, "seconds": seconds,
                   "seconds_per_view": export_view,
                   "seconds_per_megapixel": export_view / mpx},
        "reference_run_renders": {"views": shown, "seconds": render,
                                  "seconds_per_view": render_view,
                                  "seconds_per_megapixel": render_view / mpx},
        "export_over_render_per_megapixel": export_view / render_view,
        "export_over_training": seconds / metrics["train_seconds_this_run"],
    }
    with open(out, "w") as f:
        json.dump(report, f, indent=1)
        f.write("\n")
    print(json.dumps({k: report[k] for k in
                      ("export_over_render_per_megapixel", "export_over_training")}))


if __name__ == "__main__":
    main()
