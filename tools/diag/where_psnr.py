#!/usr/bin/env python3
"""Where a run's whole-image PSNR goes (issue 49): the squared error of its test renders
against the scene's object-free test views, split into the mask, the crop margin (the mask's
box grown by MARGIN of its size on each side, as the guided crop and the geometry term's
`region = "crop"` grow it) and the rest of the view, pooled over the test views.

    tools/diag/where_psnr.py SCENE_DIR NAME=RUN_DIR [NAME=RUN_DIR ...] [--margin 0.25] [--out F.json]

SCENE_DIR is a procedural scene (`images_1/view_NNN.png` and `images_1/test_label/view_NNN.png`
for each test view); RUN_DIR a finished run (`renders/view_NNN_rgb.png`, test view order).
Prints one Markdown row per run: PSNR over the whole view and over each part, and each part's
share of the whole squared error. The squared error is pooled over the test views' 8-bit
renders, so the whole-view column is not the reports' PSNR (a mean over views of the float
renders; they differ by about 0.01 dB): compare runs within this tool's tables only.
Standard library and numpy only (its own PNG reader, 8-bit, non-interlaced, as the scenes and
renders are written).
"""
import argparse
import json
import math
import os
import struct
import zlib

import numpy as np

CHANNELS = {0: 1, 2: 3, 4: 2, 6: 4}


def unfilter(raw, height, stride, bpp):
    """The PNG scanline filters undone (RFC 2083, 6.3)."""
    out = np.zeros((height, stride), np.uint8)
    prev = np.zeros(stride, np.int32)
    pos = 0
    for y in range(height):
        kind = raw[pos]
        line = np.frombuffer(raw, np.uint8, stride, pos + 1).astype(np.int32)
        pos += 1 + stride
        if kind == 0:
            cur = line
        elif kind == 2:
            cur = (line + prev) & 255
        elif kind not in (1, 3, 4):
            raise ValueError(f"unknown PNG filter {kind}")
        else:
            cur = np.zeros(stride, np.int32)
            for x in range(stride):
                a = cur[x - bpp] if x >= bpp else 0
                b = prev[x]
                c = prev[x - bpp] if x >= bpp else 0
                if kind == 1:
                    p = a
                elif kind == 3:
                    p = (a + b) >> 1
                else:
                    e = a + b - c
                    pa, pb, pc = abs(e - a), abs(e - b), abs(e - c)
                    p = a if pa <= pb and pa <= pc else b if pb <= pc else c
                cur[x] = (line[x] + p) & 255
        out[y] = cur
        prev = cur
    return out


def read_png(path):
    """An 8-bit PNG as floats in [0, 1], shape (H, W, C)."""
    data = open(path, "rb").read()
    pos, idat, colour = 8, b"", None
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + n]
        pos += 12 + n
        if kind == b"IHDR":
            width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", body)
            if depth != 8 or interlace or colour not in CHANNELS:
                raise SystemExit(f"{path}: only 8-bit non-interlaced PNGs are read")
        elif kind == b"IDAT":
            idat += body
    if colour is None:
        raise SystemExit(f"{path}: no IHDR chunk")
    ch = CHANNELS[colour]
    pixels = unfilter(zlib.decompress(idat), height, width * ch, ch)
    return pixels.reshape(height, width, ch).astype(np.float64) / 255


def grow(size, margin):
    """The margin of a box side, rounded as gb-inpaint's `grown_bbox` rounds it (f32, half away
    from zero; Python's round() takes halves to even)."""
    return math.floor(float(np.float32(size) * np.float32(margin)) + 0.5)


def regions(mask, margin):
    """Boolean maps of the mask, the crop margin and the rest."""
    ys, xs = np.nonzero(mask)
    box = np.zeros_like(mask)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    gy, gx = grow(y1 - y0, margin), grow(x1 - x0, margin)
    box[max(0, y0 - gy) : y1 + gy, max(0, x0 - gx) : x1 + gx] = True
    return {"mask": mask, "margin": box & ~mask, "rest": ~box}


def split(scene, run, margin):
    """{part: (summed squared error, pixels)} over the test views of `run`."""
    labels = os.path.join(scene, "images_1", "test_label")
    acc = {"mask": [0.0, 0], "margin": [0.0, 0], "rest": [0.0, 0]}
    for name in sorted(os.listdir(labels)):
        stem = os.path.splitext(name)[0]
        mask = read_png(os.path.join(labels, name))[..., 0] > 0.5
        if not mask.any():
            raise SystemExit(f"{labels}/{name}: an empty mask")
        truth = read_png(os.path.join(scene, "images_1", name))[..., :3]
        render = read_png(os.path.join(run, "renders", f"{stem}_rgb.png"))[..., :3]
        err = ((truth - render) ** 2).mean(-1)
        for part, sel in regions(mask, margin).items():
            acc[part][0] += float(err[sel].sum())
            acc[part][1] += int(sel.sum())
    return acc


def psnr(sse, n):
    """PSNR of a summed squared error over n pixels; None without pixels or error."""
    return float(-10 * np.log10(sse / n)) if n and sse > 0 else None


def num(v):
    return "—" if v is None else f"{v:.2f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("runs", nargs="+", metavar="NAME=RUN_DIR")
    ap.add_argument("--margin", type=float, default=0.25)
    ap.add_argument("--out")
    a = ap.parse_args()
    rows = {}
    print("| run | whole | mask | crop margin | rest | share of the error: mask / margin / rest |")
    print("|---|---:|---:|---:|---:|---|")
    for arg in a.runs:
        name, _, run = arg.partition("=")
        acc = split(a.scene, run, a.margin)
        sse = sum(v[0] for v in acc.values())
        n = sum(v[1] for v in acc.values())
        row = {"whole": psnr(sse, n), "run": run}
        for part, (e, k) in acc.items():
            row[part] = {"psnr": psnr(e, k), "pixels": k, "share": e / sse}
        rows[name] = row
        share = " / ".join(f"{100 * row[p]['share']:.0f}%" for p in acc)
        cells = " | ".join(num(row[p]["psnr"]) for p in acc)
        print(f"| {name} | {num(row['whole'])} | {cells} | {share} |")
    if a.out:
        with open(a.out, "w") as f:
            json.dump({"scene": a.scene, "margin": a.margin, "rows": rows}, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
