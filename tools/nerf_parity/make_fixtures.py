"""PyTorch reference fixtures for gb-nerf: volume rendering, the instant-ngp hash encoding
and the depth-to-normal plane fit, in plain torch (no CUDA extensions).

Pinned: torch==2.15.0, numpy (see tools/requirements.txt). Run from the repository root:

    /work/pyref/bin/python tools/nerf_parity/make_fixtures.py

It writes crates/gb-nerf/tests/fixtures/nerf_parity.json (a few tens of KB), which
crates/gb-nerf/tests/pytorch_parity.rs compares against. Every formula mirrors the doc
comments of crates/gb-nerf/src/render/volume.rs, field/hash_grid.rs and render/normals.rs.
"""

import json
import math
import os

import numpy as np
import torch
import torch.nn.functional as F

torch.manual_seed(0)
torch.set_default_dtype(torch.float32)
OUT = os.path.join("crates", "gb-nerf", "tests", "fixtures", "nerf_parity.json")


def flat(t):
    return [float(v) for v in t.detach().reshape(-1).tolist()]


# ---------------------------------------------------------------- volume rendering
def composite(sigma, rgb, t, delta, bg, bg_depth):
    tau = sigma.clamp(0.0, 1e10) * delta.clamp(0.0, 1e10)
    shifted = torch.cat([torch.zeros_like(tau[:, :1]), tau[:, :-1]], 1)
    trans = torch.exp(-torch.cumsum(shifted, 1))
    alpha = 1.0 - torch.exp(-tau)
    w = trans * alpha
    acc = w.sum(1, keepdim=True).clamp(0.0, 1.0)
    color = (w[..., None] * rgb).sum(1) + (1.0 - acc) * torch.tensor(bg)
    depth = ((w * t).sum(1, keepdim=True) + (1.0 - acc) * bg_depth).reshape(-1)
    disp = 1.0 / depth.clamp_min(1e-10)
    return color, depth, disp, acc.reshape(-1), w


def volume_fixture():
    r, s = 5, 9
    sigma = (torch.rand(r, s) * 4.0).pow(3).requires_grad_(True)
    rgb = torch.rand(r, s, 3).requires_grad_(True)
    delta = torch.rand(r, s) * 0.3 + 0.01
    t = 1.0 + torch.cumsum(delta, 1) - 0.5 * delta
    bg, bg_depth = [0.1, 0.2, 0.3], 6.0
    color, depth, disp, acc, w = composite(sigma, rgb, t, delta, bg, bg_depth)
    g_rgb, g_d, g_disp, g_a = torch.randn(r, 3), torch.randn(r), torch.randn(r), torch.randn(r)
    loss = (color * g_rgb).sum() + (depth * g_d).sum() + (disp * g_disp).sum() + (acc * g_a).sum()
    loss.backward()
    return {
        "rays": r, "samples": s, "sigma": flat(sigma), "rgb": flat(rgb), "t": flat(t),
        "delta": flat(delta), "background": bg, "background_depth": bg_depth,
        "g_rgb": flat(g_rgb), "g_depth": flat(g_d), "g_disparity": flat(g_disp),
        "g_opacity": flat(g_a),
        "out_rgb": flat(color), "out_depth": flat(depth), "out_disparity": flat(disp),
        "out_opacity": flat(acc), "out_weights": flat(w),
        "grad_sigma": flat(sigma.grad), "grad_rgb": flat(rgb.grad),
    }


# ---------------------------------------------------------------- hash encoding
def hash_encode(x, table, levels, feats, log2_t, base, max_res):
    """instant-ngp's multiresolution hash encoding, explicitly (full table per level)."""
    T = 1 << log2_t
    f32 = np.float32
    b = f32(np.exp((np.log(f32(max_res)) - np.log(f32(base))) / f32(levels - 1)))
    outs = []
    x = x.clamp(0.0, 1.0)
    for l in range(levels):
        scale = f32(f32(base) * f32(b) ** l - f32(1.0))
        res = int(math.ceil(scale)) + 1
        pos = x * float(scale) + 0.5
        g = torch.floor(pos)
        f = pos - g
        g = g.long()
        acc = torch.zeros(x.shape[0], feats)
        for c in range(8):
            bits = [(c >> i) & 1 for i in range(3)]
            w = torch.ones(x.shape[0])
            for i in range(3):
                w = w * (f[:, i] if bits[i] else 1.0 - f[:, i])
            gc = g + torch.tensor(bits)
            if res ** 3 <= T:
                idx = (gc[:, 0] + gc[:, 1] * res + gc[:, 2] * res * res) % T
            else:
                m = 0xFFFFFFFF
                h = gc[:, 0] ^ ((gc[:, 1] * 2654435761) & m) ^ ((gc[:, 2] * 805459861) & m)
                idx = (h & m) % T
            acc = acc + w[:, None] * table[l * T + idx]
        outs.append(acc)
    return torch.cat(outs, 1)


def hash_fixture():
    cfg = dict(levels=4, feats=2, log2_t=10, base=4.0, max_res=64.0)
    n = 24
    table = (torch.randn(cfg["levels"] << cfg["log2_t"], cfg["feats"]) * 0.2).requires_grad_(True)
    x = torch.rand(n, 3)
    x[0] = torch.tensor([0.0, 0.0, 0.0])
    x[1] = torch.tensor([1.0, 1.0, 1.0])
    out = hash_encode(x, table, **cfg)
    g = torch.randn_like(out)
    (out * g).sum().backward()
    return {
        "levels": cfg["levels"], "features_per_level": cfg["feats"], "log2_table_size": cfg["log2_t"],
        "base_resolution": cfg["base"], "max_resolution": cfg["max_res"],
        "points": flat(x), "table": flat(table), "g": flat(g),
        "out": flat(out), "grad_table": flat(table.grad),
    }


# ---------------------------------------------------------------- plane fit
def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def depth_to_normals(depth, fx, fy, cx, cy, kernel, ds):
    h, w = depth.shape
    ds = max(1, min(ds, h, w))
    hs, ws = h // ds, w // ds
    z = F.avg_pool2d(depth[None, None], ds)[0, 0] if ds > 1 else depth
    fx, fy, cx, cy = fx / ds, fy / ds, cx / ds, cy / ds
    v, u = torch.meshgrid(torch.arange(hs, dtype=torch.float32), torch.arange(ws, dtype=torch.float32), indexing="ij")
    ax = (u + 0.5 - cx) / fx
    ay = -(v + 0.5 - cy) / fy
    pts = [ax * z, ay * z, -z]
    mean = [float(p.detach().mean()) for p in pts]
    spread = math.sqrt(sum(float((p.detach() - m).pow(2).mean()) for p, m in zip(pts, mean)))
    scale = 1.0 / spread if (math.isfinite(spread) and spread > 1e-20) else 1.0
    p = [(pp - m) * scale for pp, m in zip(pts, mean)]
    mom = torch.stack([p[0], p[1], p[2], p[0] * p[0], p[0] * p[1], p[0] * p[2], p[1] * p[1], p[1] * p[2], p[2] * p[2]])
    k = kernel
    m = F.avg_pool2d(mom[None], k, stride=1, padding=k // 2, count_include_pad=False)[0]
    mx, my, mz = m[0], m[1], m[2]
    cxx, cxy, cxz = m[3] - mx * mx, m[4] - mx * my, m[5] - mx * mz
    cyy, cyz, czz = m[6] - my * my, m[7] - my * mz, m[8] - mz * mz
    r0, r1, r2 = [cxx, cxy, cxz], [cxy, cyy, cyz], [cxz, cyz, czz]
    n0, n1, n2 = cross(r1, r2), cross(r0, r2), cross(r0, r1)
    sq = lambda a: a[0] ** 2 + a[1] ** 2 + a[2] ** 2
    l0, l1, l2 = sq(n0), sq(n1), sq(n2)
    pick1 = l1 > l0
    best = [torch.where(pick1, n1[i], n0[i]) for i in range(3)]
    l01 = torch.where(pick1, l1, l0)
    pick2 = l2 > l01
    n = [torch.where(pick2, n2[i], best[i]) for i in range(3)]
    len2 = torch.where(pick2, l2, l01)
    cen = [mx / scale + mean[0], my / scale + mean[1], mz / scale + mean[2]]
    facing = n[0] * cen[0] + n[1] * cen[1] + n[2] * cen[2]
    n = [torch.where(facing > 0, -c, c) for c in n]
    trace = cxx + cyy + czz
    degenerate = len2 <= trace.pow(4) * 1e-10 + 1e-30
    inv = 1.0 / torch.sqrt(len2 + 1e-30)
    fb = [0.0, 0.0, 1.0]
    n = torch.stack([torch.where(degenerate, torch.tensor(fb[i]), n[i] * inv) for i in range(3)])
    if ds > 1:
        n = F.interpolate(n[None], size=(h, w), mode="bilinear", align_corners=False)[0]
    n = n / torch.sqrt((n * n).sum(0, keepdim=True) + 1e-12)
    return n.permute(1, 2, 0)


def plane_fit_fixture():
    h, w = 18, 24
    fx, fy, cx, cy = 20.0, 21.0, 12.0, 9.0
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
    depth = 2.0 + 0.3 * torch.sin(u / 4.0) + 0.2 * torch.cos(v / 5.0) + 0.01 * u
    cases = []
    for kernel, ds in [(5, 1), (3, 3), (7, 2)]:
        d = depth.clone().requires_grad_(True)
        n = depth_to_normals(d, fx, fy, cx, cy, kernel, ds)
        g = torch.randn_like(n)
        (n * g).sum().backward()
        cases.append({"kernel": kernel, "downsample": ds, "normals": flat(n), "g": flat(g), "grad_depth": flat(d.grad)})
    return {"height": h, "width": w, "fx": fx, "fy": fy, "cx": cx, "cy": cy, "depth": flat(depth), "cases": cases}


def main():
    fixture = {
        "generator": "tools/nerf_parity/make_fixtures.py, torch " + torch.__version__,
        "volume": volume_fixture(),
        "hash": hash_fixture(),
        "plane_fit": plane_fit_fixture(),
    }
    os.makedirs(os.path.dirname(OUT), exist_ok=True)
    with open(OUT, "w") as f:
        json.dump(fixture, f)
    print("wrote", OUT, os.path.getsize(OUT), "bytes")


if __name__ == "__main__":
    main()
