//! What a generation is conditioned on: the prompt's sentence embedding and the target
//! skeleton's OwO global embedding.

use candle_core::{Device, Result, Tensor};

/// Sentence-embedding width (all-MiniLM-L6-v2).
pub const TEXT_DIM: usize = 384;

/// A batch of conditions: `text (B, 384)` and `skeleton (B, owo_dim)`.
#[derive(Clone, Debug)]
pub struct Condition {
    /// Sentence embeddings; an all-zero row is the unconditional (dropped) prompt.
    pub text: Tensor,
    /// OwO global embeddings of the target skeletons.
    pub skeleton: Tensor,
}

impl Condition {
    /// A batch from rows of sentence and skeleton embeddings.
    pub fn new(text: &[&[f32]], skeleton: &[&[f32]]) -> Result<Condition> {
        Ok(Condition { text: rows(text)?, skeleton: rows(skeleton)? })
    }

    /// Rows of this batch repeated: the conditional rows, then the same rows with the prompt
    /// dropped, for classifier-free guidance in one forward pass.
    pub fn with_unconditional(&self) -> Result<Condition> {
        Ok(Condition {
            text: Tensor::cat(&[&self.text, &self.text.zeros_like()?], 0)?,
            skeleton: Tensor::cat(&[&self.skeleton, &self.skeleton], 0)?,
        })
    }

    /// Rows in the batch.
    pub fn len(&self) -> usize {
        self.text.dims()[0]
    }

    /// Whether the batch is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

fn rows(rows: &[&[f32]]) -> Result<Tensor> {
    let width = rows.first().map_or(0, |r| r.len());
    let flat: Vec<f32> = rows.iter().flat_map(|r| r.iter().copied()).collect();
    Tensor::from_vec(flat, (rows.len(), width), &Device::Cpu)
}
