//! MoMask's masked transformer over the first RVQ layer: trained to fill randomly masked
//! positions (cosine-scheduled ratio), sampled by iterative parallel decoding that commits the
//! most confident tokens first.

use crate::condition::Condition;
use crate::sampling::{Sampling, draw, guide, still_masked, training_mask_ratio};
use crate::token_model::TokenModel;
use crate::trunk::{Trunk, TrunkConfig, cross_entropy};
use anymo_tokenizer::nn::{Linear, Params};
use candle_core::{Device, Result, Tensor};
use rand::seq::SliceRandom;
use rand::{Rng, RngCore};

/// The masked transformer.
pub struct MaskedTransformer {
    trunk: Trunk,
    embed: Tensor,
    head: Linear,
    codes: usize,
    steps: usize,
}

impl MaskedTransformer {
    /// A model over `codes` codes that decodes in `steps` iterations.
    pub fn new(p: &mut Params, trunk: &TrunkConfig, codes: usize, steps: usize) -> Result<MaskedTransformer> {
        p.scope("masked", |p| {
            Ok(MaskedTransformer {
                trunk: Trunk::new(p, trunk, 0)?,
                // One extra row: the mask token.
                embed: p.normal("embed", &[codes + 1, trunk.dim], 0.02)?,
                head: Linear::with_std(p, "head", trunk.dim, codes, true, 0.02)?,
                codes,
                steps,
            })
        })
    }

    fn mask_id(&self) -> u32 {
        self.codes as u32
    }

    /// Logits `(B * L, codes)` for token ids `(B, L)`.
    fn logits(&self, ids: &[u32], rows: usize, condition: &Condition) -> Result<Tensor> {
        let l = ids.len() / rows;
        let ids = Tensor::from_slice(ids, (rows, l), &Device::Cpu)?;
        let x = self.embed.embedding(&ids.flatten_all()?)?.reshape((rows, l, ()))?;
        let hidden = self.trunk.forward(condition, None, &x, false)?.narrow(1, self.trunk.prefix(), l)?;
        self.head.forward(&hidden)?.reshape((rows * l, self.codes))
    }
}

impl TokenModel for MaskedTransformer {
    fn loss(&self, codes: &[Vec<u32>], condition: &Condition, rng: &mut dyn RngCore) -> Result<Tensor> {
        let (rows, l) = (codes.len(), codes[0].len());
        let mut ids = Vec::with_capacity(rows * l);
        let mut weight = vec![0f32; rows * l];
        for (r, row) in codes.iter().enumerate() {
            let masked = ((training_mask_ratio(rng.random()) * l as f32).ceil() as usize).clamp(1, l);
            let mut order: Vec<usize> = (0..l).collect();
            order.shuffle(rng);
            let mut input = row.clone();
            for &i in &order[..masked] {
                weight[r * l + i] = 1.0;
                // BERT's corruption: mostly the mask token, sometimes a random code or the truth.
                let u: f32 = rng.random();
                if u < 0.8 {
                    input[i] = self.mask_id();
                } else if u < 0.9 {
                    input[i] = rng.random_range(0..self.codes as u32);
                }
            }
            ids.extend(input);
        }
        let targets: Vec<u32> = codes.iter().flatten().copied().collect();
        cross_entropy(&self.logits(&ids, rows, condition)?, &targets, &weight)
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
        let mut state: Vec<Vec<Option<u32>>> = known.to_vec();
        let unknown: Vec<usize> = known.iter().map(|row| row.iter().filter(|t| t.is_none()).count()).collect();
        for step in 0..self.steps {
            if state.iter().all(|row| row.iter().all(Option::is_some)) {
                break;
            }
            let ids: Vec<u32> = state.iter().flatten().map(|t| t.unwrap_or(self.mask_id())).collect();
            let ids = [ids.clone(), ids].concat();
            let logits: Vec<Vec<f32>> = self.logits(&ids, 2 * rows, &both)?.to_vec2()?;
            for (r, row) in state.iter_mut().enumerate() {
                let mut drawn: Vec<(usize, u32, f32)> = Vec::new();
                for (i, slot) in row.iter().enumerate() {
                    if slot.is_none() {
                        let g = guide(&logits[r * l + i], &logits[(rows + r) * l + i], sampling.guidance);
                        let (token, p) = draw(&g, sampling, rng);
                        // Gumbel-perturbed confidence, annealed to none by the last step.
                        let noise = -(-(rng.random::<f32>().max(1e-9)).ln()).ln();
                        let anneal = sampling.temperature * (1.0 - (step + 1) as f32 / self.steps as f32);
                        drawn.push((i, token, p.max(1e-12).ln() + anneal * noise));
                    }
                }
                let keep_masked = if step + 1 == self.steps { 0 } else { still_masked(unknown[r], step, self.steps) };
                let commit = drawn.len().saturating_sub(keep_masked);
                drawn.sort_by(|a, b| b.2.total_cmp(&a.2));
                for &(i, token, _) in &drawn[..commit] {
                    row[i] = Some(token);
                }
            }
        }
        Ok(state
            .into_iter()
            .map(|row| row.into_iter().map(|t| t.expect("every position is decided")).collect())
            .collect())
    }
}
