//! Where the suite's pairs come from: a [`PairSource`] gives each pair's render, its
//! ground truth (if any), its mask and its disparity maps, read on demand. Two sources ship:
//! folders paired by sorted name ([`EvalInputs`], `cargo xtask eval`) and pairs held in
//! memory ([`PairSet`], a run's test views).

use std::borrow::Cow;

use gb_core::RgbImage;

use crate::disparity::ScalarMap;
use crate::eval_inputs::{EvalInputs, InputError};

/// An input a metric may need.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Input {
    /// Ground-truth images (the full-reference metrics).
    Reference,
    /// Predicted and ground-truth depth (D-PSNR, D-FID).
    Depth,
}

/// A render and its ground truth, borrowed from memory or read from files.
pub type Images<'a> = (Cow<'a, RgbImage>, Option<Cow<'a, RgbImage>>);
/// Predicted and ground-truth disparity.
pub type Disparity<'a> = (Cow<'a, ScalarMap>, Cow<'a, ScalarMap>);

/// The pairs one evaluation scores.
pub trait PairSource {
    /// Number of pairs.
    fn len(&self) -> usize;
    /// Whether there is no pair.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Name of pair `i` (its file or view name).
    fn name(&self, i: usize) -> &str;
    /// What one pair is called in reasons ("image pair", "test view").
    fn noun(&self) -> &str {
        "image pair"
    }
    /// Whether the source has `input` at all; `None` when it has, else why not.
    fn missing(&self, input: Input) -> Option<String>;
    /// Whether any pair has a mask.
    fn has_masks(&self) -> bool;
    /// Pair `i`'s render and its ground truth (same size), if it has one.
    fn images(&self, i: usize) -> Result<Images<'_>, InputError>;
    /// Pair `i`'s mask (row-major, `true` inside), if it has one.
    fn mask(&self, i: usize) -> Result<Option<Cow<'_, [bool]>>, InputError>;
    /// Pair `i`'s predicted and ground-truth disparity, if it has them.
    fn disparity(&self, i: usize) -> Result<Option<Disparity<'_>>, InputError>;
}

impl PairSource for EvalInputs {
    fn len(&self) -> usize {
        self.pred.len()
    }

    fn name(&self, i: usize) -> &str {
        &self.names[i]
    }

    fn missing(&self, input: Input) -> Option<String> {
        match input {
            Input::Reference => None,
            Input::Depth => self
                .depth
                .is_none()
                .then(|| "no depth folders (pass --pred-depth and --gt-depth)".into()),
        }
    }

    fn has_masks(&self) -> bool {
        self.masks.is_some()
    }

    fn images(&self, i: usize) -> Result<Images<'_>, InputError> {
        let (pred, gt) = self.load_pair(i)?;
        Ok((Cow::Owned(pred), Some(Cow::Owned(gt))))
    }

    fn mask(&self, i: usize) -> Result<Option<Cow<'_, [bool]>>, InputError> {
        Ok(self.load_mask(i)?.map(Cow::Owned))
    }

    fn disparity(&self, i: usize) -> Result<Option<Disparity<'_>>, InputError> {
        Ok(self
            .load_disparity_pair(i)?
            .map(|(p, g)| (Cow::Owned(p), Cow::Owned(g))))
    }
}

/// One pair held in memory.
#[derive(Debug, Clone)]
pub struct EvalPair {
    /// Name (view or file stem).
    pub name: String,
    /// The render.
    pub pred: RgbImage,
    /// The ground truth (same size), if there is one.
    pub gt: Option<RgbImage>,
    /// The object mask (row-major, `true` inside, the render's size), if there is one.
    pub mask: Option<Vec<bool>>,
    /// Predicted and ground-truth disparity, if there is ground-truth depth.
    pub disparity: Option<(ScalarMap, ScalarMap)>,
}

/// Pairs held in memory, with the words their reasons use.
#[derive(Debug, Clone)]
pub struct PairSet<'a> {
    /// The pairs.
    pub pairs: &'a [EvalPair],
    /// What one pair is called ("test view").
    pub noun: &'a str,
    /// Why there is no ground truth, when no pair has one.
    pub no_reference: &'a str,
    /// Why there is no depth, when no pair has it.
    pub no_depth: &'a str,
}

impl<'a> PairSet<'a> {
    /// The pairs, called "image pair"s in reasons.
    pub fn new(pairs: &'a [EvalPair]) -> Self {
        Self {
            pairs,
            noun: "image pair",
            no_reference: "no ground-truth images",
            no_depth: "no ground-truth depth",
        }
    }
}

impl PairSource for PairSet<'_> {
    fn len(&self) -> usize {
        self.pairs.len()
    }

    fn name(&self, i: usize) -> &str {
        &self.pairs[i].name
    }

    fn noun(&self) -> &str {
        self.noun
    }

    fn missing(&self, input: Input) -> Option<String> {
        let (any, why) = match input {
            Input::Reference => (self.pairs.iter().any(|p| p.gt.is_some()), self.no_reference),
            Input::Depth => (
                self.pairs.iter().any(|p| p.disparity.is_some()),
                self.no_depth,
            ),
        };
        (!any).then(|| why.to_string())
    }

    fn has_masks(&self) -> bool {
        self.pairs.iter().any(|p| p.mask.is_some())
    }

    fn images(&self, i: usize) -> Result<Images<'_>, InputError> {
        let p = &self.pairs[i];
        Ok((Cow::Borrowed(&p.pred), p.gt.as_ref().map(Cow::Borrowed)))
    }

    fn mask(&self, i: usize) -> Result<Option<Cow<'_, [bool]>>, InputError> {
        Ok(self.pairs[i].mask.as_deref().map(Cow::Borrowed))
    }

    fn disparity(&self, i: usize) -> Result<Option<Disparity<'_>>, InputError> {
        Ok(self.pairs[i]
            .disparity
            .as_ref()
            .map(|(p, g)| (Cow::Borrowed(p), Cow::Borrowed(g))))
    }
}
