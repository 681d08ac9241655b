#!/usr/bin/env python3
"""Parity fixtures for gb-eval's PSNR, SSIM, ST-LPIPS and D-PSNR.

Pinned references (see tools/requirements.txt):
    scikit-image==0.26.0, stlpips-pytorch==0.0.2, lpips==0.1.4, torch==2.15.0, torchvision,
    numpy, opencv-contrib-python-headless

Standard LPIPS (alex, vgg) has no weights here, so its check uses "formula weights": every
backbone/head tensor number t (in the order of LPIPS_KEYS) gets element i =
amp * sin(0.731 i + 1.37 t + 0.5) (f64, then f32), amp = 2 / sqrt(fan_in) for convolution
weights, 0.01 for biases; heads are 0.05 * (1 + sin(...)). The Rust test rebuilds the same
file (crates/gb-eval/tests/parity_lpips.rs), so no multi-MB weight file is committed.

Run from the repository root (about 10 s):
    GB_TEST_DATA=/work/shared /work/pyref/bin/python tools/eval_parity/make_fixtures.py

Writes crates/gb-eval/tests/fixtures/eval/:
    images/<case>_gt.png, images/<case>_pred.png, images/<case>_mask.png (0/255)
    depth/<case>_{pred,gt}.npy (float32 disparity maps)
    expected.json: one entry per case with the reference numbers.

Every image is an 8-bit RGB PNG (JPEG artefacts are baked in and stored losslessly), so the Rust
side decodes exactly the same bytes. Pixels are converted like gb_core::read_rgb does,
u8 -> float32 / 255, then widened to float64 for scikit-image. Real photographs are small crops
(64x64 or so) of the shared data, never whole files.
"""

import json
import os
import sys
import types
from pathlib import Path

import cv2
import numpy as np
import skimage
import torch
from safetensors.torch import load_file
from skimage.color import rgb2gray
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

# stlpips-pytorch 0.0.2 imports two packages it never uses at inference (IPython.embed for
# debugging, torchsummary for printing); stub them instead of installing them.
for _name, _attr in [("IPython", "embed"), ("torchsummary", "summary")]:
    _mod = types.ModuleType(_name)
    setattr(_mod, _attr, None)
    sys.modules.setdefault(_name, _mod)
from stlpips_pytorch import stlpips  # noqa: E402
import lpips  # noqa: E402

assert skimage.__version__ == "0.26.0", skimage.__version__
assert torch.__version__.startswith("2.15.0"), torch.__version__

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "crates/gb-eval/tests/fixtures/eval"
DATA = Path(os.environ.get("GB_TEST_DATA", ROOT.parent / "shared"))
RNG = np.random.default_rng(20261122)


def read_rgb_u8(path):
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img.ndim == 3 and img.shape[2] == 4:  # composite RGBA on white, in 8 bits
        a = img[:, :, 3:4].astype(np.float64) / 255.0
        img = np.round(img[:, :, :3] * a + 255.0 * (1.0 - a)).astype(np.uint8)
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def crop(img, y, x, h, w):
    return np.ascontiguousarray(img[y : y + h, x : x + w])


def to_u8(x):
    return np.clip(np.round(x * 255.0), 0, 255).astype(np.uint8)


def to_f(u8):
    """gb_core::read_rgb: u8 -> f32 / 255, then f64 for the references."""
    return (u8.astype(np.float32) / np.float32(255.0)).astype(np.float64)


def noise(u8, sigma):
    return to_u8(u8 / 255.0 + RNG.normal(0.0, sigma, u8.shape))


def gaussian_blur(u8, sigma):
    return cv2.GaussianBlur(u8, (0, 0), sigma, borderType=cv2.BORDER_REFLECT_101)


def box_blur(u8, k):
    return cv2.blur(u8, (k, k), borderType=cv2.BORDER_REFLECT_101)


def jpeg(u8, quality):
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(u8, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def ellipse_mask(h, w, cy, cx, ry, rx):
    yy, xx = np.mgrid[0:h, 0:w]
    return ((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2 <= 1.0


def procedural_rings(h, w):
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    r = np.hypot(yy - h * 0.45, xx - w * 0.55)
    base = np.stack([0.5 + 0.5 * np.sin(r * 0.6), 0.5 + 0.5 * np.cos(xx * 0.3), (yy / h) ** 2], axis=-1)
    return to_u8(base)


def procedural_checker(h, w):
    yy, xx = np.mgrid[0:h, 0:w]
    c = ((yy // 6 + xx // 6) % 2).astype(np.float64)
    base = np.stack([0.2 + 0.6 * c, 0.8 - 0.5 * c, 0.4 + 0.3 * np.sin(xx * 0.2)], axis=-1)
    return to_u8(base)


def make_cases():
    statue = read_rgb_u8(DATA / "data/statue/images_2/IMG_2707.png")
    fern = read_rgb_u8(sorted((DATA / "data/fern/images_8").glob("*.png"))[0])
    lego = read_rgb_u8(DATA / "data/lego_small/test/r_0.png")
    cases = []
    s = crop(statue, 150, 200, 64, 64)
    cases.append(("statue_noise", s, noise(s, 0.05)))
    cases.append(("statue_shift1", s, crop(statue, 150, 201, 64, 64)))
    f = crop(fern, 100, 150, 64, 64)
    cases.append(("fern_blur", f, gaussian_blur(f, 1.5)))
    cases.append(("fern_jpeg", f, jpeg(f, 15)))
    lg = crop(lego, 60, 60, 80, 72)
    cases.append(("lego_jpeg", lg, jpeg(lg, 10)))
    rings = procedural_rings(56, 72)
    cases.append(("rings_boxblur", rings, box_blur(rings, 5)))
    checker = procedural_checker(64, 64)
    cases.append(("checker_noise", checker, noise(checker, 0.1)))
    const_gt = np.full((48, 40, 3), 128, np.uint8)
    cases.append(("constant_pair", const_gt, np.full((48, 40, 3), 179, np.uint8)))
    cases.append(("constant_vs_noise", const_gt, noise(const_gt, 0.1)))
    cases.append(("identical", s, s.copy()))
    return cases


def stlpips_model():
    model = stlpips.LPIPS(net="alex", variant="shift_tolerant", verbose=False)
    state = load_file(str(DATA / "weights/stlpips_alex_shift_tolerant.safetensors"))
    res = model.load_state_dict(state, strict=False)
    # `lins.N` are aliases of `linN` (the same tensors registered twice).
    assert all(k.startswith("lins.") for k in res.missing_keys), res
    assert not res.unexpected_keys, res
    return model.eval()


LPIPS_CONVS = {
    "alex": ["net.slice1.0", "net.slice2.3", "net.slice3.6", "net.slice4.8", "net.slice5.10"],
    "vgg": [
        "net.slice1.0", "net.slice1.2", "net.slice2.5", "net.slice2.7", "net.slice3.10", "net.slice3.12",
        "net.slice3.14", "net.slice4.17", "net.slice4.19", "net.slice4.21", "net.slice5.24", "net.slice5.26",
        "net.slice5.28",
    ],
}
LPIPS_FORMULA_CASES = ["statue_noise", "fern_jpeg", "rings_boxblur"]


def lpips_keys(net):
    keys = []
    for c in LPIPS_CONVS[net]:
        keys += [c + ".weight", c + ".bias"]
    return keys + [f"lin{k}.model.1.weight" for k in range(5)]


def formula_tensor(t, shape, key):
    n = int(np.prod(shape))
    wave = np.sin(0.731 * np.arange(n, dtype=np.float64) + 1.37 * t + 0.5)
    if key.startswith("lin"):
        vals = 0.05 * (1.0 + wave)
    elif key.endswith(".bias"):
        vals = 0.01 * wave
    else:
        fan_in = int(np.prod(shape[1:]))
        vals = 2.0 / np.sqrt(fan_in) * wave
    return torch.from_numpy(vals.astype(np.float32).reshape(shape))


def lpips_formula_model(net):
    model = lpips.LPIPS(net=net, pretrained=False, pnet_rand=True, verbose=False)
    state = model.state_dict()
    new = {}
    for t, key in enumerate(lpips_keys(net)):
        new[key] = formula_tensor(t, tuple(state[key].shape), key)
    res = model.load_state_dict(new, strict=False)
    assert all(k.startswith("lins.") or k.startswith("scaling_layer.") for k in res.missing_keys), res
    return model.eval()


def to_tensor(f64):
    return torch.from_numpy(f64.astype(np.float32)).permute(2, 0, 1)[None]


def ssim_rgb(a, b, **kw):
    return structural_similarity(
        a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1.0, **kw
    )


def masked_ssim(gt, pred, mask, channel_axis):
    kw = {"channel_axis": channel_axis} if channel_axis is not None else {}
    _, smap = ssim_rgb(gt, pred, full=True, **kw)
    if smap.ndim == 3:
        return float(np.mean([smap[:, :, c][mask].mean() for c in range(smap.shape[2])]))
    return float(smap[mask].mean())


def bbox(mask):
    ys, xs = np.nonzero(mask)
    return int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1


def finite_or_inf(v):
    return "inf" if np.isinf(v) else float(v)


def to8b_disparity(d):
    """nerf-pytorch's to8b(disp / max(disp)): truncation, not rounding."""
    return (255 * np.clip(d / np.max(d), 0, 1)).astype(np.uint8)


def depth_cases(out_dir):
    yy, xx = np.mgrid[0:24, 0:32].astype(np.float32)
    gt = (1.0 / (1.0 + 0.05 * xx + 0.02 * yy)).astype(np.float32) * 3.0
    pred = (gt * (1.0 + 0.05 * np.sin(xx * 0.7)) + 0.02).astype(np.float32)
    entries = []
    for name, p, g in [("ramp", pred, gt), ("ramp_identical", gt, gt.copy())]:
        np.save(out_dir / f"{name}_pred.npy", p)
        np.save(out_dir / f"{name}_gt.npy", g)
        p8 = np.repeat(to8b_disparity(p.astype(np.float64))[:, :, None], 3, axis=2)
        g8 = np.repeat(to8b_disparity(g.astype(np.float64))[:, :, None], 3, axis=2)
        v = peak_signal_noise_ratio(g8, p8, data_range=255)
        entries.append({"name": name, "pred": f"{name}_pred.npy", "gt": f"{name}_gt.npy", "d_psnr": finite_or_inf(v)})
    return entries


def main():
    (OUT / "images").mkdir(parents=True, exist_ok=True)
    (OUT / "depth").mkdir(parents=True, exist_ok=True)
    model = stlpips_model()
    formula = {net: lpips_formula_model(net) for net in ["alex", "vgg"]}
    entries = []
    for name, gt_u8, pred_u8 in make_cases():
        h, w, _ = gt_u8.shape
        mask = ellipse_mask(h, w, h * 0.5, w * 0.45, h * 0.3, w * 0.25)
        for suffix, img in [("gt", gt_u8), ("pred", pred_u8)]:
            cv2.imwrite(str(OUT / f"images/{name}_{suffix}.png"), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(OUT / f"images/{name}_mask.png"), mask.astype(np.uint8) * 255)
        gt, pred = to_f(gt_u8), to_f(pred_u8)
        x0, y0, x1, y1 = bbox(mask)
        gt_b, pred_b = gt[y0:y1, x0:x1], pred[y0:y1, x0:x1]
        m3 = np.repeat(mask[:, :, None], 3, axis=2)
        mse_mask = np.mean((gt[m3] - pred[m3]) ** 2)
        psnr_mask = np.inf if mse_mask == 0 else 10 * np.log10(1.0 / mse_mask)
        with torch.no_grad():
            lp = model(to_tensor(pred), to_tensor(gt), normalize=True).item()
            extra = {}
            if name in LPIPS_FORMULA_CASES:
                for net, m in formula.items():
                    extra[f"lpips_{net}_formula"] = m(to_tensor(pred), to_tensor(gt), normalize=True).item()
        entries.append(
            {
                "name": name,
                "gt": f"{name}_gt.png",
                "pred": f"{name}_pred.png",
                "mask": f"{name}_mask.png",
                "bbox": [x0, y0, x1, y1],
                "psnr": finite_or_inf(peak_signal_noise_ratio(gt, pred, data_range=1.0)),
                "psnr_bbox": finite_or_inf(peak_signal_noise_ratio(gt_b, pred_b, data_range=1.0)),
                "psnr_mask": finite_or_inf(psnr_mask),
                "ssim": float(ssim_rgb(gt, pred, channel_axis=-1)),
                "ssim_bbox": float(ssim_rgb(gt_b, pred_b, channel_axis=-1)),
                "ssim_mask": masked_ssim(gt, pred, mask, -1),
                "ssim_luminance": float(ssim_rgb(rgb2gray(gt), rgb2gray(pred))),
                "ssim_luminance_mask": masked_ssim(rgb2gray(gt), rgb2gray(pred), mask, None),
                "stlpips": lp,
                **extra,
            }
        )
        print(f"{name:20s} psnr {entries[-1]['psnr']} ssim {entries[-1]['ssim']:.6f} stlpips {lp:.6f}")
    doc = {
        "generator": "tools/eval_parity/make_fixtures.py",
        "versions": {
            "scikit-image": skimage.__version__,
            "torch": torch.__version__,
            "stlpips-pytorch": "0.0.2",
            "lpips": "0.1.4",
            "numpy": np.__version__,
            "opencv": cv2.__version__,
        },
        "inf_encoding": "the string \"inf\"",
        "cases": entries,
        "depth_cases": depth_cases(OUT / "depth"),
    }
    (OUT / "expected.json").write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    main()
