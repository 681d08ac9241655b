#!/usr/bin/env python3
"""Proves that the shipped tiny prior (assets/tiny-prior) is an ordinary diffusers checkpoint.

diffusers loads assets/tiny-prior as a StableDiffusionInpaintPipeline, runs its text encoder
and 9-channel inpainting U-Net on fixed inputs, then loads the folder's pytorch_lora_weights.safetensors
with `load_lora_weights` and runs them again. The inputs and the four outputs are written to
crates/gb-diffusion/tests/fixtures/tiny_prior_io.safetensors; the Rust test
crates/gb-diffusion/tests/tiny_prior_parity.rs loads the same folder (and LoRA) with our code
and compares.

Pinned: torch 2.15.0, diffusers 0.42.1, transformers 5.23.0, peft (tools/requirements.txt).
Run: /work/pyref/bin/python tools/parity/check_tiny_prior.py
"""
import pathlib

import torch
from safetensors.torch import save_file
from diffusers import StableDiffusionInpaintPipeline

ROOT = pathlib.Path(__file__).resolve().parents[2]
PRIOR = ROOT / "assets" / "tiny-prior"
OUT = ROOT / "crates/gb-diffusion/tests/fixtures/tiny_prior_io.safetensors"
PROMPTS = ["normal map, a wooden staircase in front of a brick wall", "RGB image"]


def main():
    torch.manual_seed(0)
    pipe = StableDiffusionInpaintPipeline.from_pretrained(
        PRIOR, safety_checker=None, requires_safety_checker=False
    )
    unet, te, tok = pipe.unet, pipe.text_encoder, pipe.tokenizer
    size = unet.config.sample_size
    ids = tok(PROMPTS, padding="max_length", max_length=77, truncation=True, return_tensors="pt").input_ids
    x = torch.randn(2, unet.config.in_channels, size, size)
    t = torch.tensor([700, 80])
    with torch.no_grad():
        ctx = te(ids)[0]
        eps = unet(x, t, ctx).sample
    pipe.load_lora_weights(PRIOR, weight_name="pytorch_lora_weights.safetensors")
    with torch.no_grad():
        ctx_lora = te(ids)[0]
        eps_lora = unet(x, t, ctx_lora).sample
    print("LoRA changes eps by", (eps - eps_lora).abs().max().item())
    save_file(
        {
            "input_ids": ids.to(torch.int64).contiguous(),
            "sample": x.contiguous(),
            "timesteps": t.to(torch.float32).contiguous(),
            "context": ctx.contiguous(),
            "eps": eps.contiguous(),
            "context_lora": ctx_lora.contiguous(),
            "eps_lora": eps_lora.contiguous(),
        },
        OUT,
    )
    print("wrote", OUT)


if __name__ == "__main__":
    main()
