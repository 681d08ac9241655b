#!/usr/bin/env python3
"""Parity fixtures for the text side of gb-diffusion (tokenizer, CLIP text encoder, LoRA).

Pinned reference versions (see tools/requirements.txt):
    torch==2.15.0  transformers==5.23.0  diffusers==0.42.1  peft==0.21.2
    safetensors==0.8.0  open_clip_torch==3.3.0 (source of the real CLIP BPE vocabulary)

Writes into crates/gb-diffusion/tests/fixtures/sd_text/:
  tokenizer/                vocab.json + merges.txt (real CLIP vocab, as CLIPTokenizer saves
                            them) + tokenizer_config.json / special_tokens_map.json (SD 1.5)
  tokenizer_expected.json   prompts and transformers' CLIPTokenizer ids (padding="max_length",
                            truncation=True, max_length=77) for the SD 1.5 config and for the
                            SD 2 config (pad_token "!")
  clip_quick/               diffusers layout: model_index.json, text_encoder/{config.json,
                            model.safetensors} (tiny random CLIPTextModel, quick_gelu)
  clip_gelu/                same with hidden_act="gelu"
  clip_fp16/                text_encoder/model.fp16.safetensors only (the fp16 variant)
  text_io.safetensors       input_ids [2, 16] (i64) and last_hidden_state_{quick,gelu,fp16}
  lora/pytorch_lora_weights.safetensors   PEFT LoRA (r=4, alpha=8) on q/k/v/out_proj,
                            written by diffusers' save_lora_weights with adapter metadata
  lora/kohya_lora.safetensors            the same LoRA in kohya naming with `alpha`
  lora_io.safetensors       last_hidden_state_lora for clip_quick + the LoRA
  lora/unet_lora.safetensors  PEFT LoRA (r=2, alpha=3) on the sd-image fixture U-Net
                            (tests/fixtures/sd_image/pipeline/unet): to_q/to_k/to_v/to_out.0
                            and the 3x3 convs conv1 / conv_in; unet_lora_io.safetensors holds
                            its output `out_lora` on sd_image/unet_sd15_io.safetensors inputs
Run: /work/pyref/bin/python tools/parity/make_text_fixtures.py
Check LoRA files gb-diffusion wrote (tools/parity/README.md):
     /work/pyref/bin/python tools/parity/make_text_fixtures.py --check-exported /tmp/lora_export
"""
import gzip
import json
import os
import sys
from pathlib import Path

import torch
import transformers
import diffusers
import peft
import open_clip
from safetensors.torch import save_file, load_file
from transformers import CLIPTextConfig, CLIPTextModel, CLIPTokenizer
from diffusers import StableDiffusionPipeline
from peft import LoraConfig, get_peft_model_state_dict

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "crates/gb-diffusion/tests/fixtures/sd_text"

PROMPTS = [
    "a photo of a cat",
    "A PHOTO of a Dog, sitting on a bench!!! (high quality), 4k, 1024x768",
    "   leading   and trailing\tspaces\n\nand  newlines   ",
    "don't stop: it's the cat's toy; we'll see... they've gone, I'm here, you'd know",
    "café naïve résumé – Straße, ÆØÅ, e\u0301 (combining)",
    "東京の夜景, 서울, Москва, مرحبا, 🎨🖌️ emoji art 👩‍🎨",
    "price: $100.50 & 20% off @home #tag ~tilde~ `code` {braces} [brackets] <angle>",
    "",
    "an empty room with white walls, wooden floor, large window, soft daylight",
    " ".join(["a highly detailed photograph of a red brick building with many windows"] * 8),
    "<|startoftext|> special token text <|endoftext|> inside",
]


def bytes_to_unicode():
    bs = list(range(ord("!"), ord("~") + 1)) + list(range(ord("¡"), ord("¬") + 1)) + list(range(ord("®"), ord("ÿ") + 1))
    cs = bs[:]
    n = 0
    for b in range(2**8):
        if b not in bs:
            bs.append(b)
            cs.append(2**8 + n)
            n += 1
    return dict(zip(bs, [chr(n) for n in cs]))


def write_tokenizer(dir_: Path):
    """The real CLIP vocabulary, laid out like openai/clip-vit-large-patch14's files."""
    bpe = Path(open_clip.__file__).parent / "bpe_simple_vocab_16e6.txt.gz"
    merges = gzip.open(bpe).read().decode("utf-8").split("\n")
    merges = merges[1 : 49152 - 256 - 2 + 1]
    merges = [tuple(m.split()) for m in merges]
    vocab = list(bytes_to_unicode().values())
    vocab = vocab + [v + "</w>" for v in vocab]
    for m in merges:
        vocab.append("".join(m))
    vocab.extend(["<|startoftext|>", "<|endoftext|>"])
    dir_.mkdir(parents=True, exist_ok=True)
    with open(dir_ / "vocab.json", "w", encoding="utf-8") as f:
        json.dump({t: i for i, t in enumerate(vocab)}, f, ensure_ascii=False)
    with open(dir_ / "merges.txt", "w", encoding="utf-8") as f:
        f.write("#version: 0.2\n")
        for m in merges:
            f.write(" ".join(m) + "\n")
    tok = lambda s: {"__type": "AddedToken", "content": s, "lstrip": False, "normalized": True, "rstrip": False, "single_word": False}
    config = {
        "add_prefix_space": False,
        "bos_token": tok("<|startoftext|>"),
        "do_lower_case": True,
        "eos_token": tok("<|endoftext|>"),
        "errors": "replace",
        "model_max_length": 77,
        "pad_token": "<|endoftext|>",
        "tokenizer_class": "CLIPTokenizer",
        "unk_token": tok("<|endoftext|>"),
    }
    (dir_ / "tokenizer_config.json").write_text(json.dumps(config, indent=2))
    special = {"bos_token": tok("<|startoftext|>"), "eos_token": tok("<|endoftext|>"),
               "pad_token": "<|endoftext|>", "unk_token": tok("<|endoftext|>")}
    (dir_ / "special_tokens_map.json").write_text(json.dumps(special, indent=2))
    return config


def expected_ids(dir_: Path, **kwargs):
    t = CLIPTokenizer.from_pretrained(str(dir_), **kwargs)
    enc = t(PROMPTS, padding="max_length", max_length=t.model_max_length, truncation=True)
    return enc["input_ids"]


def randomize(model, gen):
    with torch.no_grad():
        for name, p in model.named_parameters():
            if "norm" in name and name.endswith("weight"):
                p.copy_(1.0 + 0.2 * torch.randn(p.shape, generator=gen))
            else:
                p.copy_(0.2 * torch.randn(p.shape, generator=gen))


def tiny_config(act):
    return CLIPTextConfig(
        vocab_size=1000, hidden_size=32, intermediate_size=64, num_hidden_layers=2,
        num_attention_heads=4, max_position_embeddings=77, hidden_act=act,
        bos_token_id=998, eos_token_id=999, pad_token_id=1, projection_dim=32,
    )


def write_model_index(dir_: Path):
    index = {"_class_name": "StableDiffusionInpaintPipeline", "_diffusers_version": diffusers.__version__,
             "text_encoder": ["transformers", "CLIPTextModel"], "tokenizer": ["transformers", "CLIPTokenizer"],
             "safety_checker": [None, None], "requires_safety_checker": False}
    (dir_ / "model_index.json").write_text(json.dumps(index, indent=2))


def kohya_from_peft(sd, alpha):
    out = {}
    for k, v in sd.items():
        assert k.startswith("text_encoder."), k
        stem = k[len("text_encoder."):]
        module, kind = stem.rsplit(".lora_", 1)
        name = "lora_te_" + module.replace(".", "_")
        out[name + (".lora_down.weight" if kind.startswith("A") else ".lora_up.weight")] = v.contiguous()
        out[name + ".alpha"] = torch.tensor(float(alpha))
    return out


def main():
    torch.manual_seed(0)
    gen = torch.Generator().manual_seed(1234)
    OUT.mkdir(parents=True, exist_ok=True)

    # --- tokenizer ---------------------------------------------------------------------
    write_tokenizer(OUT / "tokenizer")
    ids_sd1 = expected_ids(OUT / "tokenizer")
    ids_sd2 = expected_ids(OUT / "tokenizer", pad_token="!")
    (OUT / "tokenizer_expected.json").write_text(json.dumps(
        {"prompts": PROMPTS, "input_ids_sd15": ids_sd1, "input_ids_sd2_pad": ids_sd2}, ensure_ascii=False))

    # --- text encoders -----------------------------------------------------------------
    ids = torch.randint(0, 1000, (2, 16), generator=gen)
    ids[:, 0] = 998
    ids[0, 9] = 999
    ids[1, 15] = 999
    tensors = {"input_ids": ids.to(torch.int64)}
    models = {}
    for tag, act in [("quick", "quick_gelu"), ("gelu", "gelu")]:
        model = CLIPTextModel(tiny_config(act)).eval()
        randomize(model, gen)
        d = OUT / f"clip_{tag}"
        model.save_pretrained(str(d / "text_encoder"))
        write_model_index(d)
        with torch.no_grad():
            tensors[f"last_hidden_state_{tag}"] = model(input_ids=ids).last_hidden_state.contiguous()
        models[tag] = model

    half = CLIPTextModel(tiny_config("quick_gelu")).eval()
    half.load_state_dict(models["quick"].state_dict())
    half = half.half()
    d = OUT / "clip_fp16"
    half.save_pretrained(str(d / "text_encoder"), variant="fp16")
    write_model_index(d)
    with torch.no_grad():
        tensors["last_hidden_state_fp16"] = half.float()(input_ids=ids).last_hidden_state.contiguous()
    save_file(tensors, str(OUT / "text_io.safetensors"))

    # --- LoRA --------------------------------------------------------------------------
    base = CLIPTextModel.from_pretrained(str(OUT / "clip_quick/text_encoder")).eval()
    cfg = LoraConfig(r=4, lora_alpha=8, init_lora_weights=True,
                     target_modules=["q_proj", "k_proj", "v_proj", "out_proj"])
    base.add_adapter(cfg)
    with torch.no_grad():
        for name, p in base.named_parameters():
            if "lora_" in name:
                p.copy_(0.2 * torch.randn(p.shape, generator=gen))
        lora_out = base(input_ids=ids).last_hidden_state.contiguous()
    te_sd = get_peft_model_state_dict(base)
    (OUT / "lora").mkdir(exist_ok=True)
    metadata = base.peft_config["default"].to_dict()
    metadata.pop("base_model_name_or_path", None)  # no local paths in committed fixtures
    StableDiffusionPipeline.save_lora_weights(
        str(OUT / "lora"), text_encoder_lora_layers=te_sd, text_encoder_lora_adapter_metadata=metadata)
    saved = load_file(str(OUT / "lora/pytorch_lora_weights.safetensors"))
    save_file(kohya_from_peft(saved, 8.0), str(OUT / "lora/kohya_lora.safetensors"))
    save_file({"last_hidden_state_lora": lora_out}, str(OUT / "lora_io.safetensors"))

    # --- prove diffusers reads both files back to the same output -----------------------
    for name in ["pytorch_lora_weights.safetensors", "kohya_lora.safetensors"]:
        err = diffusers_lora_error(OUT / "lora" / name, OUT / "clip_quick", ids, lora_out)
        print(f"diffusers reload of {name}: max abs err {err:.3e}")
        assert err < 1e-5, name
    print("keys:", sorted(saved)[:4], "...", len(saved))
    unet_lora_fixture(gen)
    print("wrote", OUT)


def unet_lora_fixture(gen):
    """PEFT LoRA on the sd-image fixture's SD-1.5-inpainting U-Net (make_image_fixtures.py):
    attention to_q/to_k/to_v/to_out.0 (linear) and resnet conv1 + conv_in (3x3 conv)."""
    from diffusers import UNet2DConditionModel
    image = ROOT / "crates/gb-diffusion/tests/fixtures/sd_image"
    if not (image / "pipeline/unet").is_dir():
        print("sd_image fixtures absent: skipping the U-Net LoRA fixture")
        return
    io = load_file(str(image / "unet_sd15_io.safetensors"))
    unet = UNet2DConditionModel.from_pretrained(str(image / "pipeline/unet")).eval()
    cfg = LoraConfig(r=2, lora_alpha=3, init_lora_weights=True,
                     target_modules=["to_q", "to_k", "to_v", "to_out.0", "conv1", "conv_in"])
    unet.add_adapter(cfg)
    with torch.no_grad():
        for name, p in unet.named_parameters():
            if "lora_" in name:
                p.copy_(0.2 * torch.randn(p.shape, generator=gen))
        out = unet(io["sample"], io["timestep"], io["encoder_hidden_states"]).sample.contiguous()
    sd = get_peft_model_state_dict(unet)
    meta = unet.peft_config["default"].to_dict()
    meta.pop("base_model_name_or_path", None)
    tmp = OUT / "lora_unet_tmp"
    StableDiffusionPipeline.save_lora_weights(
        str(tmp), unet_lora_layers=sd, unet_lora_adapter_metadata=meta)
    os.replace(tmp / "pytorch_lora_weights.safetensors", OUT / "lora/unet_lora.safetensors")
    tmp.rmdir()
    save_file({"out_lora": out}, str(OUT / "unet_lora_io.safetensors"))
    err = diffusers_unet_lora_error(OUT / "lora/unet_lora.safetensors", image / "pipeline/unet", io, out)
    print(f"diffusers reload of unet_lora.safetensors: max abs err {err:.3e}; "
          f"{len(sd)} tensors, conv: {sum('conv' in k for k in sd)}")
    assert err < 1e-5


def diffusers_unet_lora_error(lora_file: Path, unet_dir: Path, io, expected) -> float:
    from diffusers import UNet2DConditionModel
    unet = UNet2DConditionModel.from_pretrained(str(unet_dir)).eval()
    state_dict, alphas, metadata = StableDiffusionPipeline.lora_state_dict(
        str(lora_file.parent), weight_name=lora_file.name, return_lora_metadata=True)
    StableDiffusionPipeline.load_lora_into_unet(state_dict, alphas, unet=unet, metadata=metadata)
    with torch.no_grad():
        out = unet(io["sample"], io["timestep"], io["encoder_hidden_states"]).sample
    return (out - expected).abs().max().item()


def diffusers_lora_error(lora_file: Path, model_dir: Path, ids, expected) -> float:
    """Loads `lora_file` the way `StableDiffusionPipeline.load_lora_weights` does for the text
    encoder and returns the max abs error of the output against `expected`."""
    te = CLIPTextModel.from_pretrained(str(model_dir / "text_encoder")).eval()
    state_dict, alphas, metadata = StableDiffusionPipeline.lora_state_dict(
        str(lora_file.parent), weight_name=lora_file.name, return_lora_metadata=True)
    StableDiffusionPipeline.load_lora_into_text_encoder(
        state_dict, alphas, text_encoder=te, metadata=metadata)
    with torch.no_grad():
        out = te(input_ids=ids).last_hidden_state
    return (out - expected).abs().max().item()


def pipeline_load_lora_error(lora_file: Path) -> dict:
    """Loads `lora_file` with the public `StableDiffusionPipeline.load_lora_weights` into a
    pipeline built from the fixtures (sd_text/clip_quick text encoder + tokenizer, sd_image
    U-Net, VAE and scheduler; the two halves are never run together, so their sizes need not
    match) and returns, per component the file touches, the max abs error of that component's
    output against the fixture's expected LoRA output. Also fails on any key diffusers did not
    use (PEFT reports them as unexpected keys)."""
    from diffusers import AutoencoderKL, DDIMScheduler, UNet2DConditionModel
    image = ROOT / "crates/gb-diffusion/tests/fixtures/sd_image"
    pipe = StableDiffusionPipeline(
        vae=AutoencoderKL.from_pretrained(str(image / "pipeline/vae")),
        text_encoder=CLIPTextModel.from_pretrained(str(OUT / "clip_quick/text_encoder")).eval(),
        tokenizer=CLIPTokenizer.from_pretrained(str(OUT / "tokenizer")),
        unet=UNet2DConditionModel.from_pretrained(str(image / "pipeline/unet")).eval(),
        scheduler=DDIMScheduler.from_pretrained(str(image / "pipeline/scheduler")),
        safety_checker=None, feature_extractor=None, requires_safety_checker=False)
    keys = load_file(str(lora_file)).keys()
    import logging
    records = []

    class Grab(logging.Handler):
        def emit(self, record):
            records.append(record.getMessage())

    grab = Grab(level=logging.WARNING)
    for name in ["diffusers", "peft"]:
        logging.getLogger(name).addHandler(grab)
    pipe.load_lora_weights(str(lora_file.parent), weight_name=lora_file.name)
    for name in ["diffusers", "peft"]:
        logging.getLogger(name).removeHandler(grab)
    bad = [r for r in records if "unexpected keys" in r]
    assert not bad, f"diffusers did not use every tensor of {lora_file}: {bad}"
    errors = {}
    with torch.no_grad():
        if any(k.startswith("text_encoder.") for k in keys):
            ids = load_file(str(OUT / "text_io.safetensors"))["input_ids"]
            expected = load_file(str(OUT / "lora_io.safetensors"))["last_hidden_state_lora"]
            out = pipe.text_encoder(input_ids=ids).last_hidden_state
            errors["text_encoder"] = (out - expected).abs().max().item()
        if any(k.startswith("unet.") for k in keys):
            io = load_file(str(image / "unet_sd15_io.safetensors"))
            expected = load_file(str(OUT / "unet_lora_io.safetensors"))["out_lora"]
            out = pipe.unet(io["sample"], io["timestep"], io["encoder_hidden_states"]).sample
            errors["unet"] = (out - expected).abs().max().item()
    assert errors, f"{lora_file}: no text_encoder.* or unet.* LoRA tensors"
    return errors


def check_exported(export_dir: Path) -> float:
    """Checks the files the Rust tests export with GB_LORA_EXPORT_DIR (see
    tools/parity/README.md): rust_text_lora.safetensors (text encoder, sd_text_parity.rs) and
    rust_unet_lora.safetensors (U-Net with conv LoRA, sd_text_unet_lora.rs), each through the
    component loaders and through `pipe.load_lora_weights`. Returns the worst max abs error."""
    worst = 0.0
    for name in ["rust_text_lora.safetensors", "rust_unet_lora.safetensors"]:
        f = export_dir / name
        if not f.is_file():
            raise SystemExit(f"{f} is missing: run the export tests first (tools/parity/README.md)")
        for comp, err in pipeline_load_lora_error(f).items():
            print(f"pipe.load_lora_weights({name}) -> {comp}: max abs err {err:.3e}")
            worst = max(worst, err)
    image = ROOT / "crates/gb-diffusion/tests/fixtures/sd_image"
    ids = load_file(str(OUT / "text_io.safetensors"))["input_ids"]
    expected = load_file(str(OUT / "lora_io.safetensors"))["last_hidden_state_lora"]
    err = diffusers_lora_error(export_dir / "rust_text_lora.safetensors", OUT / "clip_quick", ids, expected)
    print(f"load_lora_into_text_encoder(rust_text_lora.safetensors): max abs err {err:.3e}")
    worst = max(worst, err)
    io = load_file(str(image / "unet_sd15_io.safetensors"))
    expected = load_file(str(OUT / "unet_lora_io.safetensors"))["out_lora"]
    err = diffusers_unet_lora_error(export_dir / "rust_unet_lora.safetensors", image / "pipeline/unet", io, expected)
    print(f"load_lora_into_unet(rust_unet_lora.safetensors): max abs err {err:.3e}")
    worst = max(worst, err)
    print(f"worst max abs err {worst:.3e} (bound 1e-4)")
    return worst


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--check-exported":
        sys.exit(0 if check_exported(Path(sys.argv[2])) < 1e-4 else 1)
    if len(sys.argv) == 3 and sys.argv[1] == "--check-unet-lora":
        image = ROOT / "crates/gb-diffusion/tests/fixtures/sd_image"
        io = load_file(str(image / "unet_sd15_io.safetensors"))
        expected = load_file(str(OUT / "unet_lora_io.safetensors"))["out_lora"]
        err = diffusers_unet_lora_error(Path(sys.argv[2]), image / "pipeline/unet", io, expected)
        print(f"diffusers load_lora_into_unet of {sys.argv[2]}: max abs err {err:.3e}")
        sys.exit(0 if err < 1e-4 else 1)
    if len(sys.argv) == 3 and sys.argv[1] == "--check-lora":
        # Check a LoRA file written by gb-diffusion: diffusers must load it and reproduce the
        # fixture's expected output.
        ids = load_file(str(OUT / "text_io.safetensors"))["input_ids"]
        expected = load_file(str(OUT / "lora_io.safetensors"))["last_hidden_state_lora"]
        err = diffusers_lora_error(Path(sys.argv[2]), OUT / "clip_quick", ids, expected)
        print(f"diffusers load_lora of {sys.argv[2]}: max abs err {err:.3e}")
        sys.exit(0 if err < 1e-4 else 1)
    main()
