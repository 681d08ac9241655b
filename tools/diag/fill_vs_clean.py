#!/usr/bin/env python3
"""Masked PSNR of 2D fills of one training view against its object-free image (issue 32).

For a procedural scene (its `clean/NAME.png` is the view without the object, its
`images_1/label/NAME.png` the object mask) and fills of that view written by
`cargo xtask fill --with prior --view NAME [--lora ...] --out FILL.png`, prints and writes the masked PSNR
of each fill and of a mean-colour fill (the unmasked pixels' mean):

    tools/diag/fill_vs_clean.py --scene SCENE --view view_016 \
        --fill base=FILL_A.png --fill personalised=FILL_B.png --out RESULT.json

Pinned: numpy, Pillow (tools/requirements.txt); no torch.
"""
import argparse
import json
import os

import numpy as np
from PIL import Image


def load(path):
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.float64) / 255


def masked_psnr(a, b, m):
    return float(-10 * np.log10(np.mean((a[m] - b[m]) ** 2)))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", required=True)
    ap.add_argument("--view", required=True)
    ap.add_argument("--fill", action="append", default=[], help="LABEL=PNG")
    ap.add_argument("--note", default="")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    clean = load(os.path.join(a.scene, "clean", a.view + ".png"))
    mask = np.asarray(Image.open(os.path.join(a.scene, "images_1", "label", a.view + ".png"))
                      .convert("L")) > 127
    mean_fill = clean.copy()
    mean_fill[mask] = clean[~mask].mean(0)
    rows = {"mean_colour_fill": masked_psnr(mean_fill, clean, mask)}
    for spec in a.fill:
        label, path = spec.split("=", 1)
        rows[label] = masked_psnr(load(path), clean, mask)
    doc = {"diagnosis": "masked PSNR (dB) of 2D fills of one training view against its "
                        "object-free image", "scene": a.scene, "view": a.view,
           "mask_pixels": int(mask.sum()), "note": a.note, "fills": a.fill, "psnr": rows}
    print(json.dumps(rows))
    with open(a.out, "w") as f:
        json.dump(doc, f, indent=2)
        f.write("\n")


if __name__ == "__main__":
    main()
