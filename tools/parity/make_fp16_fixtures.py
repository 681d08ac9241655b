#!/usr/bin/env python3
"""Half-precision parity fixtures: diffusers / transformers in fp16 on the committed f32
fixture models and inputs (gb-diffusion's `--precision f16`).

Pinned reference versions (see tools/requirements.txt):
    torch==2.15.0  diffusers==0.42.1  transformers==5.23.0  safetensors

Reads the models and inputs that make_image_fixtures.py and make_text_fixtures.py wrote, loads
each network with ``torch_dtype=torch.float16`` on the CPU, and writes
crates/gb-diffusion/tests/fixtures/fp16/fp16_io.safetensors (outputs stored as f32):

* ``unet_out``            the sd15-inpainting-shaped U-Net (sd_image/pipeline/unet) on
                          unet_sd15_io's sample, timestep and encoder_hidden_states
* ``vae_mean``            the VAE (sd_image/vae/vae) encoder's latent mean of vae_encode_io's image
* ``vae_image``           its decoder on vae_decode_io's latents
* ``clip_last_hidden_state``  the quick-GELU CLIP (sd_text/clip_quick) on text_io's input_ids
* the extremes: ``extreme_sample`` (unet_sd15_io's sample times ``EXTREME_SCALE``, so that the
  U-Net's activations reach about 1e4), ``extreme_timestep`` (t = 0.98 and 0.02 of the
  1000 training steps), and the U-Net's output on them in fp32 (``extreme_out_f32``) and fp16
  (``extreme_out_fp16``); ``extreme_activation_absmax`` is the largest activation fp32 saw.

Run from the repository root:  /work/pyref/bin/python tools/parity/make_fp16_fixtures.py
"""
import os

import torch
from safetensors.torch import load_file, save_file

import diffusers
import transformers
from diffusers import AutoencoderKL, UNet2DConditionModel
from transformers import CLIPTextModel

assert torch.__version__.startswith("2.15.0"), torch.__version__
assert diffusers.__version__ == "0.42.1", diffusers.__version__
assert transformers.__version__ == "5.23.0", transformers.__version__

FIX = os.path.join("crates", "gb-diffusion", "tests", "fixtures")
OUT = os.path.join(FIX, "fp16")
EXTREME_SCALE = 300.0


def f32(t):
    return t.detach().float().contiguous()


def unet_outputs(io):
    out = {}
    for dtype, tag in [(torch.float32, "f32"), (torch.float16, "fp16")]:
        unet = UNet2DConditionModel.from_pretrained(
            os.path.join(FIX, "sd_image", "pipeline", "unet"), torch_dtype=dtype
        ).eval()
        ehs = io["encoder_hidden_states"].to(dtype)
        with torch.no_grad():
            if dtype == torch.float16:
                out["unet_out"] = f32(unet(io["sample"].to(dtype), io["timestep"], encoder_hidden_states=ehs).sample)
            sample = (io["sample"] * EXTREME_SCALE).to(dtype)
            t = torch.tensor([980.0, 20.0])
            absmax = []
            hooks = [
                m.register_forward_hook(lambda _m, _i, o: absmax.append(o.float().abs().max().item()))
                for m in unet.modules()
                if isinstance(m, torch.nn.Conv2d)
            ]
            res = unet(sample, t, encoder_hidden_states=ehs).sample
            for h in hooks:
                h.remove()
        out[f"extreme_out_{tag}"] = f32(res)
        if dtype == torch.float32:
            out["extreme_activation_absmax"] = torch.tensor([max(absmax)])
        print(f"unet {tag}: extreme output absmax {res.float().abs().max().item():.4g}, "
              f"finite {bool(torch.isfinite(res).all())}, largest conv activation {max(absmax):.4g}")
    out["extreme_sample"] = f32(io["sample"] * EXTREME_SCALE)
    out["extreme_timestep"] = torch.tensor([980.0, 20.0])
    return out


def main():
    torch.manual_seed(0)
    unet_io = load_file(os.path.join(FIX, "sd_image", "unet_sd15_io.safetensors"))
    enc_io = load_file(os.path.join(FIX, "sd_image", "vae_encode_io.safetensors"))
    dec_io = load_file(os.path.join(FIX, "sd_image", "vae_decode_io.safetensors"))
    text_io = load_file(os.path.join(FIX, "sd_text", "text_io.safetensors"))

    out = unet_outputs(unet_io)
    vae = AutoencoderKL.from_pretrained(os.path.join(FIX, "sd_image", "vae", "vae"), torch_dtype=torch.float16).eval()
    clip = CLIPTextModel.from_pretrained(
        os.path.join(FIX, "sd_text", "clip_quick", "text_encoder"), torch_dtype=torch.float16
    ).eval()
    with torch.no_grad():
        out["vae_mean"] = f32(vae.encode(enc_io["image"].half()).latent_dist.mean)
        out["vae_image"] = f32(vae.decode(dec_io["latents"].half()).sample)
        out["clip_last_hidden_state"] = f32(clip(text_io["input_ids"]).last_hidden_state)
    ref = {
        "unet_out": unet_io["out"],
        "vae_mean": enc_io["mean"],
        "vae_image": dec_io["image"],
        "clip_last_hidden_state": text_io["last_hidden_state_quick"],
    }
    for k, r in ref.items():
        err = (out[k] - r).abs().max().item()
        print(f"{k}: fp16 vs fp32 max abs {err:.3e} (fp32 absmax {r.abs().max().item():.3g})")
    os.makedirs(OUT, exist_ok=True)
    save_file(out, os.path.join(OUT, "fp16_io.safetensors"))


if __name__ == "__main__":
    main()
