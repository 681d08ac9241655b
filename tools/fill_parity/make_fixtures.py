#!/usr/bin/env python3
"""Parity fixtures for gb-fill's frequency-selective reconstruction (`fill --with fsr`).

The reference is OpenCV's own FSR, `cv2.xphoto.inpaint(..., cv2.xphoto.INPAINT_FSR_FAST)` and
`INPAINT_FSR_BEST`, from the pinned `opencv-contrib-python-headless==4.14.0.94` and
`numpy==2.4.6` (tools/requirements.txt). No data is read: the images are made here, each a
96x96 8-bit RGB picture with a hole:
    stripes   oblique stripes and a finer second pattern (gb-fill's unit-test texture), square hole
    bricks    a brick wall (rows of offset rectangles with mortar lines), square hole
    noise     smooth random texture (blurred uniform noise, seed 7), elliptic hole
    gradient  a smooth two-way colour ramp with a soft shading bump, square hole

Run from the repository root (a few seconds):
    PYTHONPATH=/path/to/site python3 tools/fill_parity/make_fixtures.py

Writes crates/gb-fill/tests/fixtures/fsr/:
    <case>_truth.png           the picture, 8-bit RGB
    <case>_mask.png            0/255, 255 = the hole to fill
    <case>_opencv_fast.png     OpenCV's FSR_FAST fill of the picture with its hole
    <case>_opencv_best.png     OpenCV's FSR_BEST fill
    expected.json              per case: the hole's pixel count and the masked PSNR (dB, over
                               the hole's pixels and channels, values in [0, 1]) of each
                               OpenCV fill against the truth

OpenCV takes the image in BGR with the hole set to 0 and a mask of the known pixels (255 known,
0 to fill); the PNGs are written in RGB. The Rust test (crates/gb-fill/tests/parity.rs) fills
the same picture and compares masked PSNRs within a stated margin, not bit for bit: the two
implementations differ (see gb_fill::fsr's module docs).
"""

import json
import os
import sys
from pathlib import Path

import cv2
import numpy as np

OUT = Path("crates/gb-fill/tests/fixtures/fsr")
SIZE = 96


def stripes():
    y, x = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64)
    a = np.sin(2 * np.pi * (x + 0.5 * y) / 12.0)
    b = np.cos(2 * np.pi * (0.3 * x - y) / 7.0)
    return np.stack([0.5 + 0.25 * a + 0.15 * b, 0.5 + 0.3 * a, 0.5 - 0.2 * b + 0.1 * a], -1)


def bricks():
    y, x = np.mgrid[0:SIZE, 0:SIZE]
    row = y // 12
    shift = np.where(row % 2 == 0, 0, 12)
    mortar = ((y % 12) < 2) | (((x + shift) % 24) < 2)
    tone = 0.05 * np.sin(0.9 * row + 0.37 * ((x + shift) // 24))
    brick = np.stack([0.62 + tone, 0.30 + 0.5 * tone, 0.22 + 0.3 * tone], -1)
    grey = np.array([0.78, 0.76, 0.72])
    return np.where(mortar[..., None], grey, brick)


def noise():
    rng = np.random.default_rng(7)
    raw = rng.uniform(0.0, 1.0, (SIZE, SIZE, 3)).astype(np.float32)
    smooth = cv2.GaussianBlur(raw, (0, 0), 2.5)
    lo, hi = smooth.min(), smooth.max()
    return 0.15 + 0.7 * (smooth - lo) / (hi - lo)


def gradient():
    y, x = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64) / (SIZE - 1)
    bump = 0.15 * np.exp(-((x - 0.4) ** 2 + (y - 0.6) ** 2) / 0.05)
    return np.stack([0.2 + 0.6 * x + bump, 0.3 + 0.5 * y + bump, 0.7 - 0.4 * x * y + bump], -1)


def square_hole(x0, y0, side):
    m = np.zeros((SIZE, SIZE), bool)
    m[y0 : y0 + side, x0 : x0 + side] = True
    return m


def ellipse_hole():
    y, x = np.mgrid[0:SIZE, 0:SIZE].astype(np.float64)
    return ((x - 50) / 17.0) ** 2 + ((y - 44) / 11.0) ** 2 <= 1.0


CASES = {
    "stripes": (stripes, lambda: square_hole(34, 30, 28)),
    "bricks": (bricks, lambda: square_hole(40, 38, 20)),
    "noise": (noise, ellipse_hole),
    "gradient": (gradient, lambda: square_hole(30, 36, 24)),
}


def to_u8(img):
    return np.clip(np.rint(np.asarray(img) * 255.0), 0, 255).astype(np.uint8)


def masked_psnr(a_u8, b_u8, hole):
    a = a_u8.astype(np.float64) / 255.0
    b = b_u8.astype(np.float64) / 255.0
    mse = np.mean((a[hole] - b[hole]) ** 2)
    return float(10.0 * np.log10(1.0 / mse))


def opencv_fill(truth_u8, hole, flag):
    bgr = cv2.cvtColor(truth_u8, cv2.COLOR_RGB2BGR)
    bgr[hole] = 0
    known = np.where(hole, 0, 255).astype(np.uint8)
    dst = np.zeros_like(bgr)
    cv2.xphoto.inpaint(bgr, known, dst, flag)
    return cv2.cvtColor(dst, cv2.COLOR_BGR2RGB)


def write_png(path, rgb_or_gray):
    img = rgb_or_gray
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_RGB2BGR)
    if not cv2.imwrite(str(path), img):
        sys.exit(f"cannot write {path}")


def main():
    if not hasattr(cv2, "xphoto"):
        sys.exit("cv2 lacks the contrib modules (cv2.xphoto): install opencv-contrib-python-headless")
    OUT.mkdir(parents=True, exist_ok=True)
    expected = {
        "reference": f"opencv-contrib-python-headless {cv2.__version__}, numpy {np.__version__}",
        "psnr": "masked PSNR in dB over the hole's pixels and channels, values in [0, 1]",
        "cases": {},
    }
    for name, (picture, hole_of) in CASES.items():
        truth = to_u8(picture())
        hole = hole_of()
        fast = opencv_fill(truth, hole, cv2.xphoto.INPAINT_FSR_FAST)
        best = opencv_fill(truth, hole, cv2.xphoto.INPAINT_FSR_BEST)
        write_png(OUT / f"{name}_truth.png", truth)
        write_png(OUT / f"{name}_mask.png", np.where(hole, 255, 0).astype(np.uint8))
        write_png(OUT / f"{name}_opencv_fast.png", fast)
        write_png(OUT / f"{name}_opencv_best.png", best)
        expected["cases"][name] = {
            "hole_pixels": int(hole.sum()),
            "opencv_fast_psnr": masked_psnr(fast, truth, hole),
            "opencv_best_psnr": masked_psnr(best, truth, hole),
        }
        print(name, expected["cases"][name])
    with open(OUT / "expected.json", "w") as f:
        json.dump(expected, f, indent=2)
        f.write("\n")
    print(f"wrote {OUT}")


if __name__ == "__main__":
    os.chdir(Path(__file__).resolve().parents[2])
    main()
