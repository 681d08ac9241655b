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


class Scene:
    """Cameras, ground-truth depths and masks of a procedural scene."""

    def __init__(self, scene):
        self.images = os.path.join(scene, "images_1")
        self.names = sorted(os.path.splitext(f)[0] for f in os.listdir(self.images) if f.endswith(".png"))
        self.tests = set(os.path.splitext(f)[0] for f in os.listdir(os.path.join(self.images, "test_label")))
        self.rot, self.trans, hwf = cameras(scene)
        self.depth = {n: np.load(os.path.join(scene, "depth_1", n + ".npy")) for n in self.names}
        self.h, self.w = self.depth[self.names[0]].shape
        self.f = hwf[0, 2]
        self.train = [i for i, n in enumerate(self.names) if n not in self.tests]
        self.masks = {i: self.mask("label", self.names[i]) for i in self.train}

    def mask(self, folder, name):
        return np.asarray(Image.open(os.path.join(self.images, folder, name + ".png")).convert("L")) > 127

    def observed(self, name, region):
        """Per pixel of test view `name` inside `region` (bool [h, w]): how many training
        views observe its surface point; 0 outside the region."""
        i = self.names.index(name)
        h, w, f = self.h, self.w, self.f
        cx, cy = w / 2, h / 2
        count = np.zeros((h, w), int)
        ys, xs = np.nonzero(region & (self.depth[name] > 0))
        d = self.depth[name][ys, xs]
        pc = np.stack([(xs + 0.5 - cx) / f * d, -(ys + 0.5 - cy) / f * d, -d], 1)
        world = pc @ self.rot[i].T + self.trans[i]
        views = np.zeros(len(d), int)
        for j in self.train:
            pu = (world - self.trans[j]) @ self.rot[j]
            z = -pu[:, 2]
            ok = z > 1e-6
            u = np.where(ok, f * pu[:, 0] / np.maximum(z, 1e-6) + cx, -1)
            v = np.where(ok, -f * pu[:, 1] / np.maximum(z, 1e-6) + cy, -1)
            ui, vi = np.floor(u).astype(int), np.floor(v).astype(int)
            inside = ok & (ui >= 0) & (ui < w) & (vi >= 0) & (vi < h)
            uc, vc = np.clip(ui, 0, w - 1), np.clip(vi, 0, h - 1)
            dj = self.depth[self.names[j]][vc, uc]
            views += inside & ~self.masks[j][vc, uc] & (np.abs(dj - z) <= 0.02 * z)
        count[ys, xs] = views
        return count


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", required=True)
    ap.add_argument("--out")
    a = ap.parse_args()
    sc = Scene(a.scene)
    rows = {}
    for n in sc.names:
        if n not in sc.tests:
            continue
        m = sc.mask("test_label", n) & (sc.depth[n] > 0)
        if not m.any():
            continue
        views = sc.observed(n, m)[m]
        rows[n] = {"mask_pixels": int(m.sum()), "observed_fraction": float((views > 0).mean()),
                   "mean_views_observing": float(views.mean())}
        print(n, rows[n])
    train = sc.train
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
