#!/usr/bin/env python3
"""Pools single `inpaint` runs into one JSON of mask-box metrics (standard library only).

Used for the reference-view tuning (bench/results/reference-tuning-seed-100.json), whose
variants are method files rather than rows of `bench quality`:

    tools/diag/pool_runs.py --out RESULT.json --note TEXT \
        --run SCENE:LABEL:RUN_DIR [--run ...] [--rank LABEL,LABEL,...]

Each run folder's metrics.json gives the test views' mask-box SSIM, PSNR, ST-LPIPS and
D-PSNR (null where the run had no metric weights), and for a method with `"auto"` weights the
choice (`auto`: the pseudo-hole, each trial's scores and the chosen weights). `--rank` ranks the listed labels per
scene and per bar metric (SSIM up, ST-LPIPS down, D-PSNR up; the rule of rank_methods.py)
and sums the ranks; the lowest sum wins.
"""
import argparse
import json
import os
import platform

BAR = [("ssim_bbox", True), ("lpips_bbox", False), ("d_psnr_bbox", True)]


def metrics(run_dir):
    path = os.path.join(run_dir, "metrics.json")
    with open(path) as f:
        m = json.load(f)
    e = m["eval"]
    return {
        "ssim_bbox": m["mean"].get("ssim_bbox"),
        "psnr_bbox": m["mean"].get("psnr_bbox"),
        "lpips_bbox": e.get("lpips_bbox"),
        "d_psnr_bbox": e.get("d_psnr_bbox"),
        "psnr": m["mean"].get("psnr"),
        "train_seconds": m.get("train_seconds_this_run"),
        "method": m.get("method"),
        "run": run_dir,
        # the weights the scene chose (lambda = "auto"): pseudo-hole, trials, choice
        "auto": m.get("auto"),
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--run", action="append", required=True, help="SCENE:LABEL:RUN_DIR")
    ap.add_argument("--rank", default="")
    ap.add_argument("--note", default="")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    rows = {}
    for spec in a.run:
        scene, label, run_dir = spec.split(":", 2)
        rows.setdefault(scene, {})[label] = metrics(run_dir)
    ranked = [l for l in a.rank.split(",") if l]
    sums = {l: 0 for l in ranked}
    per_scene = {}
    for scene, runs in rows.items():
        per_scene[scene] = {}
        for key, higher in BAR:
            have = [l for l in ranked if l in runs and runs[l][key] is not None]
            order = sorted(have, key=lambda l: runs[l][key], reverse=higher)
            per_scene[scene][key] = order
            for i, l in enumerate(order):
                sums[l] += i + 1
    out = {
        "machine": f"{platform.node()} ({os.cpu_count()} CPUs)",
        "note": a.note,
        "runs": rows,
        "rank_order": per_scene,
        "rank_sums": sums,
        "winner": min(sums, key=sums.get) if sums else None,
    }
    with open(a.out, "w") as f:
        json.dump(out, f, indent=2)
        f.write("\n")
    print(json.dumps({"rank_sums": sums, "winner": out["winner"]}))


if __name__ == "__main__":
    main()
