//! MoMask's length estimator: a classifier over token counts from the prompt and the skeleton,
//! used when the user gives no duration.

use crate::condition::{Condition, TEXT_DIM};
use crate::trunk::cross_entropy;
use anymo_tokenizer::nn::{Activation, FeedForward, Params};
use candle_core::{D, Result, Tensor};

/// Predicts a clip's length in token steps.
pub struct LengthPredictor {
    ff: FeedForward,
    max_tokens: usize,
}

impl LengthPredictor {
    /// A predictor of lengths `1..=max_tokens`.
    pub fn new(p: &mut Params, skeleton_dim: usize, hidden: usize, max_tokens: usize) -> Result<LengthPredictor> {
        let ff = p.scope("length", |p| {
            FeedForward::with_activation(p, "ff", TEXT_DIM + skeleton_dim, hidden, max_tokens, Activation::Gelu)
        })?;
        Ok(LengthPredictor { ff, max_tokens })
    }

    fn logits(&self, condition: &Condition) -> Result<Tensor> {
        self.ff.forward(&Tensor::cat(&[&condition.text, &condition.skeleton], D::Minus1)?)
    }

    /// Cross-entropy against true lengths (capped at the maximum).
    pub fn loss(&self, condition: &Condition, steps: &[usize]) -> Result<Tensor> {
        let targets: Vec<u32> = steps.iter().map(|&s| (s.clamp(1, self.max_tokens) - 1) as u32).collect();
        cross_entropy(&self.logits(condition)?, &targets, &vec![1.0; steps.len()])
    }

    /// The most likely length of each row.
    pub fn predict(&self, condition: &Condition) -> Result<Vec<usize>> {
        let logits: Vec<Vec<f32>> = self.logits(condition)?.to_vec2()?;
        Ok(logits
            .iter()
            .map(|row| {
                row.iter().enumerate().fold((0, f32::NEG_INFINITY), |a, (i, &v)| if v > a.1 { (i, v) } else { a }).0 + 1
            })
            .collect())
    }
}
