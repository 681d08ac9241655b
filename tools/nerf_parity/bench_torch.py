"""Plain-PyTorch reference (CPU, or CUDA with --device cuda) for `cargo xtask bench nerf`: the same hash-grid field,
stratified samples and volume rendering as gb-nerf, one Adam step per iteration on random
rays in a unit box. Prints one JSON line: {"steps_per_s": ..., "rays_per_s": ...}.

Pinned: torch==2.15.0 (tools/bench/requirements.txt; tools/bench/make_venv.sh). Usage:
    python tools/nerf_parity/bench_torch.py --config CONFIG.json --steps 10 [--device cuda]
CONFIG.json: {"levels", "features_per_level", "log2_table_size", "base_resolution",
"max_resolution", "hidden", "geo_features", "dir_freqs", "samples_per_ray", "rays_per_batch"}
"""

import argparse
import json
import math
import time

import numpy as np
import torch


def lookups(x, levels, log2_t, base, max_res):
    T = 1 << log2_t
    b = np.exp((np.log(max_res) - np.log(base)) / max(levels - 1, 1))
    rows, weights = [], []
    for l in range(levels):
        scale = base * b ** l - 1.0
        res = int(math.ceil(scale)) + 1
        pos = x * scale + 0.5
        g = torch.floor(pos)
        f = pos - g
        g = g.long()
        for c in range(8):
            bits = torch.tensor([(c >> i) & 1 for i in range(3)], device=x.device)
            w = torch.prod(torch.where(bits.bool(), f, 1.0 - f), 1)
            gc = g + bits
            if res ** 3 <= T:
                idx = (gc[:, 0] + gc[:, 1] * res + gc[:, 2] * res * res) % T
            else:
                m = 0xFFFFFFFF
                idx = ((gc[:, 0] ^ ((gc[:, 1] * 2654435761) & m) ^ ((gc[:, 2] * 805459861) & m)) & m) % T
            rows.append(l * T + idx)
            weights.append(w)
    return torch.stack(rows, 1), torch.stack(weights, 1)


def posenc(x, n):
    out = [x]
    for k in range(n):
        out += [torch.sin(math.pi * 2 ** k * x), torch.cos(math.pi * 2 ** k * x)]
    return torch.cat(out, 1)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--config", required=True)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--device", default="cpu")
    a = ap.parse_args()
    c = json.load(open(a.config))
    torch.manual_seed(0)
    dev = torch.device(a.device)
    torch.set_default_device(dev)
    L, Fd = c["levels"], c["features_per_level"]
    table = torch.nn.Parameter(torch.rand(L << c["log2_table_size"], Fd) * 2e-4 - 1e-4)
    H, G = c["hidden"], c["geo_features"]
    dens = torch.nn.Sequential(torch.nn.Linear(L * Fd, H), torch.nn.ReLU(), torch.nn.Linear(H, 1 + G))
    dd = 3 + 6 * c["dir_freqs"]
    col = torch.nn.Sequential(torch.nn.Linear(G + dd, H), torch.nn.ReLU(), torch.nn.Linear(H, H), torch.nn.ReLU(), torch.nn.Linear(H, 3))
    opt = torch.optim.Adam([table, *dens.parameters(), *col.parameters()], lr=1e-2, eps=1e-15)
    R, S = c["rays_per_batch"], c["samples_per_ray"]

    def step():
        o = torch.rand(R, 3)
        d = torch.nn.functional.normalize(torch.randn(R, 3), dim=1)
        t = (torch.arange(S) + torch.rand(R, S)) / S
        delta = torch.full((R, S), 1.0 / S)
        pts = (o[:, None] + t[..., None] * d[:, None]).reshape(-1, 3).clamp(0, 1)
        rows, w = lookups(pts, L, c["log2_table_size"], c["base_resolution"], c["max_resolution"])
        enc = (table[rows.reshape(-1)].reshape(-1, L, 8, Fd) * w.reshape(-1, L, 8, 1)).sum(2).reshape(-1, L * Fd)
        h = dens(enc)
        sigma = torch.exp(h[:, 0].clamp(-15, 15)).reshape(R, S)
        dirs = d[:, None].expand(R, S, 3).reshape(-1, 3)
        rgb = torch.sigmoid(col(torch.cat([h[:, 1:], posenc(dirs, c["dir_freqs"])], 1))).reshape(R, S, 3)
        tau = sigma * delta
        trans = torch.exp(-torch.cumsum(torch.cat([torch.zeros(R, 1), tau[:, :-1]], 1), 1))
        wts = trans * (1 - torch.exp(-tau))
        color = (wts[..., None] * rgb).sum(1)
        loss = ((color - 0.5) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()

    def sync():
        if dev.type == "cuda":
            torch.cuda.synchronize()

    for _ in range(2):
        step()
    sync()
    t0 = time.perf_counter()
    for _ in range(a.steps):
        step()
    sync()
    dt = time.perf_counter() - t0
    out = {"steps_per_s": a.steps / dt, "rays_per_s": a.steps * R / dt,
           "threads": torch.get_num_threads(), "torch": torch.__version__, "device": a.device}
    if dev.type == "cuda":
        out["gpu"] = torch.cuda.get_device_name(0)
        out["peak_gpu_mb"] = torch.cuda.max_memory_allocated() / 2**20
    print(json.dumps(out))


if __name__ == "__main__":
    main()
