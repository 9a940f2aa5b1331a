//! The transformer all token models share: the prompt and the skeleton enter as prefix
//! positions, token embeddings follow, learned positions cover both.

use crate::condition::{Condition, TEXT_DIM};
use anymo_tokenizer::nn::{LayerNorm, Linear, Params, TransformerLayer};
use candle_core::{D, Device, Result, Tensor};
use serde::{Deserialize, Serialize};

/// A trunk's shape.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct TrunkConfig {
    /// Width.
    pub dim: usize,
    /// Transformer layers.
    pub layers: usize,
    /// Attention heads.
    pub heads: usize,
    /// Feed-forward width.
    pub ff: usize,
    /// Longest token sequence.
    pub max_tokens: usize,
    /// Width of the skeleton embedding (OwO's).
    pub skeleton_dim: usize,
}

/// Prefix conditioning plus a pre-norm transformer.
pub struct Trunk {
    text: Linear,
    skeleton: Linear,
    position: Tensor,
    layers: Vec<TransformerLayer>,
    norm: LayerNorm,
    prefix: usize,
}

impl Trunk {
    /// A trunk with `extra` prefix positions after the prompt and the skeleton.
    pub fn new(p: &mut Params, config: &TrunkConfig, extra: usize) -> Result<Trunk> {
        let prefix = 2 + extra;
        Ok(Trunk {
            text: Linear::new(p, "text", TEXT_DIM, config.dim)?,
            skeleton: Linear::new(p, "skeleton", config.skeleton_dim, config.dim)?,
            position: p.normal("position", &[prefix + config.max_tokens, config.dim], 0.02)?,
            layers: (0..config.layers)
                .map(|i| TransformerLayer::new(p, &format!("layer{i}"), config.dim, config.heads, config.ff))
                .collect::<Result<_>>()?,
            norm: LayerNorm::new(p, "norm", config.dim)?,
            prefix,
        })
    }

    /// Prefix positions (prompt, skeleton, extras).
    pub fn prefix(&self) -> usize {
        self.prefix
    }

    /// Hidden states `(B, prefix + L, dim)` of `tokens (B, L, dim)` after the condition and the
    /// `extra (B, E, dim)` prefix vectors; `causal` lets each position see only earlier ones.
    pub fn forward(
        &self,
        condition: &Condition,
        extra: Option<&Tensor>,
        tokens: &Tensor,
        causal: bool,
    ) -> Result<Tensor> {
        let (b, l, dim) = tokens.dims3()?;
        let text = self.text.forward(&condition.text)?.unsqueeze(1)?;
        let skeleton = self.skeleton.forward(&condition.skeleton)?.unsqueeze(1)?;
        let mut parts = vec![text, skeleton];
        if let Some(extra) = extra {
            parts.push(extra.clone());
        }
        parts.push(tokens.clone());
        let n = self.prefix + l;
        let positions = self.position.narrow(0, 0, n)?.unsqueeze(0)?.broadcast_as((b, n, dim))?;
        let mut x = (Tensor::cat(&parts, 1)? + positions)?;
        let mask = causal.then(|| causal_mask(n)).transpose()?;
        for layer in &self.layers {
            x = layer.forward_masked(&x, mask.as_ref())?;
        }
        self.norm.forward(&x)
    }
}

/// `(n, n)` additive mask: `-inf` above the diagonal.
fn causal_mask(n: usize) -> Result<Tensor> {
    let values: Vec<f32> =
        (0..n).flat_map(|i| (0..n).map(move |j| if j > i { f32::NEG_INFINITY } else { 0.0 })).collect();
    Tensor::from_vec(values, (n, n), &Device::Cpu)
}

/// Mean cross-entropy of `logits (N, C)` against `targets`, over rows with a non-zero `weight`.
pub fn cross_entropy(logits: &Tensor, targets: &[u32], weight: &[f32]) -> Result<Tensor> {
    let n = targets.len();
    // candle-nn's log_softmax is built from max, exp, sum and log, all with a backward pass
    // (unlike the fused softmax_last_dim); the gradient tests cover it.
    let log_probs = candle_nn::ops::log_softmax(logits, D::Minus1)?;
    let targets = Tensor::from_slice(targets, (n, 1), &Device::Cpu)?;
    let picked = log_probs.gather(&targets, 1)?.squeeze(1)?;
    let total: f32 = weight.iter().sum();
    let weight = Tensor::from_slice(weight, n, &Device::Cpu)?;
    (picked * weight)?.sum_all()?.affine(-1.0 / f64::from(total.max(1.0)), 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cross_entropy_of_uniform_logits_is_log_classes() {
        let logits = Tensor::zeros((3, 8), candle_core::DType::F32, &Device::Cpu).unwrap();
        let loss = cross_entropy(&logits, &[1, 2, 3], &[1.0, 1.0, 0.0]).unwrap().to_scalar::<f32>().unwrap();
        assert!((loss - 8f32.ln()).abs() < 1e-6, "{loss}");
    }

    #[test]
    fn a_causal_trunk_does_not_see_the_future() {
        let mut p = Params::new(1);
        let config = TrunkConfig { dim: 16, layers: 2, heads: 2, ff: 32, max_tokens: 6, skeleton_dim: 4 };
        let trunk = Trunk::new(&mut p, &config, 0).unwrap();
        let condition = Condition::new(&[&[0.1; TEXT_DIM]], &[&[0.3; 4]]).unwrap();
        let a: Vec<f32> = (0..6 * 16).map(|i| (i as f32 * 0.37).sin()).collect();
        let mut b = a.clone();
        b[5 * 16..].iter_mut().for_each(|v| *v += 1.0);
        let run = |x: Vec<f32>| {
            let x = Tensor::from_vec(x, (1, 6, 16), &Device::Cpu).unwrap();
            trunk.forward(&condition, None, &x, true).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap()
        };
        let (ha, hb) = (run(a), run(b));
        // Positions before the changed last token are identical; the last one differs.
        assert_eq!(ha[..7 * 16], hb[..7 * 16]);
        assert_ne!(ha[7 * 16..], hb[7 * 16..]);
    }
}
