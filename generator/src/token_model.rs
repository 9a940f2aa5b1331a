//! The trait both first-layer token models (masked and autoregressive) implement, apart from
//! the generator that holds one, so neither model depends on the generator.

use crate::condition::Condition;
use crate::sampling::Sampling;
use candle_core::{Result, Tensor};
use rand::RngCore;

/// A model of first-layer token sequences given a condition.
pub trait TokenModel {
    /// Training loss on first-layer codes `(B, L)`.
    fn loss(&self, codes: &[Vec<u32>], condition: &Condition, rng: &mut dyn RngCore) -> Result<Tensor>;
    /// Codes `(B, L)` where `known` gives none, keeping the known ones.
    fn sample(
        &self,
        condition: &Condition,
        known: &[Vec<Option<u32>>],
        sampling: &Sampling,
        rng: &mut dyn RngCore,
    ) -> Result<Vec<Vec<u32>>>;
}
