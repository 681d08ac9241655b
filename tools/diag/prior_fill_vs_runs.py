"""Is the prior's own 2D fill better than what the NeRF already knows? (issue 8 diagnosis)

For every test view of a procedural scene (object-free ground truth, `test_label/` masks),
crops the mask's box grown by 25% per side (the guidance crop), resizes it to the prior's
resolution, inpaints it with `cargo xtask inpaint-image` (the known region blended in, K
seeds, their mean), and scores masked PSNR against the ground truth for:
  - the prior: one sample and the mean of K;
  - each run folder's test render (e.g. `none`, `gb-nerf`), cropped the same way;
  - a mean-colour fill.
If the prior's fill scores below the `none` run, distilling it can only pull the NeRF away
from what the other views already show. With `--condition-on RUN`, the prior also inpaints
only the unobserved pixels, seeing RUN's render on the observed ones (the visibility-aware
conditioning of `condition_on_observed`), keys `prior_unseen_mask_*`. Each score is also split into the mask pixels that
some training view observes and those none does (`hidden_region_visibility.py`), suffixes
`_observed` and `_unobserved`.

Usage (from the repository root, after `cargo build --workspace`):
  python tools/diag/prior_fill_vs_runs.py --scene SCENE_DIR --runs ABLATE_DIR \
      --methods none,gb-nerf --prompt "..." --negative-prompt "..." --out RESULT.json
Pinned: numpy, Pillow (tools/requirements.txt); no torch.
"""

import argparse
import json
import os
import subprocess
import sys

import numpy as np
from PIL import Image

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from hidden_region_visibility import Scene  # noqa: E402


def load(path):
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.float32) / 255


def resize(a, res, resample):
    img = Image.fromarray((np.clip(a, 0, 1) * 255).round().astype(np.uint8))
    return np.asarray(img.resize((res, res), resample), dtype=np.float32) / 255


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", required=True)
    ap.add_argument("--runs", required=True, help="folder with one sub-folder per run")
    ap.add_argument("--methods", default="none,gb-nerf")
    ap.add_argument("--prompt", required=True)
    ap.add_argument("--negative-prompt", default="")
    ap.add_argument("--prior", default="tiny")
    ap.add_argument("--lora", action="append", default=[],
                    help="LoRA file merged into the prior, in order (repeatable: the prior's "
                         "geometric LoRA, then a run's personalize/lora.safetensors)")
    ap.add_argument("--resolution", type=int, default=64)
    ap.add_argument("--samples", type=int, default=4)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--xtask", default="target-lead/debug/xtask")
    ap.add_argument("--work", default="/tmp/prior-fill")
    ap.add_argument("--out", required=True)
    ap.add_argument("--reuse", action="store_true", help="keep samples already in --work")
    ap.add_argument("--condition-on", default="",
                    help="run whose render fills the observed pixels for an unobserved-only fill")
    a = ap.parse_args()
    sc = Scene(a.scene)
    os.makedirs(a.work, exist_ok=True)
    images = os.path.join(a.scene, "images_1")
    names = sorted(os.path.splitext(f)[0] for f in os.listdir(os.path.join(images, "test_label")))
    methods = [m for m in a.methods.split(",") if m]
    rows = {}
    for name in names:
        gt = load(os.path.join(images, name + ".png"))
        mask = np.asarray(Image.open(os.path.join(images, "test_label", name + ".png")).convert("L")) > 127
        ys, xs = np.nonzero(mask)
        if len(ys) == 0:
            continue
        x0, x1, y0, y1 = xs.min(), xs.max() + 1, ys.min(), ys.max() + 1
        side = max(x1 - x0, y1 - y0)
        half = side // 2 + int(0.25 * side)
        cx, cy = (x0 + x1) // 2, (y0 + y1) // 2
        bx0, by0 = max(cx - half, 0), max(cy - half, 0)
        bx1, by1 = min(cx + half, gt.shape[1]), min(cy + half, gt.shape[0])

        def crop(img):
            return resize(img[by0:by1, bx0:bx1], a.resolution, Image.BILINEAR)

        gtc = crop(gt)

        def crop_mask(m):
            m3 = m[by0:by1, bx0:bx1, None].repeat(3, 2).astype(np.float32)
            return resize(m3, a.resolution, Image.NEAREST)[..., 0] > 0.5

        mc = crop_mask(mask)
        seen = crop_mask(mask & (sc.observed(name, mask) > 0)) & mc
        regions = {"": mc, "_observed": seen, "_unobserved": mc & ~seen}
        gt_path = os.path.join(a.work, name + "_gt.png")
        mask_path = os.path.join(a.work, name + "_mask.png")
        Image.fromarray((gtc * 255).round().astype(np.uint8)).save(gt_path)
        Image.fromarray((mc * 255).astype(np.uint8)).save(mask_path)

        def scores(key, x):
            out = {}
            for suffix, m in regions.items():
                if m.any():
                    out[key + suffix] = float(-10 * np.log10(np.mean((x[m] - gtc[m]) ** 2)))
            return out

        def inpaint(image_path, hole_path, tag):
            samples = []
            for seed in range(a.samples):
                out = os.path.join(a.work, f"{name}{tag}_s{seed}.png")
                if not (a.reuse and os.path.exists(out)):
                    loras = [arg for f in a.lora for arg in ("--lora", f)]
                    subprocess.run([a.xtask, "inpaint-image", "--prior", a.prior, *loras,
                                    "--image", image_path, "--mask", hole_path,
                                    "--prompt", a.prompt, "--negative-prompt", a.negative_prompt,
                                    "--steps", str(a.steps), "--seed", str(seed),
                                    "--blend-known", "--out", out],
                                   check=True, capture_output=True)
                samples.append(load(out))
            return samples

        samples = inpaint(gt_path, mask_path, "")
        fill = gtc.copy()
        fill[mc] = gtc[~mc].mean(0)
        row = {"mask_fraction": float(mc.mean()), "observed_fraction": float(seen.sum() / mc.sum())}
        row.update(scores("prior_one_sample", samples[0]))
        row.update(scores(f"prior_mean_of_{a.samples}", np.mean(samples, 0)))
        row.update(scores("mean_colour_fill", fill))
        for m in methods:
            row.update(scores(m, crop(load(os.path.join(a.runs, m, "renders", name + "_rgb.png")))))
        if a.condition_on:
            run = crop(load(os.path.join(a.runs, a.condition_on, "renders", name + "_rgb.png")))
            known = np.where(mc[..., None], run, gtc)
            hole = mc & ~seen
            known_path = os.path.join(a.work, name + "_known.png")
            hole_path = os.path.join(a.work, name + "_unobserved.png")
            Image.fromarray((np.clip(known, 0, 1) * 255).round().astype(np.uint8)).save(known_path)
            Image.fromarray((hole * 255).astype(np.uint8)).save(hole_path)
            cond = inpaint(known_path, hole_path, "_unseen")
            row.update(scores("prior_unseen_mask_one_sample", cond[0]))
            row.update(scores(f"prior_unseen_mask_mean_of_{a.samples}", np.mean(cond, 0)))
        rows[name] = row
        print(name, {k: round(v, 2) for k, v in row.items()}, flush=True)
    keys = sorted({k for r in rows.values() for k in r})
    mean = {k: float(np.mean([r[k] for r in rows.values() if k in r])) for k in keys}
    print("mean", {k: round(v, 2) for k, v in mean.items()})
    doc = {"diagnosis": "masked PSNR (dB) in the guidance crop of each test view",
           "scene": a.scene, "prior": a.prior, "lora": a.lora, "resolution": a.resolution,
           "ddim_steps": a.steps, "samples": a.samples, "blend_known": True,
           "condition_on": a.condition_on or None,
           "prompt": a.prompt, "negative_prompt": a.negative_prompt,
           "mean": mean, "per_view": rows}
    with open(a.out + ".tmp", "w") as f:
        json.dump(doc, f, indent=2)
    os.replace(a.out + ".tmp", a.out)


if __name__ == "__main__":
    main()
