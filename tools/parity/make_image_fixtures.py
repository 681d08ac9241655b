#!/usr/bin/env python3
"""Parity fixtures for the image half of the Stable Diffusion stack (gb-diffusion).

Pinned reference versions (see tools/requirements.txt):
    torch==2.15.0  diffusers==0.42.1  transformers==5.23.0  safetensors

Writes, under crates/gb-diffusion/tests/fixtures/sd_image/ (a few hundred KB in total):

* ``pipeline/unet/``  (parity fixture ``unet_sd15_io``) a tiny SD-1.5-inpainting-shaped UNet2DConditionModel (9 input
  channels, cross-attention at two resolution levels, conv proj_in/proj_out, heads as an int)
* ``unet_sd2/unet/``   a tiny SD-2-style one (use_linear_projection, attention_head_dim as a
  list, flip_sin_to_cos = False and freq_shift = 1 to exercise those config paths)
* ``vae/vae/``         a tiny AutoencoderKL with the current attention key names
* ``vae_old/vae/``     the same weights saved under the old (query/key/value/proj_attn) names
* ``pipeline/``        a complete tiny diffusers inpainting folder (tokenizer with a small
  byte-level CLIP-style vocabulary, CLIP text encoder, the sd15 U-Net, a VAE, DDIM scheduler)
* ``*_io.safetensors`` inputs and diffusers' outputs for each component
  (unet: sample, timestep, encoder_hidden_states -> out; vae-encode: image -> mean (unscaled);
  vae-decode: latents -> image), ``scheduler_io.safetensors`` for DDIM, and
  ``pipeline_io.safetensors`` with a full 3-step inpainting run.

Every parameter is overwritten with randn * 0.2 (diffusers zero-initialises some layers,
which would leave half the network untested).

Run from the repository root:  /work/pyref/bin/python tools/parity/make_image_fixtures.py
"""
import json
import os
import shutil

import numpy as np
import torch
from safetensors.torch import save_file, load_file

import diffusers
from diffusers import (
    AutoencoderKL,
    DDIMScheduler,
    StableDiffusionInpaintPipeline,
    UNet2DConditionModel,
)
from transformers import CLIPTextConfig, CLIPTextModel, CLIPTokenizer

assert torch.__version__.startswith("2.15.0"), torch.__version__
assert diffusers.__version__ == "0.42.1", diffusers.__version__

OUT = os.path.join("crates", "gb-diffusion", "tests", "fixtures", "sd_image")


def randomize(model, seed):
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for _, p in sorted(model.named_parameters()):
            p.copy_(torch.randn(p.shape, generator=g) * 0.2)
    return model


def fresh(path):
    if os.path.isdir(path):
        shutil.rmtree(path)
    os.makedirs(path)


def save_io(name, tensors):
    save_file({k: v.contiguous() for k, v in tensors.items()}, os.path.join(OUT, name))


SD15_UNET = dict(
    sample_size=8,
    in_channels=9,
    out_channels=4,
    layers_per_block=2,
    block_out_channels=(8, 16, 16),
    down_block_types=("CrossAttnDownBlock2D", "CrossAttnDownBlock2D", "DownBlock2D"),
    up_block_types=("UpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D"),
    cross_attention_dim=16,
    attention_head_dim=2,
    norm_num_groups=4,
    flip_sin_to_cos=True,
    freq_shift=0,
)

SD2_UNET = dict(
    sample_size=8,
    in_channels=4,
    out_channels=4,
    layers_per_block=1,
    block_out_channels=(8, 16, 32),
    down_block_types=("CrossAttnDownBlock2D", "CrossAttnDownBlock2D", "DownBlock2D"),
    up_block_types=("UpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D"),
    cross_attention_dim=12,
    attention_head_dim=[2, 4, 4],
    use_linear_projection=True,
    upcast_attention=True,
    norm_num_groups=4,
    flip_sin_to_cos=False,
    freq_shift=1,
)

TINY_VAE = dict(
    in_channels=3,
    out_channels=3,
    down_block_types=("DownEncoderBlock2D",) * 3,
    up_block_types=("UpDecoderBlock2D",) * 3,
    block_out_channels=(8, 16, 16),
    layers_per_block=1,
    latent_channels=4,
    norm_num_groups=4,
    sample_size=16,
    scaling_factor=0.18215,
)


def unet_fixture(name, cfg, seed):
    torch.manual_seed(seed)
    unet = randomize(UNet2DConditionModel(**cfg), seed).eval()
    folder = os.path.join(OUT, name, "unet")
    fresh(os.path.join(OUT, name))
    unet.save_pretrained(folder, safe_serialization=True)
    g = torch.Generator().manual_seed(seed + 1)
    sample = torch.randn(2, cfg["in_channels"], 8, 8, generator=g)
    timestep = torch.tensor([999.0, 37.0])
    ehs = torch.randn(2, 5, cfg["cross_attention_dim"], generator=g)
    with torch.no_grad():
        out = unet(sample, timestep, encoder_hidden_states=ehs).sample
    save_io(f"{name}_io.safetensors", dict(sample=sample, timestep=timestep, encoder_hidden_states=ehs, out=out))
    print(name, "params", sum(p.numel() for p in unet.parameters()), "out absmax", out.abs().max().item())
    return unet


OLD_ATTN_NAMES = {"to_q": "query", "to_k": "key", "to_v": "value", "to_out.0": "proj_attn"}


def vae_fixture(seed):
    vae = randomize(AutoencoderKL(**TINY_VAE), seed).eval()
    fresh(os.path.join(OUT, "vae"))
    vae.save_pretrained(os.path.join(OUT, "vae", "vae"), safe_serialization=True)
    # The same weights under the old attention names (diffusers < 0.14 checkpoints).
    fresh(os.path.join(OUT, "vae_old", "vae"))
    state = load_file(os.path.join(OUT, "vae", "vae", "diffusion_pytorch_model.safetensors"))
    old = {}
    for k, v in state.items():
        for new, o in OLD_ATTN_NAMES.items():
            marker = f".attentions.0.{new}."
            if marker in k:
                k = k.replace(marker, f".attentions.0.{o}.")
        old[k] = v
    assert any(".query." in k for k in old)
    save_file(old, os.path.join(OUT, "vae_old", "vae", "diffusion_pytorch_model.safetensors"))
    shutil.copy(os.path.join(OUT, "vae", "vae", "config.json"), os.path.join(OUT, "vae_old", "vae", "config.json"))
    # diffusers itself must read the old names back to the same model.
    reloaded = AutoencoderKL.from_pretrained(os.path.join(OUT, "vae_old", "vae")).eval()

    g = torch.Generator().manual_seed(seed + 1)
    image = torch.rand(2, 3, 16, 16, generator=g) * 2 - 1
    latents = torch.randn(2, 4, 4, 4, generator=g)
    with torch.no_grad():
        mean = vae.encode(image).latent_dist.mean
        decoded = vae.decode(latents).sample
        assert torch.allclose(reloaded.encode(image).latent_dist.mean, mean, atol=1e-6)
    save_io("vae_encode_io.safetensors", dict(image=image, mean=mean))
    save_io("vae_decode_io.safetensors", dict(latents=latents, image=decoded))
    print("vae params", sum(p.numel() for p in vae.parameters()), "mean absmax", mean.abs().max().item(),
          "decoded absmax", decoded.abs().max().item())
    return vae


def scheduler_fixture():
    # SD-1.5's scheduler config (stable-diffusion-v1-5/stable-diffusion-inpainting, scheduler_config.json).
    cfg = dict(num_train_timesteps=1000, beta_start=0.00085, beta_end=0.012, beta_schedule="scaled_linear",
               clip_sample=False, set_alpha_to_one=False, steps_offset=1, prediction_type="epsilon")
    out = {}
    g = torch.Generator().manual_seed(7)
    x = torch.randn(1, 4, 4, 4, generator=g)
    model_out = torch.randn(1, 4, 4, 4, generator=g)
    noise = torch.randn(1, 4, 4, 4, generator=g)
    for pred in ("epsilon", "v_prediction"):
        s = DDIMScheduler(**{**cfg, "prediction_type": pred})
        s.set_timesteps(50)
        out["alphas_cumprod"] = s.alphas_cumprod.clone()
        out["timesteps_50"] = s.timesteps.clone().to(torch.int64)
        for t in (int(s.timesteps[0]), int(s.timesteps[25]), int(s.timesteps[-1])):
            out[f"step_{pred}_{t}"] = s.step(model_out, t, x, eta=0.0).prev_sample
    s = DDIMScheduler(**cfg)
    s.set_timesteps(7)
    out["timesteps_7"] = s.timesteps.clone().to(torch.int64)
    for spacing in ("trailing", "linspace"):
        sp = DDIMScheduler(**{**cfg, "timestep_spacing": spacing})
        sp.set_timesteps(7)
        out[f"timesteps_7_{spacing}"] = sp.timesteps.clone().to(torch.int64)
    ts = torch.tensor([1, 500, 999])
    out["add_noise_timesteps"] = ts
    out["add_noise"] = s.add_noise(x.repeat(3, 1, 1, 1), noise.repeat(3, 1, 1, 1), ts)
    out["x"], out["model_output"], out["noise"] = x, model_out, noise
    save_io("scheduler_io.safetensors", out)
    with open(os.path.join(OUT, "scheduler_config.json"), "w") as f:
        json.dump(s.config, f, indent=2, default=list)


def bytes_to_unicode():
    bs = list(range(ord("!"), ord("~") + 1)) + list(range(ord("¡"), ord("¬") + 1)) + list(range(ord("®"), ord("ÿ") + 1))
    cs = bs[:]
    n = 0
    for b in range(2**8):
        if b not in bs:
            bs.append(b)
            cs.append(2**8 + n)
            n += 1
    return [chr(c) for c in cs]


def tiny_tokenizer(folder):
    """A CLIP-style byte-level BPE vocabulary with a handful of merges (the real one is 1.6 MB)."""
    os.makedirs(folder)
    chars = bytes_to_unicode()
    vocab_list = chars + [c + "</w>" for c in chars]
    merges = [("r", "e"), ("m", "o"), ("v", "e</w>"), ("mo", "ve</w>"), ("t", "h"), ("th", "e</w>"),
              ("s", "t"), ("st", "a"), ("i", "r"), ("ir", "s</w>"), ("sta", "irs</w>"), ("o", "b")]
    for a, b in merges:
        vocab_list.append(a + b)
    vocab_list += ["<|startoftext|>", "<|endoftext|>"]
    vocab = {t: i for i, t in enumerate(vocab_list)}
    with open(os.path.join(folder, "vocab.json"), "w") as f:
        json.dump(vocab, f)
    with open(os.path.join(folder, "merges.txt"), "w") as f:
        f.write("#version: 0.2\n" + "\n".join(f"{a} {b}" for a, b in merges) + "\n")
    with open(os.path.join(folder, "special_tokens_map.json"), "w") as f:
        json.dump({"bos_token": "<|startoftext|>", "eos_token": "<|endoftext|>",
                   "pad_token": "<|endoftext|>", "unk_token": "<|endoftext|>"}, f, indent=2)
    with open(os.path.join(folder, "tokenizer_config.json"), "w") as f:
        json.dump({"tokenizer_class": "CLIPTokenizer", "model_max_length": 77, "do_lower_case": True,
                   "bos_token": "<|startoftext|>", "eos_token": "<|endoftext|>",
                   "pad_token": "<|endoftext|>", "unk_token": "<|endoftext|>",
                   "errors": "replace", "add_prefix_space": False}, f, indent=2)
    return len(vocab)


def pipeline_fixture(unet, seed):
    root = os.path.join(OUT, "pipeline")
    fresh(root)
    vocab_size = tiny_tokenizer(os.path.join(root, "tokenizer"))
    tcfg = CLIPTextConfig(vocab_size=vocab_size, hidden_size=16, intermediate_size=32, num_hidden_layers=2,
                          num_attention_heads=2, max_position_embeddings=77, hidden_act="quick_gelu",
                          projection_dim=16, bos_token_id=vocab_size - 2, eos_token_id=vocab_size - 1,
                          pad_token_id=vocab_size - 1)
    torch.manual_seed(seed)
    text_encoder = randomize(CLIPTextModel(tcfg), seed).eval()
    text_encoder.save_pretrained(os.path.join(root, "text_encoder"), safe_serialization=True)
    unet.save_pretrained(os.path.join(root, "unet"), safe_serialization=True)
    vae = randomize(AutoencoderKL(**TINY_VAE), seed + 1).eval()
    vae.save_pretrained(os.path.join(root, "vae"), safe_serialization=True)
    sched = DDIMScheduler(num_train_timesteps=1000, beta_start=0.00085, beta_end=0.012,
                          beta_schedule="scaled_linear", clip_sample=False, set_alpha_to_one=False,
                          steps_offset=1, prediction_type="epsilon")
    tokenizer = CLIPTokenizer.from_pretrained(os.path.join(root, "tokenizer"))
    pipe = StableDiffusionInpaintPipeline(vae=vae, text_encoder=text_encoder, tokenizer=tokenizer, unet=unet,
                                          scheduler=sched, safety_checker=None, feature_extractor=None,
                                          requires_safety_checker=False)
    pipe.save_pretrained(root, safe_serialization=True)
    # Stable Diffusion repositories ship only vocab.json + merges.txt; so do we.
    os.remove(os.path.join(root, "tokenizer", "tokenizer.json"))

    # 32x32 RGB image and mask PNGs, and a fixed initial noise, so that Rust can replay the run.
    from PIL import Image
    g = torch.Generator().manual_seed(seed + 2)
    img = (torch.rand(32, 32, 3, generator=g) * 255).round().to(torch.uint8).numpy()
    yy, xx = np.mgrid[0:32, 0:32]
    mask = (((yy - 14) ** 2 + (xx - 17) ** 2) < 80).astype(np.uint8) * 255
    Image.fromarray(img).save(os.path.join(OUT, "pipeline_image.png"))
    Image.fromarray(mask).save(os.path.join(OUT, "pipeline_mask.png"))
    vsf = pipe.vae_scale_factor
    latents = torch.randn(1, 4, 32 // vsf, 32 // vsf, generator=g)
    # The pipeline samples the masked-image latent distribution; we give it the mean (what the
    # Rust sampler uses), computed exactly as the pipeline preprocesses image and mask.
    image_t = pipe.image_processor.preprocess(Image.fromarray(img), height=32, width=32)
    mask_t = pipe.mask_processor.preprocess(Image.fromarray(mask), height=32, width=32)
    masked = image_t * (mask_t < 0.5)
    with torch.no_grad():
        mil = vae.encode(masked).latent_dist.mean * vae.config.scaling_factor
        result = pipe(prompt="remove the stairs", negative_prompt="ob", image=Image.fromarray(img),
                      mask_image=Image.fromarray(mask), masked_image_latents=mil, height=32, width=32,
                      num_inference_steps=3, guidance_scale=7.5, latents=latents, output_type="pt").images
    save_io("pipeline_io.safetensors", dict(latents=latents, masked_image_latents=mil, image=result))
    print("pipeline image", tuple(result.shape), "min/max", result.min().item(), result.max().item())


def main():
    os.makedirs(OUT, exist_ok=True)
    unet = unet_fixture("unet_sd15", SD15_UNET, 1)
    unet_fixture("unet_sd2", SD2_UNET, 2)
    vae_fixture(3)
    scheduler_fixture()
    pipeline_fixture(unet, 4)
    # The SD-1.5-shaped U-Net lives in pipeline/unet (same weights); do not commit it twice.
    shutil.rmtree(os.path.join(OUT, "unet_sd15"))
    total = 0
    for d, _, files in os.walk(OUT):
        total += sum(os.path.getsize(os.path.join(d, f)) for f in files)
    print(f"fixtures: {total / 1e6:.2f} MB in {OUT}")


if __name__ == "__main__":
    main()
