//! `cargo xtask parity --component C --model DIR --inputs IN --out OUT [--lora FILE]`:
//! runs one component of a diffusers-layout checkpoint on given inputs and writes its
//! outputs as safetensors, so they can be compared with diffusers / transformers.
//!
//! - `tokenizer`: IN is a JSON list of strings; writes `input_ids` (i64 `[n, 77]`).
//! - `text-encoder`: IN holds `input_ids` (i64); writes `last_hidden_state`.
//! - `vae-encode`: IN holds `image` in [-1, 1]; writes the latent `mean`, unscaled.
//! - `vae-decode`: IN holds `latents` (unscaled); writes `image`.
//! - `unet`: IN holds `sample`, `timestep`, `encoder_hidden_states`; writes `out`
//!   (`--lora` applies a U-Net LoRA first).
//!
//! `--precision f16` runs the networks as a run's prior does in f16 (half-precision weights
//! and activations, norms and softmax in f32), for comparison with diffusers in fp16; the
//! default is f32, whatever the device. `--device` picks the backend.
//!
//! Extension point (sd-image): add `VaeEncode`, `VaeDecode`, `Unet` variants to
//! [`Component`] and one match arm each in [`run`], in a function of their own below.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use burn::module::Module;
use burn::tensor::Tensor;
use gb_core::{BackendKind, Precision};
use gb_diffusion::checkpoint::hub;
use gb_diffusion::checkpoint::{keymap, DiffusersFolder, WeightVariant};
use gb_diffusion::clip::load_text_encoder;
use gb_diffusion::lora::{apply_lora, LoraComponent, LoraFile};
use gb_diffusion::models::parity as image_parity;
use gb_diffusion::models::{load_unet_variant, load_vae_variant};
use gb_diffusion::precision::cast_frozen;
use gb_diffusion::tensor_file::{read_i64, write_tensors, TensorOut};
use gb_diffusion::tokenizer::ClipTokenizer;

/// The component to run.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Component {
    /// CLIP tokenizer: prompts (JSON list) -> `input_ids`.
    Tokenizer,
    /// CLIP text encoder: `input_ids` -> `last_hidden_state`.
    TextEncoder,
    /// VAE encoder: `image` in [-1, 1] -> latent `mean` (unscaled).
    VaeEncode,
    /// VAE decoder: `latents` (unscaled) -> `image`.
    VaeDecode,
    /// U-Net: `sample`, `timestep`, `encoder_hidden_states` -> `out`.
    Unet,
}

/// Which weight files to load.
#[derive(Debug, Clone, Copy, clap::ValueEnum, Default)]
pub enum Variant {
    /// Full precision when present, else `.fp16`.
    #[default]
    Auto,
    /// Only full-precision files.
    Full,
    /// Only `.fp16` files (cast to f32).
    Fp16,
}

/// Arguments of `cargo xtask parity`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Which component to run.
    #[arg(long, value_enum)]
    pub component: Component,
    /// A diffusers-layout folder, or a hub id (`owner/name[@rev]`): taken from the hub
    /// cache (`$HF_HUB_CACHE`, else `$HF_HOME/hub`), else downloaded into it.
    #[arg(long)]
    pub model: String,
    /// Hub to download a hub id from when it is not cached (default: `$HF_ENDPOINT`, else
    /// https://huggingface.co).
    #[arg(long)]
    pub hub_endpoint: Option<String>,
    /// Inputs: a JSON list of strings for `tokenizer`, a safetensors file otherwise.
    #[arg(long)]
    pub inputs: PathBuf,
    /// Output safetensors file.
    #[arg(long)]
    pub out: PathBuf,
    /// A LoRA file (diffusers/PEFT or kohya) applied to the component first.
    #[arg(long)]
    pub lora: Option<PathBuf>,
    /// Compute backend: ndarray, flex (default) or wgpu.
    #[arg(long, value_enum)]
    pub device: Option<BackendKind>,
    /// Weight variant.
    #[arg(long, value_enum, default_value_t)]
    pub variant: Variant,
    /// The precision the network computes in (default f32; f16 needs flex or wgpu).
    #[arg(long, value_enum, default_value_t = Precision::F32)]
    pub precision: Precision,
}

/// Runs the command.
pub fn run(args: Args) -> anyhow::Result<()> {
    let root = resolve_model(&args.model, args.hub_endpoint.as_deref())?;
    let folder = DiffusersFolder::open(&root)?;
    let device = args.device.unwrap_or_default().device();
    let precision = Precision::resolve(Some(args.precision), &device).context("--precision")?;
    let variant = match args.variant {
        Variant::Auto => WeightVariant::Auto,
        Variant::Full => WeightVariant::Full,
        Variant::Fp16 => WeightVariant::Fp16,
    };
    let lora = args
        .lora
        .as_deref()
        .map(LoraFile::read)
        .transpose()
        .context("reading --lora")?;
    let outputs = match args.component {
        Component::Tokenizer => {
            if lora.is_some() {
                bail!("--lora does not apply to the tokenizer");
            }
            run_tokenizer(&folder, &args.inputs)?
        }
        Component::TextEncoder => run_text_encoder(
            &folder,
            variant,
            lora.as_ref(),
            &args.inputs,
            precision,
            &device,
        )?,
        Component::VaeEncode | Component::VaeDecode => {
            if lora.is_some() {
                bail!("--lora does not apply to the VAE");
            }
            let encode = matches!(args.component, Component::VaeEncode);
            run_vae(&root, variant, encode, &args.inputs, precision, &device)?
        }
        Component::Unet => run_unet(
            &root,
            variant,
            lora.as_ref(),
            &args.inputs,
            precision,
            &device,
        )?,
    };
    let named: Vec<(&str, TensorOut)> = outputs.iter().map(|(n, t)| (*n, t.clone())).collect();
    write_tensors(&args.out, &named)?;
    tracing::info!(out = %args.out.display(), "parity outputs written");
    Ok(())
}

/// The folder of `--model` through the one resolver (`tiny`, a folder, or a hub id from the
/// hf-hub cache or downloaded, at `--hub-endpoint` when given).
fn resolve_model(spec: &str, endpoint: Option<&str>) -> anyhow::Result<PathBuf> {
    let settings = hub::HubSettings::from_env();
    let settings = match endpoint {
        Some(e) => settings.with_endpoint(e),
        None => settings,
    };
    gb_diffusion::checkpoint::locate_model(spec, &settings).context("--model")
}

fn run_tokenizer(
    folder: &DiffusersFolder,
    inputs: &Path,
) -> anyhow::Result<Vec<(&'static str, TensorOut)>> {
    let text = std::fs::read_to_string(inputs)
        .with_context(|| format!("reading prompts {}", inputs.display()))?;
    let prompts: Vec<String> = serde_json::from_str(&text)
        .with_context(|| format!("{}: expected a JSON list of strings", inputs.display()))?;
    let tok = ClipTokenizer::from_dir(&folder.component_dir("tokenizer")?)?;
    let rows = tok.encode_batch(&prompts)?;
    let len = tok.special_tokens().max_length;
    let ids: Vec<i64> = rows.iter().flatten().map(|&i| i as i64).collect();
    Ok(vec![(
        "input_ids",
        TensorOut::I64(ids, vec![rows.len(), len]),
    )])
}

fn run_text_encoder(
    folder: &DiffusersFolder,
    variant: WeightVariant,
    lora: Option<&LoraFile>,
    inputs: &Path,
    precision: Precision,
    device: &burn::tensor::Device,
) -> anyhow::Result<Vec<(&'static str, TensorOut)>> {
    let (ids, shape) = read_i64(inputs, "input_ids")?;
    if shape.len() != 2 {
        bail!(
            "{}: input_ids must be [batch, seq], got {shape:?}",
            inputs.display()
        );
    }
    let rows: Vec<Vec<i64>> = ids.chunks(shape[1].max(1)).map(<[i64]>::to_vec).collect();
    let mut model = load_text_encoder(folder, variant, device)?;
    if let Some(lora) = lora {
        let (m, n) = apply_lora(
            model,
            lora,
            LoraComponent::TextEncoder,
            &keymap::TEXT_ENCODER,
        )?;
        if n == 0 {
            bail!("{}: no text-encoder entries", lora.path.display());
        }
        model = m;
    }
    let model = cast_frozen(model.valid(), precision);
    let out: Tensor<3> = model.forward(model.ids_tensor(&rows, device)?);
    let dims = out.dims().to_vec();
    let values = out
        .into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .map_err(|e| anyhow::anyhow!("reading output: {e:?}"))?;
    Ok(vec![("last_hidden_state", TensorOut::F32(values, dims))])
}

// --- sd-image: VAE and U-Net arms ------------------------------------------------------

fn f32_out<const D: usize>(t: Tensor<D>) -> anyhow::Result<TensorOut> {
    let dims = t.dims().to_vec();
    let values = t
        .into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .map_err(|e| anyhow::anyhow!("reading output: {e:?}"))?;
    Ok(TensorOut::F32(values, dims))
}

fn run_vae(
    root: &Path,
    variant: WeightVariant,
    encode: bool,
    inputs: &Path,
    precision: Precision,
    device: &burn::tensor::Device,
) -> anyhow::Result<Vec<(&'static str, TensorOut)>> {
    let (vae, cfg) = load_vae_variant(root, variant, device)?;
    let vae = cast_frozen(vae.valid(), precision);
    Ok(if encode {
        vec![(
            "mean",
            f32_out(image_parity::vae_encode(&vae, &cfg, inputs, device)?)?,
        )]
    } else {
        vec![(
            "image",
            f32_out(image_parity::vae_decode(&vae, &cfg, inputs, device)?)?,
        )]
    })
}

fn run_unet(
    root: &Path,
    variant: WeightVariant,
    lora: Option<&LoraFile>,
    inputs: &Path,
    precision: Precision,
    device: &burn::tensor::Device,
) -> anyhow::Result<Vec<(&'static str, TensorOut)>> {
    let (mut unet, cfg) = load_unet_variant(root, variant, device)?;
    if let Some(lora) = lora {
        let section = if cfg.use_linear_projection {
            keymap::UNET_LINEAR_PROJECTION
        } else {
            keymap::UNET
        };
        let (m, n) = apply_lora(unet, lora, LoraComponent::Unet, &section)?;
        if n == 0 {
            bail!("{}: no U-Net entries", lora.path.display());
        }
        unet = m;
    }
    let unet = cast_frozen(unet.valid(), precision);
    Ok(vec![(
        "out",
        f32_out(image_parity::unet(&unet, &cfg, inputs, device)?)?,
    )])
}
