//! The text-motion evaluator (TMR-like, NEC appendix D): a motion encoder over TAT's encoder
//! latents (so it reads any skeleton) and a projection of the sentence embedding, trained
//! contrastively into one space. It scores generation (R-Precision, FID, MM-Dist) and gives
//! retrieval its motion embeddings.

use crate::condition::TEXT_DIM;
use crate::corpus::{Crop, TokenClip, draw_batch};
use anymo_tokenizer::nn::{Activation, FeedForward, LayerNorm, Linear, Params, TransformerLayer};
use candle_core::{D, Device, Result, Tensor};
use serde::{Deserialize, Serialize};

/// The evaluator's shape.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct EvaluatorConfig {
    /// Width of a TAT latent row.
    pub latent_dim: usize,
    /// Motion transformer width.
    pub dim: usize,
    /// Motion transformer layers.
    pub layers: usize,
    /// Attention heads.
    pub heads: usize,
    /// Feed-forward width.
    pub ff: usize,
    /// Width of the shared space.
    pub embed: usize,
    /// Longest motion in token steps (longer ones are cut).
    pub max_tokens: usize,
    /// Softmax temperature of the contrastive loss.
    pub temperature: f32,
}

impl EvaluatorConfig {
    /// The default shape over latents of `latent_dim`.
    pub fn new(latent_dim: usize) -> EvaluatorConfig {
        EvaluatorConfig {
            latent_dim,
            dim: 192,
            layers: 3,
            heads: 4,
            ff: 384,
            embed: 128,
            max_tokens: 64,
            temperature: 0.1,
        }
    }
}

/// The evaluator.
pub struct Evaluator {
    config: EvaluatorConfig,
    params: Params,
    input: Linear,
    position: Tensor,
    layers: Vec<TransformerLayer>,
    norm: LayerNorm,
    motion_out: Linear,
    text: FeedForward,
}

impl Evaluator {
    /// A fresh evaluator initialised from `seed`.
    pub fn new(config: EvaluatorConfig, seed: u64) -> Result<Evaluator> {
        let mut p = Params::new(seed);
        let input = Linear::new(&mut p, "motion/input", config.latent_dim, config.dim)?;
        let position = p.normal("motion/position", &[config.max_tokens, config.dim], 0.02)?;
        let layers = (0..config.layers)
            .map(|i| TransformerLayer::new(&mut p, &format!("motion/layer{i}"), config.dim, config.heads, config.ff))
            .collect::<Result<_>>()?;
        let norm = LayerNorm::new(&mut p, "motion/norm", config.dim)?;
        let motion_out = Linear::new(&mut p, "motion/out", config.dim, config.embed)?;
        let text =
            FeedForward::with_activation(&mut p, "text", TEXT_DIM, 2 * config.embed, config.embed, Activation::Gelu)?;
        Ok(Evaluator { config, params: p, input, position, layers, norm, motion_out, text })
    }

    /// The configuration.
    pub fn config(&self) -> &EvaluatorConfig {
        &self.config
    }

    /// The parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// The parameters, for loading.
    pub fn params_mut(&mut self) -> &mut Params {
        &mut self.params
    }

    /// Unit-length embeddings `(B, embed)` of motions given as TAT latents `(B, L, latent_dim)`
    /// (`L` at most `max_tokens`).
    pub fn embed_motion(&self, latent: &Tensor) -> Result<Tensor> {
        let (b, l, _) = latent.dims3()?;
        let x = self.input.forward(latent)?;
        let mut x = x.broadcast_add(&self.position.narrow(0, 0, l)?.unsqueeze(0)?)?;
        for layer in &self.layers {
            x = layer.forward(&x)?;
        }
        let pooled = self.norm.forward(&x)?.mean(1)?;
        debug_assert_eq!(pooled.dims(), &[b, self.config.dim]);
        unit(&self.motion_out.forward(&pooled)?)
    }

    /// Unit-length embeddings `(B, embed)` of sentence embeddings `(B, 384)`.
    pub fn embed_text(&self, text: &Tensor) -> Result<Tensor> {
        unit(&self.text.forward(text)?)
    }

    /// One motion's embedding from its latent rows (`steps x latent_dim`, cut to `max_tokens`).
    pub fn embed_one(&self, latent: &[f32]) -> Result<Vec<f32>> {
        let d = self.config.latent_dim;
        let steps = (latent.len() / d).min(self.config.max_tokens);
        let x = Tensor::from_slice(&latent[..steps * d], (1, steps, d), &Device::Cpu)?;
        self.embed_motion(&x)?.squeeze(0)?.to_vec1()
    }

    /// One sentence embedding's projection.
    pub fn embed_sentence(&self, text: &[f32]) -> Result<Vec<f32>> {
        self.embed_text(&Tensor::from_slice(text, (1, text.len()), &Device::Cpu)?)?.squeeze(0)?.to_vec1()
    }

    /// Symmetric InfoNCE over a batch of motion latents and their captions' embeddings;
    /// `same[i][j]` marks pairs where either text is also a caption of the other motion, which are
    /// not counted as negatives.
    pub fn loss(&self, latent: &Tensor, text: &Tensor, same: &[Vec<bool>]) -> Result<Tensor> {
        let m = self.embed_motion(latent)?;
        let t = self.embed_text(text)?;
        let b = same.len();
        let blocked: Vec<f32> = (0..b)
            .flat_map(|i| (0..b).map(move |j| (i, j)))
            .map(|(i, j)| if i != j && same[i][j] { -1e4 } else { 0.0 })
            .collect();
        let blocked = Tensor::from_vec(blocked, (b, b), &Device::Cpu)?;
        let logits = ((m.matmul(&t.t()?)? * (1.0 / f64::from(self.config.temperature)))? + blocked)?;
        let diagonal: Vec<u32> = (0..b as u32).collect();
        let weights = vec![1.0; b];
        let a = crate::trunk::cross_entropy(&logits, &diagonal, &weights)?;
        let c = crate::trunk::cross_entropy(&logits.t()?.contiguous()?, &diagonal, &weights)?;
        (a + c)? * 0.5
    }
}

impl Evaluator {
    /// The contrastive loss on a batch of `batch` crops drawn from `clips`.
    pub fn batch_loss(&self, clips: &[TokenClip], batch: usize, rng: &mut impl rand::Rng) -> Result<Tensor> {
        let (length, crops) = draw_batch(clips, batch, self.config.max_tokens, rng);
        let d = self.config.latent_dim;
        let mut latent = Vec::with_capacity(batch * length * d);
        let mut text = Vec::with_capacity(batch * TEXT_DIM);
        for c in &crops {
            let clip = &clips[c.clip];
            let decoded = !clip.decoded_latent.is_empty() && rng.random_bool(0.5);
            let rows = if decoded { &clip.decoded_latent } else { &clip.latent };
            latent.extend_from_slice(&rows[c.start * d..(c.start + length) * d]);
            text.extend_from_slice(&clip.text[c.caption]);
        }
        let same = not_negatives(clips, &crops);
        let latent = Tensor::from_vec(latent, (batch, length, d), &Device::Cpu)?;
        let text = Tensor::from_vec(text, (batch, TEXT_DIM), &Device::Cpu)?;
        self.loss(&latent, &text, &same)
    }
}

/// The pairs of a batch that are no negatives of each other: either crop's text is also a
/// caption of the other's clip. Templated captions ("a man walks") and their rewordings are
/// shared by many clips, and a text that describes a clip must not be pushed away from it.
fn not_negatives(clips: &[TokenClip], crops: &[Crop]) -> Vec<Vec<bool>> {
    let describes =
        |text: &Crop, motion: &Crop| clips[motion.clip].captions.contains(&clips[text.clip].captions[text.caption]);
    crops.iter().map(|a| crops.iter().map(|b| describes(a, b) || describes(b, a)).collect()).collect()
}

fn unit(x: &Tensor) -> Result<Tensor> {
    let norm = x.sqr()?.sum_keepdim(D::Minus1)?.sqrt()?.affine(1.0, 1e-8)?;
    x.broadcast_div(&norm)
}

/// Euclidean distance.
pub fn distance(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f32>().sqrt()
}

/// R-Precision top-1/2/3 (MoMask protocol): in consecutive groups of `group` pairs, how often a
/// motion's own caption ranks within the first k of the group's captions by distance. A short
/// last group is dropped.
pub fn r_precision(motions: &[Vec<f32>], texts: &[Vec<f32>], group: usize) -> [f32; 3] {
    let mut hits = [0usize; 3];
    let mut counted = 0;
    for start in (0..motions.len()).step_by(group) {
        if start + group > motions.len() {
            break;
        }
        for i in start..start + group {
            let own = distance(&motions[i], &texts[i]);
            let closer = (start..start + group).filter(|&j| j != i && distance(&motions[i], &texts[j]) < own).count();
            for (k, hit) in hits.iter_mut().enumerate() {
                *hit += usize::from(closer <= k);
            }
            counted += 1;
        }
    }
    hits.map(|h| h as f32 / counted.max(1) as f32)
}

/// Mean distance between each motion and its caption.
pub fn mm_dist(motions: &[Vec<f32>], texts: &[Vec<f32>]) -> f32 {
    motions.iter().zip(texts).map(|(m, t)| distance(m, t)).sum::<f32>() / motions.len().max(1) as f32
}

/// Fréchet distance between Gaussians fitted to two sets of embeddings.
pub fn fid(a: &[Vec<f32>], b: &[Vec<f32>]) -> f64 {
    let (mu_a, cov_a) = moments(a);
    let (mu_b, cov_b) = moments(b);
    let root_a = symmetric_sqrt(&cov_a);
    let product = &root_a * &cov_b * &root_a;
    let trace_root: f64 = nalgebra::SymmetricEigen::new((&product + product.transpose()) * 0.5)
        .eigenvalues
        .iter()
        .map(|&v| v.max(0.0).sqrt())
        .sum();
    ((mu_a - mu_b).norm_squared() + cov_a.trace() + cov_b.trace() - 2.0 * trace_root).max(0.0)
}

fn moments(rows: &[Vec<f32>]) -> (nalgebra::DVector<f64>, nalgebra::DMatrix<f64>) {
    let d = rows[0].len();
    let n = rows.len() as f64;
    let m = nalgebra::DMatrix::from_fn(rows.len(), d, |i, j| f64::from(rows[i][j]));
    let mean = nalgebra::DVector::from_fn(d, |j, _| m.column(j).sum() / n);
    let centred = nalgebra::DMatrix::from_fn(rows.len(), d, |i, j| m[(i, j)] - mean[j]);
    let cov = centred.transpose() * &centred / (n - 1.0).max(1.0);
    (mean, cov)
}

fn symmetric_sqrt(m: &nalgebra::DMatrix<f64>) -> nalgebra::DMatrix<f64> {
    let eig = nalgebra::SymmetricEigen::new(m.clone());
    let roots = eig.eigenvalues.map(|v| v.max(0.0).sqrt());
    &eig.eigenvectors * nalgebra::DMatrix::from_diagonal(&roots) * eig.eigenvectors.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fid_of_a_set_with_itself_is_zero_and_a_shift_costs_its_square() {
        let a: Vec<Vec<f32>> =
            (0..50).map(|i| vec![(i as f32 * 0.7).sin(), (i as f32 * 1.3).cos(), i as f32 * 0.01]).collect();
        assert!(fid(&a, &a).abs() < 1e-6, "{}", fid(&a, &a));
        let shifted: Vec<Vec<f32>> = a.iter().map(|r| vec![r[0] + 2.0, r[1], r[2]]).collect();
        assert!((fid(&a, &shifted) - 4.0).abs() < 1e-4, "{}", fid(&a, &shifted));
    }

    #[test]
    fn a_text_that_one_clip_carries_is_no_negative_for_it() {
        let clip = |captions: &[&str]| TokenClip {
            key: String::new(),
            subject: "person".into(),
            captions: captions.iter().map(|c| c.to_string()).collect(),
            text: Vec::new(),
            skeleton: Vec::new(),
            codes: Vec::new(),
            latent: Vec::new(),
            decoded_latent: Vec::new(),
        };
        let clips = [clip(&["a man walks", "a guy strolls"]), clip(&["a man walks"]), clip(&["a man waves"])];
        let crop = |clip: usize, caption: usize| Crop { clip, start: 0, caption };
        // Clip 0 drew its rewording, which clip 1 lacks; clip 1's caption is also clip 0's.
        let same = not_negatives(&clips, &[crop(0, 1), crop(1, 0), crop(2, 0)]);
        assert_eq!(same, vec![vec![true, true, false], vec![true, true, false], vec![false, false, true]]);
    }

    #[test]
    fn r_precision_counts_ranks_within_groups() {
        // Motion i sits on caption i, except motion 1, whose own caption is the third closest.
        let texts = vec![vec![0.0, 0.0], vec![1.0, 0.0], vec![0.0, 1.0]];
        let motions = vec![vec![0.0, 0.0], vec![0.1, 0.9], vec![0.0, 1.0]];
        let r = r_precision(&motions, &texts, 3);
        assert!((r[0] - 2.0 / 3.0).abs() < 1e-6, "{r:?}");
        assert!((r[1] - 2.0 / 3.0).abs() < 1e-6, "{r:?}");
        assert_eq!(r[2], 1.0);
        assert!((mm_dist(&motions, &texts) - distance(&[0.1, 0.9], &[1.0, 0.0]) / 3.0).abs() < 1e-6);
    }

    #[test]
    fn every_parameter_learns_and_matching_pairs_lower_the_loss() {
        let config = EvaluatorConfig {
            latent_dim: 4,
            dim: 8,
            layers: 1,
            heads: 2,
            ff: 16,
            embed: 4,
            max_tokens: 6,
            temperature: 0.1,
        };
        let e = Evaluator::new(config, 2).unwrap();
        let latent =
            Tensor::from_vec((0..3 * 5 * 4).map(|i| (i as f32 * 0.3).sin()).collect(), (3, 5, 4), &Device::Cpu)
                .unwrap();
        let text =
            Tensor::from_vec((0..3 * TEXT_DIM).map(|i| (i as f32 * 0.7).cos()).collect(), (3, TEXT_DIM), &Device::Cpu)
                .unwrap();
        let same = vec![vec![false; 3]; 3];
        let loss = e.loss(&latent, &text, &same).unwrap();
        let grads = loss.backward().unwrap();
        for (name, var) in e.params().vars() {
            let g = grads.get(var.as_tensor()).map(|t| t.abs().unwrap().sum_all().unwrap().to_scalar::<f32>().unwrap());
            assert!(g.is_some_and(|v| v > 0.0), "no gradient reaches {name}");
        }
        // Marking every pair as the same caption leaves no negatives: the loss is zero.
        let all_same = vec![vec![true; 3]; 3];
        let none = e.loss(&latent, &text, &all_same).unwrap().to_scalar::<f32>().unwrap();
        assert!(none.abs() < 1e-4, "{none}");
    }
}
