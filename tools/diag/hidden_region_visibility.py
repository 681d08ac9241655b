"""How much of a procedural scene's hidden region do the training views see? (issue 8)

For each test view (object-free ground truth) of a scene written by `cargo xtask scene`, every
pixel inside its `test_label/` mask is back-projected with the ground-truth depth and
projected into every training view. It counts as observed when it lands inside that view,
outside that view's object mask, and in front of (within 2% of) that view's ground-truth
depth, i.e. not hidden by the object or anything else. The fraction of mask pixels observed
by at least one training view says how much a multi-view reconstruction can know without a
prior.

Usage: python tools/diag/hidden_region_visibility.py --scene SCENE_DIR [--out RESULT.json]
Pinned: numpy, Pillow (tools/requirements.txt).
"""

import argparse
import json
import os

import numpy as np
from PIL import Image


def cameras(scene):
    pb = np.load(os.path.join(scene, "poses_bounds.npy"))
    poses = pb[:, :15].reshape(-1, 3, 5)
    # LLFF columns (down, right, back) -> OpenGL (right, up, back)
    rot = np.stack([poses[:, :, 1], -poses[:, :, 0], poses[:, :, 2]], axis=2)
    return rot, poses[:, :, 3], poses[:, :, 4]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", required=True)
    ap.add_argument("--out")
    a = ap.parse_args()
    images = os.path.join(a.scene, "images_1")
    names = sorted(os.path.splitext(f)[0] for f in os.listdir(images) if f.endswith(".png"))
    tests = set(os.path.splitext(f)[0] for f in os.listdir(os.path.join(images, "test_label")))
    rot, trans, hwf = cameras(a.scene)
    depth = {n: np.load(os.path.join(a.scene, "depth_1", n + ".npy")) for n in names}
    h, w = depth[names[0]].shape
    f = hwf[0, 2]
    cx, cy = w / 2, h / 2
    train = [i for i, n in enumerate(names) if n not in tests]
    masks = {i: np.asarray(Image.open(os.path.join(images, "label", names[i] + ".png")).convert("L")) > 127
             for i in train}
    rows = {}
    for i, n in enumerate(names):
        if n not in tests:
            continue
        m = np.asarray(Image.open(os.path.join(images, "test_label", n + ".png")).convert("L")) > 127
        ys, xs = np.nonzero(m & (depth[n] > 0))
        if len(ys) == 0:
            continue
        d = depth[n][ys, xs]
        pc = np.stack([(xs + 0.5 - cx) / f * d, -(ys + 0.5 - cy) / f * d, -d], 1)
        world = pc @ rot[i].T + trans[i]
        seen = np.zeros(len(d), bool)
        views = np.zeros(len(d), int)
        for j in train:
            pu = (world - trans[j]) @ rot[j]
            z = -pu[:, 2]
            ok = z > 1e-6
            u = np.where(ok, f * pu[:, 0] / np.maximum(z, 1e-6) + cx, -1)
            v = np.where(ok, -f * pu[:, 1] / np.maximum(z, 1e-6) + cy, -1)
            ui, vi = np.floor(u).astype(int), np.floor(v).astype(int)
            inside = ok & (ui >= 0) & (ui < w) & (vi >= 0) & (vi < h)
            uc, vc = np.clip(ui, 0, w - 1), np.clip(vi, 0, h - 1)
            visible = inside & ~masks[j][vc, uc] & (np.abs(depth[names[j]][vc, uc] - z) <= 0.02 * z)
            seen |= visible
            views += visible
        rows[n] = {"mask_pixels": int(len(d)), "observed_fraction": float(seen.mean()),
                   "mean_views_observing": float(views.mean())}
        print(n, rows[n])
    mean = float(np.mean([r["observed_fraction"] for r in rows.values()]))
    print("mean observed fraction", round(mean, 3))
    if a.out:
        doc = {"scene": a.scene, "train_views": len(train), "observed_fraction_mean": mean,
               "per_test_view": rows}
        with open(a.out + ".tmp", "w") as fh:
            json.dump(doc, fh, indent=2)
        os.replace(a.out + ".tmp", a.out)


if __name__ == "__main__":
    main()
