//! Residual vector quantisation (NEC C.5) with EMA codebooks, dead-code reset and quantiser
//! dropout. Codebooks are not trained by gradients, so they live in plain memory and are updated
//! in place; they are saved as buffers beside the model's parameters.

use crate::nn::Params;
use candle_core::{Device, Result, Tensor};
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// The quantiser's shape and update rule.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct RvqConfig {
    /// Residual layers (tokens per time step).
    pub layers: usize,
    /// Codes per layer.
    pub codes: usize,
    /// Width of a code.
    pub dim: usize,
    /// EMA decay of the codebook statistics.
    pub decay: f32,
    /// A code whose EMA usage falls below this is re-seeded from the batch.
    pub dead_threshold: f32,
    /// Probability that a training step quantises with a random prefix of the layers.
    pub dropout: f64,
}

impl Default for RvqConfig {
    fn default() -> Self {
        RvqConfig { layers: 6, codes: 1024, dim: 128, decay: 0.99, dead_threshold: 0.01, dropout: 0.2 }
    }
}

/// The quantised latent and what quantising it cost.
pub struct Quantised {
    /// The sum of the chosen codes, with a straight-through gradient to the input.
    pub latent: Tensor,
    /// `(rows, layers_used)` code indices.
    pub codes: Vec<Vec<u32>>,
    /// Commitment loss: mean squared distance of each residual to its code.
    pub commitment: Tensor,
}

/// A residual quantiser.
pub struct Rvq {
    config: RvqConfig,
    codebooks: Vec<Vec<f32>>,
    usage: Vec<Vec<f32>>,
    sums: Vec<Vec<f32>>,
    initialised: bool,
}

impl Rvq {
    /// A quantiser whose codebooks are seeded from the first training batch.
    pub fn new(config: RvqConfig) -> Rvq {
        let size = config.codes * config.dim;
        Rvq {
            config,
            codebooks: vec![vec![0.0; size]; config.layers],
            usage: vec![vec![1.0; config.codes]; config.layers],
            sums: vec![vec![0.0; size]; config.layers],
            initialised: false,
        }
    }

    /// The configuration.
    pub fn config(&self) -> RvqConfig {
        self.config
    }

    /// Quantises `x (rows, dim)`. In training, codebooks follow their assignments by EMA, dead
    /// codes are re-seeded and a random prefix of layers may be used (quantiser dropout).
    pub fn forward<R: Rng + ?Sized>(&mut self, x: &Tensor, training: bool, rng: &mut R) -> Result<Quantised> {
        let (rows, dim) = x.dims2()?;
        let device = Device::Cpu;
        let mut residual = x.detach();
        if training && !self.initialised {
            self.seed_codebooks(&residual.to_vec2::<f32>()?, rng);
        }
        let used = if training && rng.random_bool(self.config.dropout) {
            rng.random_range(1..=self.config.layers)
        } else {
            self.config.layers
        };
        let mut total = Tensor::zeros((rows, dim), x.dtype(), &device)?;
        let mut codes = vec![Vec::with_capacity(used); rows];
        for layer in 0..used {
            let book = Tensor::from_slice(&self.codebooks[layer], (self.config.codes, dim), &device)?;
            let distances = book.sqr()?.sum(1)?.unsqueeze(0)?.broadcast_sub(&(residual.matmul(&book.t()?)? * 2.0)?)?;
            let chosen = distances.argmin(1)?;
            let quantised = book.index_select(&chosen, 0)?;
            let chosen: Vec<u32> = chosen.to_vec1()?;
            if training {
                self.update(layer, &residual.to_vec2::<f32>()?, &chosen, rng);
            }
            for (r, c) in chosen.iter().enumerate() {
                codes[r].push(*c);
            }
            total = (total + &quantised)?;
            residual = (residual - quantised)?;
        }
        // The commitment gradient flows to the encoder only: ||x - sg(sum of codes)||^2.
        let commit = (x - total.detach())?.sqr()?.mean_all()?;
        let latent = (x + (total - x)?.detach())?;
        Ok(Quantised { latent, codes, commitment: commit })
    }

    /// The latent for given codes (`(rows, layers)`; fewer layers use a prefix).
    pub fn decode(&self, codes: &[Vec<u32>]) -> Result<Tensor> {
        let dim = self.config.dim;
        let mut out = vec![0.0f32; codes.len() * dim];
        for (r, row) in codes.iter().enumerate() {
            for (layer, &c) in row.iter().enumerate() {
                let code = &self.codebooks[layer][c as usize * dim..(c as usize + 1) * dim];
                for (o, v) in out[r * dim..(r + 1) * dim].iter_mut().zip(code) {
                    *o += v;
                }
            }
        }
        Tensor::from_vec(out, (codes.len(), dim), &Device::Cpu)
    }

    fn seed_codebooks<R: Rng + ?Sized>(&mut self, rows: &[Vec<f32>], rng: &mut R) {
        let mut residuals: Vec<Vec<f32>> = rows.to_vec();
        for layer in 0..self.config.layers {
            for c in 0..self.config.codes {
                let src = &residuals[rng.random_range(0..residuals.len())];
                let code = &mut self.codebooks[layer][c * self.config.dim..(c + 1) * self.config.dim];
                for (v, s) in code.iter_mut().zip(src) {
                    *v = s + rng.random_range(-1e-3..1e-3f32);
                }
            }
            let sums = &mut self.sums[layer];
            sums.copy_from_slice(&self.codebooks[layer]);
            // Later layers see the residual left by a nearest code of this one.
            for r in residuals.iter_mut() {
                let best = nearest(&self.codebooks[layer], self.config.dim, r);
                let code = &self.codebooks[layer][best * self.config.dim..(best + 1) * self.config.dim];
                for (v, c) in r.iter_mut().zip(code) {
                    *v -= c;
                }
            }
        }
        self.initialised = true;
    }

    fn update<R: Rng + ?Sized>(&mut self, layer: usize, rows: &[Vec<f32>], chosen: &[u32], rng: &mut R) {
        let (k, dim, decay) = (self.config.codes, self.config.dim, self.config.decay);
        let mut counts = vec![0.0f32; k];
        let mut sums = vec![0.0f32; k * dim];
        for (row, &c) in rows.iter().zip(chosen) {
            counts[c as usize] += 1.0;
            for (s, v) in sums[c as usize * dim..(c as usize + 1) * dim].iter_mut().zip(row) {
                *s += v;
            }
        }
        let usage = &mut self.usage[layer];
        let ema_sums = &mut self.sums[layer];
        for c in 0..k {
            usage[c] = decay * usage[c] + (1.0 - decay) * counts[c];
        }
        for (e, s) in ema_sums.iter_mut().zip(&sums) {
            *e = decay * *e + (1.0 - decay) * s;
        }
        let book = &mut self.codebooks[layer];
        for c in 0..k {
            if usage[c] < self.config.dead_threshold {
                // Dead code: restart it on a random residual of this batch.
                let src = &rows[rng.random_range(0..rows.len())];
                book[c * dim..(c + 1) * dim].copy_from_slice(src);
                ema_sums[c * dim..(c + 1) * dim].copy_from_slice(src);
                usage[c] = 1.0;
            } else {
                for d in 0..dim {
                    book[c * dim + d] = ema_sums[c * dim + d] / usage[c];
                }
            }
        }
    }

    /// Stores the codebooks and their statistics as buffers of `params` under `prefix`.
    pub fn save_into(&self, params: &mut Params, prefix: &str) -> Result<()> {
        let (k, dim) = (self.config.codes, self.config.dim);
        for layer in 0..self.config.layers {
            params.set_buffer(
                &format!("{prefix}/codebook{layer}"),
                Tensor::from_slice(&self.codebooks[layer], (k, dim), &Device::Cpu)?,
            );
            params.set_buffer(
                &format!("{prefix}/usage{layer}"),
                Tensor::from_slice(&self.usage[layer], k, &Device::Cpu)?,
            );
            params.set_buffer(
                &format!("{prefix}/sums{layer}"),
                Tensor::from_slice(&self.sums[layer], (k, dim), &Device::Cpu)?,
            );
        }
        Ok(())
    }

    /// Restores what [`Rvq::save_into`] stored, from the tensors [`Params::load`] returned.
    pub fn load_from(&mut self, tensors: &HashMap<String, Tensor>, prefix: &str) -> Result<()> {
        for layer in 0..self.config.layers {
            let get = |name: &str| -> Result<Vec<f32>> {
                let key = format!("{prefix}/{name}{layer}");
                match tensors.get(&key) {
                    Some(t) => t.flatten_all()?.to_vec1(),
                    None => candle_core::bail!("the checkpoint has no {key}"),
                }
            };
            self.codebooks[layer] = get("codebook")?;
            self.usage[layer] = get("usage")?;
            self.sums[layer] = get("sums")?;
        }
        self.initialised = true;
        Ok(())
    }
}

fn nearest(book: &[f32], dim: usize, v: &[f32]) -> usize {
    book.chunks_exact(dim)
        .map(|c| c.iter().zip(v).map(|(a, b)| (a - b) * (a - b)).sum::<f32>())
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(0, |(i, _)| i)
}
