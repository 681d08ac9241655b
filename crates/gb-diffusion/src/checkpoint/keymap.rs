//! THE table of key remapping between checkpoint files and Burn module paths.
//!
//! Each component has one [`KeymapSection`]: regex rules applied in order to every key of
//! its safetensors files (diffusers / transformers names) to give the Burn parameter path,
//! plus patterns of checkpoint keys that are expected to be unused (buffers such as
//! `position_ids`). The generic renames (linear weight transpose, norm `weight`/`bias` to
//! `gamma`/`beta`) are done by burn's `PyTorchToBurnAdapter` and need no entry here.
//!
//! Module fields are named after the diffusers keys, so most sections are short.

/// Key remapping rules for one pipeline component.
#[derive(Debug, Clone, Copy)]
pub struct KeymapSection {
    /// Component name (also the diffusers sub-folder name).
    pub name: &'static str,
    /// `(regex, replacement)` pairs, applied in order to each checkpoint key.
    pub rules: &'static [(&'static str, &'static str)],
    /// Regexes of checkpoint keys that the module does not use, on purpose.
    pub ignored: &'static [&'static str],
    /// `(regex, replacement)` pairs mapping a Burn path back to the diffusers name, applied
    /// in order (used when writing LoRA files). Empty when the names are the same.
    pub to_checkpoint: &'static [(&'static str, &'static str)],
}

// ---------------------------------------------------------------------------------------
// Text encoder (transformers CLIPTextModel). Owner: sd-text.
// ---------------------------------------------------------------------------------------

/// `text_encoder/`: transformers' `CLIPTextModel`. Keys map one to one; some older
/// exports lack the `text_model.` prefix and carry a `position_ids` buffer.
pub const TEXT_ENCODER: KeymapSection = KeymapSection {
    name: "text_encoder",
    rules: &[(
        r"^(embeddings|encoder|final_layer_norm)\.",
        "text_model.$1.",
    )],
    ignored: &[r"position_ids$", r"^text_projection\."],
    to_checkpoint: &[],
};

// ---------------------------------------------------------------------------------------
// VAE (diffusers AutoencoderKL). Owner: sd-image — add rules below.
// ---------------------------------------------------------------------------------------

/// `vae/`: diffusers' `AutoencoderKL`. Checkpoints written before diffusers 0.14 name the
/// mid-block attention `query`/`key`/`value`/`proj_attn`; current ones (and the Burn module)
/// `to_q`/`to_k`/`to_v`/`to_out.0`.
pub const VAE: KeymapSection = KeymapSection {
    name: "vae",
    rules: &[
        (r"(mid_block\.attentions\.\d+)\.query\.", "${1}.to_q."),
        (r"(mid_block\.attentions\.\d+)\.key\.", "${1}.to_k."),
        (r"(mid_block\.attentions\.\d+)\.value\.", "${1}.to_v."),
        (
            r"(mid_block\.attentions\.\d+)\.proj_attn\.",
            "${1}.to_out.0.",
        ),
    ],
    ignored: &[],
    to_checkpoint: &[],
};

// ---------------------------------------------------------------------------------------
// U-Net (diffusers UNet2DConditionModel). Owner: sd-image — add rules below.
// ---------------------------------------------------------------------------------------

/// `unet/`: diffusers' `UNet2DConditionModel` (SD 1.x: 1x1-convolution `proj_in`/`proj_out`).
/// The feed-forward's `ff.net.0` (GEGLU) and `ff.net.2` (linear) are different module
/// types, so the Burn fields are `ff.net_0` and `ff.net_2`.
pub const UNET: KeymapSection = KeymapSection {
    name: "unet",
    rules: &[
        (r"\.ff\.net\.0\.", ".ff.net_0."),
        (r"\.ff\.net\.2\.", ".ff.net_2."),
    ],
    ignored: &[],
    to_checkpoint: &[
        (r"\.ff\.net_0\.", ".ff.net.0."),
        (r"\.ff\.net_2\.", ".ff.net.2."),
    ],
};

/// `unet/` of a config with `use_linear_projection = true` (SD 2.x): as [`UNET`], and the
/// linear `proj_in`/`proj_out` of each transformer live in the Burn fields
/// `proj_in_linear`/`proj_out_linear` (the 1x1-convolution fields stay empty).
pub const UNET_LINEAR_PROJECTION: KeymapSection = KeymapSection {
    name: "unet",
    rules: &[
        (r"\.ff\.net\.0\.", ".ff.net_0."),
        (r"\.ff\.net\.2\.", ".ff.net_2."),
        (r"\.proj_in\.", ".proj_in_linear."),
        (r"\.proj_out\.", ".proj_out_linear."),
    ],
    ignored: &[],
    to_checkpoint: &[
        (r"\.ff\.net_0\.", ".ff.net.0."),
        (r"\.ff\.net_2\.", ".ff.net.2."),
        (r"\.proj_in_linear\.", ".proj_in."),
        (r"\.proj_out_linear\.", ".proj_out."),
    ],
};

// ---------------------------------------------------------------------------------------
// LoRA files. Owner: sd-text. A LoRA key's component prefix (`text_encoder.`, `unet.`,
// `lora_te_`, `lora_unet_`) is split off in `lora::file`; the rest of the key is mapped
// with the component's section above (`map_key` on `<module>.weight`), and written back
// with `unmap_key`. No extra table is needed here.
// ---------------------------------------------------------------------------------------

impl KeymapSection {
    /// Applies this section's rules to one checkpoint key.
    pub fn map_key(&self, key: &str) -> Result<String, super::CheckpointError> {
        let mut out = key.to_string();
        for (pattern, replacement) in self.rules {
            let re = self.compile(pattern)?;
            out = re.replace_all(&out, *replacement).into_owned();
        }
        Ok(out)
    }

    /// Maps a Burn parameter/module path back to the checkpoint (diffusers) name.
    pub fn unmap_key(&self, path: &str) -> Result<String, super::CheckpointError> {
        let mut out = path.to_string();
        for (pattern, replacement) in self.to_checkpoint {
            let re = self.compile(pattern)?;
            out = re.replace_all(&out, *replacement).into_owned();
        }
        Ok(out)
    }

    /// Whether `key` is listed as intentionally unused.
    pub fn is_ignored(&self, key: &str) -> Result<bool, super::CheckpointError> {
        for pattern in self.ignored {
            if self.compile(pattern)?.is_match(key) {
                return Ok(true);
            }
        }
        Ok(false)
    }

    fn compile(&self, pattern: &str) -> Result<regex::Regex, super::CheckpointError> {
        regex::Regex::new(pattern).map_err(|e| super::CheckpointError::Keymap {
            section: self.name.to_string(),
            pattern: pattern.to_string(),
            message: e.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_rule_compiles() {
        for section in [TEXT_ENCODER, VAE, UNET, UNET_LINEAR_PROJECTION] {
            section.map_key("x").unwrap();
            section.is_ignored("x").unwrap();
            section.unmap_key("x").unwrap();
        }
    }

    #[test]
    fn unet_paths_round_trip_through_both_directions() {
        for section in [UNET, UNET_LINEAR_PROJECTION] {
            for key in [
                "down_blocks.0.attentions.0.transformer_blocks.0.ff.net.0.proj.weight",
                "down_blocks.0.attentions.0.transformer_blocks.0.ff.net.2.weight",
                "up_blocks.1.attentions.2.proj_in.weight",
                "mid_block.attentions.0.transformer_blocks.0.attn2.to_out.0.weight",
            ] {
                let burn = section.map_key(key).unwrap();
                assert_eq!(section.unmap_key(&burn).unwrap(), key, "{}", section.name);
            }
        }
    }

    #[test]
    fn text_encoder_adds_missing_prefix() {
        assert_eq!(
            TEXT_ENCODER
                .map_key("encoder.layers.3.self_attn.q_proj.weight")
                .unwrap(),
            "text_model.encoder.layers.3.self_attn.q_proj.weight"
        );
        assert_eq!(
            TEXT_ENCODER
                .map_key("text_model.final_layer_norm.weight")
                .unwrap(),
            "text_model.final_layer_norm.weight"
        );
        assert!(TEXT_ENCODER
            .is_ignored("text_model.embeddings.position_ids")
            .unwrap());
    }

    // --- sd-image: VAE / U-Net rules ---------------------------------------------------

    #[test]
    fn vae_old_attention_names_map_to_new() {
        let cases = [
            (
                "encoder.mid_block.attentions.0.query.weight",
                "encoder.mid_block.attentions.0.to_q.weight",
            ),
            (
                "decoder.mid_block.attentions.0.key.bias",
                "decoder.mid_block.attentions.0.to_k.bias",
            ),
            (
                "encoder.mid_block.attentions.0.value.weight",
                "encoder.mid_block.attentions.0.to_v.weight",
            ),
            (
                "decoder.mid_block.attentions.0.proj_attn.weight",
                "decoder.mid_block.attentions.0.to_out.0.weight",
            ),
            (
                "decoder.mid_block.attentions.0.to_q.weight",
                "decoder.mid_block.attentions.0.to_q.weight",
            ),
            (
                "encoder.down_blocks.0.resnets.0.conv1.weight",
                "encoder.down_blocks.0.resnets.0.conv1.weight",
            ),
        ];
        for (from, to) in cases {
            assert_eq!(VAE.map_key(from).unwrap(), to);
        }
    }

    #[test]
    fn unet_feed_forward_and_linear_projection() {
        let k = "down_blocks.0.attentions.1.transformer_blocks.0.ff.net.0.proj.weight";
        let want = "down_blocks.0.attentions.1.transformer_blocks.0.ff.net_0.proj.weight";
        assert_eq!(UNET.map_key(k).unwrap(), want);
        assert_eq!(UNET_LINEAR_PROJECTION.map_key(k).unwrap(), want);
        let k = "mid_block.attentions.0.transformer_blocks.0.ff.net.2.bias";
        assert_eq!(
            UNET.map_key(k).unwrap(),
            "mid_block.attentions.0.transformer_blocks.0.ff.net_2.bias"
        );
        let k = "up_blocks.1.attentions.2.proj_in.weight";
        assert_eq!(UNET.map_key(k).unwrap(), k);
        assert_eq!(
            UNET_LINEAR_PROJECTION.map_key(k).unwrap(),
            "up_blocks.1.attentions.2.proj_in_linear.weight"
        );
        let k = "up_blocks.1.attentions.2.transformer_blocks.0.attn1.to_out.0.weight";
        assert_eq!(UNET_LINEAR_PROJECTION.map_key(k).unwrap(), k);
    }
}
