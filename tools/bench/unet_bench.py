#!/usr/bin/env python3
"""diffusers reference timings for `cargo xtask bench unet` (run by it, same machine, same run).

Pinned: torch==2.15.0, diffusers==0.42.1 (tools/bench/requirements.txt; tools/bench/make_venv.sh).
Prints one JSON object on stdout: U-Net forward seconds and peak RSS at the real
SD-1.5-inpainting size (random weights) for the requested latent size and batch, and the
VAE encoder forward+backward seconds at the requested image sizes.

    python tools/bench/unet_bench.py --latent 32 --batch 2 --vae-sizes 256 --threads 2 --repeats 2
    python tools/bench/unet_bench.py --latent 64 --vae-sizes 512 --device cuda --fp16   # bench gpu
"""
import argparse
import json
import resource
import time

import torch
from diffusers import AutoencoderKL, UNet2DConditionModel

# stable-diffusion-v1-5/stable-diffusion-inpainting unet/config.json and vae/config.json (shape fields).
SD15_INPAINT_UNET = dict(in_channels=9, out_channels=4, sample_size=64, layers_per_block=2,
                         block_out_channels=(320, 640, 1280, 1280), cross_attention_dim=768,
                         attention_head_dim=8, norm_num_groups=32,
                         down_block_types=("CrossAttnDownBlock2D",) * 3 + ("DownBlock2D",),
                         up_block_types=("UpBlock2D",) + ("CrossAttnUpBlock2D",) * 3)
SD15_VAE = dict(in_channels=3, out_channels=3, latent_channels=4, layers_per_block=2,
                block_out_channels=(128, 256, 512, 512), norm_num_groups=32,
                down_block_types=("DownEncoderBlock2D",) * 4, up_block_types=("UpDecoderBlock2D",) * 4)


def peak_rss_mb():
    # VmHWM of this process's own address space. ru_maxrss is not used: Linux carries the
    # parent's peak over fork+exec, so under `cargo xtask bench unet` it reported the Rust
    # side's peak instead of ours.
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def time_forward(unet, x, t, ehs, dev, repeats):
    """Fastest of `repeats` U-Net forwards after one warm-up (synchronised on CUDA)."""
    times = []
    with torch.no_grad():
        for _ in range(repeats + 1):
            if dev.type == "cuda":
                torch.cuda.synchronize()
            s = time.perf_counter()
            unet(x, t, encoder_hidden_states=ehs)
            if dev.type == "cuda":
                torch.cuda.synchronize()
            times.append(time.perf_counter() - s)
    return min(times[1:])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--latent", type=int, default=32)
    ap.add_argument("--batch", type=int, default=2)
    ap.add_argument("--vae-sizes", type=int, nargs="*", default=[256])
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--fp16", action="store_true", help="also time the U-Net in float16 (GPU)")
    a = ap.parse_args()
    torch.set_num_threads(a.threads)
    torch.manual_seed(0)
    dev = torch.device(a.device)
    out = {"torch": torch.__version__, "device": a.device, "threads": a.threads}

    unet = UNet2DConditionModel(**SD15_INPAINT_UNET).to(dev).eval()
    x = torch.randn(a.batch, 9, a.latent, a.latent, device=dev)
    ehs = torch.randn(a.batch, 77, 768, device=dev)
    t = torch.tensor([500.0] * a.batch, device=dev)
    out["unet_forward_s"] = time_forward(unet, x, t, ehs, dev, a.repeats)
    out["unet_params"] = sum(p.numel() for p in unet.parameters())
    if a.fp16:
        out["unet_forward_fp16_s"] = time_forward(unet.half(), x.half(), t.half(), ehs.half(), dev, a.repeats)
    out["unet_peak_rss_mb"] = peak_rss_mb()
    if dev.type == "cuda":
        out["unet_peak_gpu_mb"] = torch.cuda.max_memory_allocated() / 2**20
    del unet

    vae = AutoencoderKL(**SD15_VAE).to(dev)
    for p in vae.parameters():
        p.requires_grad_(False)
    out["vae_encoder_fwd_bwd_s"] = {}
    for size in a.vae_sizes:
        times = []
        for _ in range(a.repeats + 1):
            img = torch.rand(1, 3, size, size, device=dev, requires_grad=True)
            s = time.perf_counter()
            mean = vae.encode(img * 2 - 1).latent_dist.mean
            mean.sum().backward()
            if dev.type == "cuda":
                torch.cuda.synchronize()
            times.append(time.perf_counter() - s)
        out["vae_encoder_fwd_bwd_s"][str(size)] = min(times[1:])
    out["peak_rss_mb"] = peak_rss_mb()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
