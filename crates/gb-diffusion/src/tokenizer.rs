//! CLIP BPE tokenizer built with the `tokenizers` crate from a checkpoint's
//! `tokenizer/vocab.json` + `merges.txt`, configured like transformers' `CLIPTokenizer`:
//! NFC, whitespace runs to one space, lowercase; CLIP's pre-tokenising regex, byte-level
//! alphabet, `</w>` end-of-word suffix; BOS/EOS around the text; truncation and padding to
//! `model_max_length` (77) with the checkpoint's pad token.

use std::path::{Path, PathBuf};

use serde::Deserialize;
use tokenizers::models::bpe::BPE;
use tokenizers::normalizers::replace::{Replace, ReplacePattern};
use tokenizers::normalizers::{Lowercase, Sequence as NormSequence, NFC};
use tokenizers::pre_tokenizers::byte_level::ByteLevel;
use tokenizers::pre_tokenizers::sequence::Sequence as PreSequence;
use tokenizers::pre_tokenizers::split::{Split, SplitPattern};
use tokenizers::processors::roberta::RobertaProcessing;
use tokenizers::{
    AddedToken, NormalizerWrapper, PaddingDirection, PaddingParams, PaddingStrategy,
    PreTokenizerWrapper, SplitDelimiterBehavior, Tokenizer, TruncationDirection, TruncationParams,
    TruncationStrategy,
};

/// CLIP's pre-tokenising regex (with the special tokens kept whole), as in transformers.
const CLIP_PATTERN: &str =
    r"<\|startoftext\|>|<\|endoftext\|>|'s|'t|'re|'ve|'m|'ll|'d|[\p{L}]+|[\p{N}]|[^\s\p{L}\p{N}]+";

/// Error building or running the tokenizer.
#[derive(Debug, thiserror::Error)]
pub enum TokenizerError {
    /// A tokenizer file is missing or unreadable.
    #[error("cannot read tokenizer file {path}: {message}")]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// A special token named in the config is not in the vocabulary.
    #[error("special token `{token}` ({role}) is not in the vocabulary {path}")]
    UnknownSpecialToken {
        /// The token text.
        token: String,
        /// bos / eos / pad / unk.
        role: &'static str,
        /// The vocabulary file.
        path: PathBuf,
    },
    /// The `tokenizers` crate failed.
    #[error("tokenizer error: {0}")]
    Tokenizers(String),
}

/// A special token entry of `tokenizer_config.json`: a string or an `AddedToken` object.
#[derive(Debug, Clone, Deserialize)]
#[serde(untagged)]
enum SpecialToken {
    Text(String),
    Object { content: String },
}

impl SpecialToken {
    fn content(&self) -> &str {
        match self {
            SpecialToken::Text(s) => s,
            SpecialToken::Object { content } => content,
        }
    }
}

/// The fields of `tokenizer_config.json` / `special_tokens_map.json` that matter here.
#[derive(Debug, Clone, Default, Deserialize)]
struct SpecialTokensConfig {
    bos_token: Option<SpecialToken>,
    eos_token: Option<SpecialToken>,
    pad_token: Option<SpecialToken>,
    unk_token: Option<SpecialToken>,
    model_max_length: Option<f64>,
}

/// The resolved special tokens and length of a CLIP tokenizer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClipSpecialTokens {
    /// Beginning of sequence (`<|startoftext|>`).
    pub bos: (String, u32),
    /// End of sequence (`<|endoftext|>`).
    pub eos: (String, u32),
    /// Padding (`<|endoftext|>` for SD 1.x, `!` for SD 2.x).
    pub pad: (String, u32),
    /// Unknown token.
    pub unk: String,
    /// Output length (77).
    pub max_length: usize,
}

/// A CLIP tokenizer that turns prompts into fixed-length id sequences.
#[derive(Debug, Clone)]
pub struct ClipTokenizer {
    inner: Tokenizer,
    special: ClipSpecialTokens,
}

impl ClipTokenizer {
    /// Builds the tokenizer from a checkpoint's `tokenizer/` folder: `vocab.json`,
    /// `merges.txt`, and (when present) `tokenizer_config.json` and
    /// `special_tokens_map.json` for the special tokens and `model_max_length`.
    pub fn from_dir(dir: &Path) -> Result<Self, TokenizerError> {
        let vocab_path = dir.join("vocab.json");
        let merges_path = dir.join("merges.txt");
        for path in [&vocab_path, &merges_path] {
            if !path.is_file() {
                return Err(TokenizerError::File {
                    path: path.clone(),
                    message: "not found".into(),
                });
            }
        }
        let mut config = read_special(&dir.join("special_tokens_map.json"))?;
        let tok_config = read_special(&dir.join("tokenizer_config.json"))?;
        // tokenizer_config.json wins, as in transformers.
        config.bos_token = tok_config.bos_token.or(config.bos_token);
        config.eos_token = tok_config.eos_token.or(config.eos_token);
        config.pad_token = tok_config.pad_token.or(config.pad_token);
        config.unk_token = tok_config.unk_token.or(config.unk_token);
        config.model_max_length = tok_config.model_max_length.or(config.model_max_length);

        let (vocab, merges) = BPE::read_file(&path_str(&vocab_path), &path_str(&merges_path))
            .map_err(|e| TokenizerError::File {
                path: vocab_path.clone(),
                message: e.to_string(),
            })?;
        let lookup = |tok: &Option<SpecialToken>, default: &str, role: &'static str| {
            let text = tok
                .as_ref()
                .map(|t| t.content().to_string())
                .unwrap_or_else(|| default.to_string());
            match vocab.get(&text) {
                Some(id) => Ok((text, *id)),
                None => Err(TokenizerError::UnknownSpecialToken {
                    token: text,
                    role,
                    path: vocab_path.clone(),
                }),
            }
        };
        let bos = lookup(&config.bos_token, "<|startoftext|>", "bos")?;
        let eos = lookup(&config.eos_token, "<|endoftext|>", "eos")?;
        let pad = lookup(&config.pad_token, "<|endoftext|>", "pad")?;
        let unk = lookup(&config.unk_token, "<|endoftext|>", "unk")?.0;
        // transformers' "unbounded" sentinel is 1e30; CLIP checkpoints say 77.
        let max_length = match config.model_max_length {
            Some(n) if (1.0..1e6).contains(&n) => n as usize,
            _ => 77,
        };
        let special = ClipSpecialTokens {
            bos,
            eos,
            pad,
            unk,
            max_length,
        };
        let model = BPE::builder()
            .vocab_and_merges(vocab, merges)
            .continuing_subword_prefix(String::new())
            .end_of_word_suffix("</w>".into())
            .fuse_unk(false)
            .unk_token(special.unk.clone())
            .build()
            .map_err(|e| TokenizerError::Tokenizers(e.to_string()))?;
        let inner = build_pipeline(model, &special)?;
        Ok(Self { inner, special })
    }

    /// The special tokens and output length.
    pub fn special_tokens(&self) -> &ClipSpecialTokens {
        &self.special
    }

    /// Tokenises one prompt to exactly `max_length` ids: BOS, the text (truncated), EOS,
    /// then padding — as `tokenizer(p, padding="max_length", truncation=True)` does.
    pub fn encode(&self, prompt: &str) -> Result<Vec<u32>, TokenizerError> {
        let enc = self
            .inner
            .encode(prompt, true)
            .map_err(|e| TokenizerError::Tokenizers(e.to_string()))?;
        Ok(enc.get_ids().to_vec())
    }

    /// Tokenises a batch of prompts (each to `max_length` ids).
    pub fn encode_batch(&self, prompts: &[String]) -> Result<Vec<Vec<u32>>, TokenizerError> {
        prompts.iter().map(|p| self.encode(p)).collect()
    }
}

fn path_str(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

fn read_special(path: &Path) -> Result<SpecialTokensConfig, TokenizerError> {
    if !path.is_file() {
        return Ok(SpecialTokensConfig::default());
    }
    let text = std::fs::read_to_string(path).map_err(|e| TokenizerError::File {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    serde_json::from_str(&text).map_err(|e| TokenizerError::File {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

fn tk_err(e: impl std::fmt::Display) -> TokenizerError {
    TokenizerError::Tokenizers(e.to_string())
}

/// Assembles normaliser, pre-tokeniser, post-processor, truncation and padding.
fn build_pipeline(model: BPE, special: &ClipSpecialTokens) -> Result<Tokenizer, TokenizerError> {
    let mut tokenizer = Tokenizer::new(model);
    let normalizer = NormSequence::new(vec![
        NormalizerWrapper::from(NFC),
        NormalizerWrapper::from(
            Replace::new(ReplacePattern::Regex(r"\s+".into()), " ").map_err(tk_err)?,
        ),
        NormalizerWrapper::from(Lowercase),
    ]);
    tokenizer.with_normalizer(Some(normalizer));
    let split = Split::new(
        SplitPattern::Regex(CLIP_PATTERN.into()),
        SplitDelimiterBehavior::Removed,
        true,
    )
    .map_err(tk_err)?;
    let pre = PreSequence::new(vec![
        PreTokenizerWrapper::from(split),
        PreTokenizerWrapper::from(ByteLevel::new(false, true, true)),
    ]);
    tokenizer.with_pre_tokenizer(Some(pre));
    let post = RobertaProcessing::new(special.eos.clone(), special.bos.clone())
        .trim_offsets(false)
        .add_prefix_space(false);
    tokenizer.with_post_processor(Some(post));
    let mut specials: Vec<AddedToken> = Vec::new();
    for text in [&special.bos.0, &special.eos.0, &special.pad.0, &special.unk] {
        if !specials.iter().any(|t| &t.content == text) {
            specials.push(AddedToken::from(text.clone(), true));
        }
    }
    tokenizer.add_special_tokens(&specials);
    tokenizer
        .with_truncation(Some(TruncationParams {
            direction: TruncationDirection::Right,
            max_length: special.max_length,
            strategy: TruncationStrategy::LongestFirst,
            stride: 0,
        }))
        .map_err(tk_err)?;
    tokenizer.with_padding(Some(PaddingParams {
        strategy: PaddingStrategy::Fixed(special.max_length),
        direction: PaddingDirection::Right,
        pad_to_multiple_of: None,
        pad_id: special.pad.1,
        pad_type_id: 0,
        pad_token: special.pad.0.clone(),
    }));
    Ok(tokenizer)
}
