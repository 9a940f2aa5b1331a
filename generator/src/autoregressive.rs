//! T2M-GPT's autoregressive variant: a causal transformer that predicts each first-layer token
//! from the condition and the tokens before it.

use crate::condition::Condition;
use crate::sampling::{Sampling, draw, guide};
use crate::token_model::TokenModel;
use crate::trunk::{Trunk, TrunkConfig, cross_entropy};
use anymo_tokenizer::nn::{Linear, Params};
use candle_core::{Device, Result, Tensor};
use rand::RngCore;

/// The causal transformer.
pub struct Autoregressive {
    trunk: Trunk,
    embed: Tensor,
    head: Linear,
    codes: usize,
}

impl Autoregressive {
    /// A model over `codes` codes.
    pub fn new(p: &mut Params, trunk: &TrunkConfig, codes: usize) -> Result<Autoregressive> {
        p.scope("autoregressive", |p| {
            Ok(Autoregressive {
                trunk: Trunk::new(p, trunk, 0)?,
                embed: p.normal("embed", &[codes, trunk.dim], 0.02)?,
                head: Linear::with_std(p, "head", trunk.dim, codes, true, 0.02)?,
                codes,
            })
        })
    }

    /// Logits `(B * L, codes)` predicting the `L` tokens after the condition and `ids (B, L - 1)`.
    fn logits(&self, ids: &[u32], rows: usize, l: usize, condition: &Condition) -> Result<Tensor> {
        let dim = self.embed.dim(1)?;
        let x = if l > 1 {
            let ids = Tensor::from_slice(ids, (rows * (l - 1),), &Device::Cpu)?;
            self.embed.embedding(&ids)?.reshape((rows, l - 1, dim))?
        } else {
            Tensor::zeros((rows, 0, dim), candle_core::DType::F32, &Device::Cpu)?
        };
        let hidden = self.trunk.forward(condition, None, &x, true)?.narrow(1, self.trunk.prefix() - 1, l)?;
        self.head.forward(&hidden)?.reshape((rows * l, self.codes))
    }
}

impl TokenModel for Autoregressive {
    fn loss(&self, codes: &[Vec<u32>], condition: &Condition, _rng: &mut dyn RngCore) -> Result<Tensor> {
        let (rows, l) = (codes.len(), codes[0].len());
        let inputs: Vec<u32> = codes.iter().flat_map(|row| row[..l - 1].iter().copied()).collect();
        let targets: Vec<u32> = codes.iter().flatten().copied().collect();
        cross_entropy(&self.logits(&inputs, rows, l, condition)?, &targets, &vec![1.0; rows * l])
    }

    fn sample(
        &self,
        condition: &Condition,
        known: &[Vec<Option<u32>>],
        sampling: &Sampling,
        rng: &mut dyn RngCore,
    ) -> Result<Vec<Vec<u32>>> {
        let (rows, l) = (known.len(), known[0].len());
        let both = condition.with_unconditional()?;
        let mut out: Vec<Vec<u32>> = vec![Vec::with_capacity(l); rows];
        for t in 0..l {
            if known.iter().all(|row| row[t].is_some()) {
                out.iter_mut().zip(known).for_each(|(o, k)| o.push(k[t].expect("known")));
                continue;
            }
            let ids: Vec<u32> = out.iter().flatten().copied().collect();
            let ids = [ids.clone(), ids].concat();
            let logits = self.logits(&ids, 2 * rows, t + 1, &both)?.reshape((2 * rows, t + 1, self.codes))?;
            let last: Vec<Vec<f32>> = logits.narrow(1, t, 1)?.squeeze(1)?.to_vec2()?;
            for r in 0..rows {
                let token = match known[r][t] {
                    Some(token) => token,
                    None => draw(&guide(&last[r], &last[rows + r], sampling.guidance), sampling, rng).0,
                };
                out[r].push(token);
            }
        }
        Ok(out)
    }
}
