//! MoMask's residual transformer: predicts RVQ layer `q` at every position from the sum of the
//! embeddings of layers `0..q`, with `q` given as a prefix token.

use crate::condition::Condition;
use crate::sampling::{Sampling, draw, guide};
use crate::trunk::{Trunk, TrunkConfig, cross_entropy};
use anymo_tokenizer::nn::{Linear, Params};
use candle_core::{Device, Result, Tensor};
use rand::{Rng, RngCore};

/// The residual transformer.
pub struct ResidualTransformer {
    trunk: Trunk,
    embeds: Vec<Tensor>,
    layer: Tensor,
    head: Linear,
    codes: usize,
}

impl ResidualTransformer {
    /// A model for `layers` RVQ layers of `codes` codes.
    pub fn new(p: &mut Params, trunk: &TrunkConfig, layers: usize, codes: usize) -> Result<ResidualTransformer> {
        p.scope("residual", |p| {
            Ok(ResidualTransformer {
                trunk: Trunk::new(p, trunk, 1)?,
                embeds: (0..layers - 1)
                    .map(|q| p.normal(&format!("embed{q}"), &[codes, trunk.dim], 0.02))
                    .collect::<Result<_>>()?,
                layer: p.normal("layer", &[layers, trunk.dim], 0.02)?,
                head: Linear::with_std(p, "head", trunk.dim, codes, true, 0.02)?,
                codes,
            })
        })
    }

    /// RVQ layers the model knows.
    pub fn layers(&self) -> usize {
        self.embeds.len() + 1
    }

    /// Logits `(B * L, codes)` of layer `q` given `codes (B, L, >= q)`.
    fn logits(&self, codes: &[Vec<Vec<u32>>], q: usize, condition: &Condition) -> Result<Tensor> {
        let (rows, l) = (codes.len(), codes[0].len());
        let dim = self.layer.dim(1)?;
        let mut x = Tensor::zeros((rows * l, dim), candle_core::DType::F32, &Device::Cpu)?;
        for (k, embed) in self.embeds.iter().enumerate().take(q) {
            let ids: Vec<u32> = codes.iter().flat_map(|row| row.iter().map(move |step| step[k])).collect();
            x = (x + embed.embedding(&Tensor::from_vec(ids, rows * l, &Device::Cpu)?)?)?;
        }
        let layer = self.layer.get(q)?.reshape((1, 1, dim))?.broadcast_as((rows, 1, dim))?.contiguous()?;
        let hidden = self.trunk.forward(condition, Some(&layer), &x.reshape((rows, l, dim))?, false)?.narrow(
            1,
            self.trunk.prefix(),
            l,
        )?;
        self.head.forward(&hidden)?.reshape((rows * l, self.codes))
    }

    /// Training loss on full codes `(B, L, layers)`: one random layer `q >= 1` per batch.
    pub fn loss(&self, codes: &[Vec<Vec<u32>>], condition: &Condition, rng: &mut dyn RngCore) -> Result<Tensor> {
        let q = rng.random_range(1..self.layers());
        let targets: Vec<u32> = codes.iter().flat_map(|row| row.iter().map(move |step| step[q])).collect();
        let n = targets.len();
        cross_entropy(&self.logits(codes, q, condition)?, &targets, &vec![1.0; n])
    }

    /// Fills layers `1..` of `codes (B, L, 1 or more)` where `known` (same shape as the result)
    /// has no code.
    pub fn sample(
        &self,
        condition: &Condition,
        base: &[Vec<u32>],
        known: &[Vec<Vec<Option<u32>>>],
        sampling: &Sampling,
        rng: &mut dyn RngCore,
    ) -> Result<Vec<Vec<Vec<u32>>>> {
        let rows = base.len();
        let mut codes: Vec<Vec<Vec<u32>>> = base.iter().map(|row| row.iter().map(|&c| vec![c]).collect()).collect();
        let both = condition.with_unconditional()?;
        for q in 1..self.layers() {
            let doubled: Vec<Vec<Vec<u32>>> = codes.iter().chain(codes.iter()).cloned().collect();
            let logits: Vec<Vec<f32>> = self.logits(&doubled, q, &both)?.to_vec2()?;
            let l = base[0].len();
            for r in 0..rows {
                for i in 0..l {
                    let token = match known.get(r).and_then(|row| row[i].get(q).copied().flatten()) {
                        Some(token) => token,
                        None => {
                            let g = guide(&logits[r * l + i], &logits[(rows + r) * l + i], sampling.guidance);
                            draw(&g, sampling, rng).0
                        }
                    };
                    codes[r][i].push(token);
                }
            }
        }
        Ok(codes)
    }
}
