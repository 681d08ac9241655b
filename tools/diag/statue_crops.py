#!/usr/bin/env python3
"""The mask boxes of statue's first three masked training views, as one picture.

Rows: the views; columns: the capture, then each run's render (name=RUN_DIR, its
renders/train_NAME_rgb.png), each crop the mask's bounding box grown by 16 pixels. Needs numpy
and opencv-python-headless (any recent version; only imread, rectangle-free slicing, putText
and imwrite are used).

Usage: statue_crops.py OUT.jpg SCENE_DIR name=RUN_DIR [name=RUN_DIR ...]
"""
import os
import sys

import cv2
import numpy as np

MARGIN = 16
VIEWS = ["IMG_2707", "IMG_2708", "IMG_2709"]


def crop_box(mask):
    ys, xs = np.nonzero(mask)
    h, w = mask.shape
    return (max(ys.min() - MARGIN, 0), min(ys.max() + MARGIN + 1, h),
            max(xs.min() - MARGIN, 0), min(xs.max() + MARGIN + 1, w))


def label(img, text):
    out = img.copy()
    cv2.putText(out, text, (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 2)
    cv2.putText(out, text, (4, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1)
    return out


def main():
    out, scene, runs = sys.argv[1], sys.argv[2], [a.split("=", 1) for a in sys.argv[3:]]
    rows = []
    for view in VIEWS:
        mask_path = os.path.join(scene, "images_2", "label", view + ".png")
        mask = cv2.imread(mask_path, 0)
        if mask is None or not (mask > 0).any():
            sys.exit(f"{mask_path}: no mask, or an empty one")
        y0, y1, x0, x1 = crop_box(mask > 0)
        capture_path = os.path.join(scene, "images_2", view + ".png")
        capture = cv2.imread(capture_path)
        if capture is None:
            sys.exit(f"{capture_path}: cannot read the capture")
        cells = [label(capture[y0:y1, x0:x1], "capture")]
        for name, run in runs:
            render = cv2.imread(os.path.join(run, "renders", f"train_{view}_rgb.png"))
            if render is None:
                sys.exit(f"{run}: no renders/train_{view}_rgb.png")
            cells.append(label(render[y0:y1, x0:x1], name))
        rows.append(np.hstack(cells))
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 4), (0, width - r.shape[1]), (0, 0))) for r in rows]
    cv2.imwrite(out, np.vstack(rows), [cv2.IMWRITE_JPEG_QUALITY, 90])


if __name__ == "__main__":
    main()
