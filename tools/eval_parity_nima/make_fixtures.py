#!/usr/bin/env python3
"""Parity fixtures for gb-eval's NIMA (crates/gb-eval/src/nima, test tests/nima_parity.rs).

Pinned references (also in tools/requirements.txt):
    torch==2.15.0  torchvision==0.29.2  timm==1.0.31  numpy==2.4.6  safetensors  Pillow

The reference is pyiqa's `nima` metric (chaofengc/IQA-PyTorch, pyiqa/archs/nima_arch.py,
`NIMA(base_model_name='inception_resnet_v2', num_classes=10)`), rebuilt here from timm
without pyiqa itself (pyiqa would download ImageNet weights at construction):

    base_model = timm.create_model('inception_resnet_v2', features_only=True)  # FeatureListNet
    x = (x - mean) / std           # timm pretrained_cfg: mean = std = (0.5, 0.5, 0.5)
    x = base_model(x)[-1]          # conv2d_7b output, 1536 channels
    x = AdaptiveAvgPool2d(1)(x)
    dist = Sequential(Flatten, Dropout(0), Linear(1536, 10), Softmax(-1))(x)
    mos = sum_i i * dist_i, i = 1..10

In eval mode pyiqa first resizes and crops (NIMA.preprocess): torchvision
`F.resize(x, 299)` (shorter side to 299, bilinear, antialias=True) then
`F.center_crop(x, 299)`. The fixtures use 96 instead of 299 so that the Rust test stays fast
(the Rust model takes the size as a parameter; 299 is its default).

No NIMA weights exist here, so every parameter and buffer is filled from a tiny integer
generator that the Rust test reimplements bit for bit; only the ordered tensor names, shapes
and a checksum per tensor are committed (weights.json), never the 55M weights:

    k = index of the tensor in the state_dict order of the pyiqa model (base_model.* then
        classifier.2.*), counting only float tensors (num_batches_tracked skipped)
    z = splitmix64_finaliser((k << 32) | i + 0x9E3779B97F4A7C15)  for element i (uint64,
        wrapping): z = (z ^ z>>30) * 0xBF58476D1CE4E5B9; z = (z ^ z>>27) * 0x94D049BB133111EB;
        z = z ^ z>>31
    u = ((z >> 40) - 2^23) / 2^23   exactly, in float32, in [-1, 1)
    conv / linear weight: u * s, s = float32(sqrt(6 / fan_in)) (He-uniform), fan_in =
        prod(shape[1:]); 1 / sqrt(fan_in) made the deep random network nearly input-blind
        (features of the two images 14% apart at sqrt(3), almost equal at 1), He-uniform keeps
        them 47% apart with O(1) logits, so the check is sensitive to the input path
    conv / linear bias:   u * s with the fan_in of the layer's weight
    batch norm: weight 1 + 0.1 u, bias 0.1 u, running_mean 0.1 u, running_var 1 + 0.5 |u|
    (all float32 arithmetic with float32 constants)
    checksum = sum_i (float32 bits of v_i) * (i + 1), uint64 wrapping, as 16 hex digits

Writes crates/gb-eval/tests/fixtures/nima/ (about 0.4 MB):
    weights.json       {"tensors": [[name, shape, checksum], ...], ...}
    image_0.png        61x50 procedural image (upsampled to 96, odd crop offset 10.5 -> 10)
    image_1.png        232x174 procedural "photo-like" image (downsampled, antialiased)
    expected.safetensors  for each image n: `image_n.input` [1, 3, 96, 96] (pyiqa's preprocess:
        resize + center crop + normalisation), `image_n.features` [1, 1536] (pooled),
        `image_n.logits` [1, 10], `image_n.dist` [1, 10], `image_n.mos` [1]
    expected.json      mos, dist and feature statistics, for the report

Run from the repository root (about 10 s):
    /work/pyref/bin/python tools/eval_parity_nima/make_fixtures.py
"""
import json
import os

import numpy as np
import PIL.Image
import timm
import torch
import torch.nn as nn
import torchvision
import torchvision.transforms.functional as TF
from safetensors.numpy import save_file

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT = os.path.join(ROOT, "crates", "gb-eval", "tests", "fixtures", "nima")
INPUT_SIZE = 96

GOLDEN = np.uint64(0x9E3779B97F4A7C15)
MUL1 = np.uint64(0xBF58476D1CE4E5B9)
MUL2 = np.uint64(0x94D049BB133111EB)


def unit(k, n):
    """u(k, i) for i < n: float32 in [-1, 1), exact multiples of 2^-23."""
    with np.errstate(over="ignore"):
        z = (np.uint64(k) << np.uint64(32)) | np.arange(n, dtype=np.uint64)
        z = z + GOLDEN
        z = (z ^ (z >> np.uint64(30))) * MUL1
        z = (z ^ (z >> np.uint64(27))) * MUL2
        z = z ^ (z >> np.uint64(31))
    t = (z >> np.uint64(40)).astype(np.int64) - (1 << 23)
    return t.astype(np.float32) / np.float32(1 << 23)


def tensor_values(k, name, shape, shapes):
    """The generated float32 values of tensor number k (see the module docs)."""
    n = int(np.prod(shape))
    u = unit(k, n)
    f32 = np.float32
    if name.endswith(".running_mean") or name.endswith(".bn.bias"):
        v = f32(0.1) * u
    elif name.endswith(".running_var"):
        v = f32(1.0) + f32(0.5) * np.abs(u)
    elif name.endswith(".bn.weight"):
        v = f32(1.0) + f32(0.1) * u
    elif name.endswith(".weight") or name.endswith(".bias"):
        weight_shape = shape if name.endswith(".weight") else shapes[name[: -len("bias")] + "weight"]
        fan_in = int(np.prod(weight_shape[1:]))
        v = u * f32(np.sqrt(6.0 / np.float64(fan_in)))
    else:
        raise ValueError(f"no generator rule for {name}")
    assert v.dtype == np.float32
    return v.reshape(shape)


def checksum(v):
    bits = v.reshape(-1).view(np.uint32).astype(np.uint64)
    with np.errstate(over="ignore"):
        s = np.sum(bits * np.arange(1, bits.size + 1, dtype=np.uint64), dtype=np.uint64)
    return f"{int(s):016x}"


class NimaRef(nn.Module):
    """pyiqa's NIMA (inception_resnet_v2, 10 bins) without its weight download."""

    def __init__(self):
        super().__init__()
        self.base_model = timm.create_model("inception_resnet_v2", pretrained=False, features_only=True)
        self.global_pool = nn.AdaptiveAvgPool2d(1)
        in_ch = self.base_model.feature_info.channels()[-1]
        self.classifier = nn.Sequential(nn.Flatten(), nn.Dropout(p=0.0), nn.Linear(in_ch, 10), nn.Softmax(dim=-1))
        self.default_mean = torch.Tensor(self.base_model.pretrained_cfg["mean"]).view(1, 3, 1, 1)
        self.default_std = torch.Tensor(self.base_model.pretrained_cfg["std"]).view(1, 3, 1, 1)

    def preprocess(self, x, size):
        # pyiqa: T.functional.resize(x, input_size[-1]); T.functional.center_crop(x, input_size[-1])
        x = TF.resize(x, size)
        x = TF.center_crop(x, size)
        return (x - self.default_mean.to(x)) / self.default_std.to(x)

    def head(self, x):
        feats = self.global_pool(self.base_model(x)[-1]).flatten(1)
        logits = self.classifier[:3](feats)
        dist = self.classifier[3](logits)
        mos = (dist * torch.arange(1, 11).to(dist)).sum(dim=-1)
        return feats, logits, dist, mos


def procedural_small():
    """61x50: smooth gradients, a disc and hard stripes."""
    h, w = 50, 61
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    r = 0.5 + 0.5 * np.sin(x / 7.0) * np.cos(y / 5.0)
    g = x / w
    b = ((x // 6 + y // 6) % 2) * 0.8 + 0.1
    disc = (x - 30) ** 2 + (y - 22) ** 2 < 12**2
    g = np.where(disc, 0.95, g)
    img = np.stack([r, g, b], -1)
    return np.clip(np.round(img * 255.0), 0, 255).astype(np.uint8)


def procedural_photo_like():
    """232x174: sky gradient, ground plane with texture, a few objects, sensor noise."""
    h, w = 174, 232
    rng = np.random.default_rng(6)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    horizon = 70 + 8 * np.sin(x / 23.0)
    sky = np.stack([0.45 + 0.3 * y / h, 0.6 + 0.25 * y / h, 0.95 - 0.1 * y / h], -1)
    ground_tex = 0.5 + 0.25 * np.sin(x / 3.1 + 2 * np.sin(y / 9.0)) * np.exp(-(y - horizon) / 200.0)
    ground = np.stack([0.35 * ground_tex + 0.2, 0.45 * ground_tex + 0.15, 0.2 * ground_tex + 0.1], -1)
    img = np.where((y > horizon)[..., None], ground, sky)
    box = (np.abs(x - 150) < 25) & (np.abs(y - 95) < 30)
    img[box] = [0.8, 0.25, 0.2]
    ball = (x - 70) ** 2 + (y - 120) ** 2 < 22**2
    shade = np.clip(1.0 - ((x - 62) ** 2 + (y - 112) ** 2) / (2 * 22.0**2), 0.2, 1.0)
    img[ball] = (np.array([0.2, 0.35, 0.85])[None] * shade[ball][:, None])
    img = img + rng.normal(0.0, 0.03, img.shape)
    return np.clip(np.round(img * 255.0), 0, 255).astype(np.uint8)


def main():
    torch.manual_seed(0)
    os.makedirs(OUT, exist_ok=True)
    model = NimaRef().eval()
    sd = model.state_dict()
    names = [n for n, t in sd.items() if t.is_floating_point()]
    assert all(n.endswith("num_batches_tracked") for n, t in sd.items() if not t.is_floating_point())
    shapes = {n: tuple(sd[n].shape) for n in names}
    entries = []
    with torch.no_grad():
        for k, name in enumerate(names):
            v = tensor_values(k, name, shapes[name], shapes)
            sd[name].copy_(torch.from_numpy(np.ascontiguousarray(v)))
            assert np.array_equal(sd[name].numpy(), v)
            entries.append([name, list(shapes[name]), checksum(v)])
    n_params = sum(int(np.prod(s)) for s in shapes.values())
    bn_eps = {m.eps for m in model.modules() if isinstance(m, nn.BatchNorm2d)}
    assert bn_eps == {1e-3}, bn_eps
    with open(os.path.join(OUT, "weights.json"), "w") as f:
        f.write("{\n")
        f.write('  "model": "pyiqa NIMA(base_model_name=inception_resnet_v2, num_classes=10): timm 1.0.31 '
                'inception_resnet_v2 (features_only) + classifier.2 = Linear(1536, 10)",\n')
        f.write('  "generator": "see tools/eval_parity_nima/make_fixtures.py",\n')
        f.write(f'  "bn_eps": 0.001,\n  "n_values": {n_params},\n  "tensors": [\n')
        f.write(",\n".join("    " + json.dumps(e) for e in entries))
        f.write("\n  ]\n}\n")

    images = [procedural_small(), procedural_photo_like()]
    arrays, summary = {}, {"input_size": INPUT_SIZE, "images": []}
    with torch.no_grad():
        for n, im in enumerate(images):
            PIL.Image.fromarray(im).save(os.path.join(OUT, f"image_{n}.png"))
            # pyiqa's imread2tensor: PIL RGB -> to_tensor (u8 / 255, float32)
            x = TF.to_tensor(PIL.Image.open(os.path.join(OUT, f"image_{n}.png")).convert("RGB"))[None]
            inp = model.preprocess(x, INPUT_SIZE)
            feats, logits, dist, mos = model.head(inp)
            arrays[f"image_{n}.input"] = inp.numpy().astype(np.float32)
            arrays[f"image_{n}.features"] = feats.numpy().astype(np.float32)
            arrays[f"image_{n}.logits"] = logits.numpy().astype(np.float32)
            arrays[f"image_{n}.dist"] = dist.numpy().astype(np.float32)
            arrays[f"image_{n}.mos"] = mos.numpy().astype(np.float32)
            summary["images"].append({
                "file": f"image_{n}.png", "size_wh": [im.shape[1], im.shape[0]],
                "mos": float(mos[0]), "dist": [float(v) for v in dist[0]],
                "logits": [float(v) for v in logits[0]],
                "features_max_abs": float(feats.abs().max()), "features_mean": float(feats.mean()),
            })
            print(f"image_{n}: mos {float(mos[0]):.6f} logits {logits[0].numpy()} "
                  f"features max {float(feats.abs().max()):.4f} mean {float(feats.mean()):.4f}")
    save_file(arrays, os.path.join(OUT, "expected.safetensors"))
    summary["versions"] = {"torch": torch.__version__, "torchvision": torchvision.__version__,
                           "timm": timm.__version__, "numpy": np.__version__}
    with open(os.path.join(OUT, "expected.json"), "w") as f:
        json.dump(summary, f, indent=1)
        f.write("\n")
    print(f"{len(entries)} tensors, {n_params} values")


if __name__ == "__main__":
    main()
