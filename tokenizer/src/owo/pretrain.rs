//! OwO's self-supervised pretraining (NEC C.3): pairwise offset regression (geometry), lowest
//! common ancestor by query-key attention (topology), and joint-label InfoNCE (semantics), on
//! real skeletons and their synthetic variants.

use super::graph::{GLOBAL_NODE_TEXT, GraphBatch, SkeletonGraph, UNKNOWN_LABEL_TEXT};
use super::model::{Owo, OwoConfig};
use super::variants::random_variant;
use crate::nn::{FeedForward, Params};
use crate::text::{CachedEncoder, EMBEDDING_DIM, TextError};
use anymo_motion::skeleton::Skeleton;
use candle_core::{D, Device, Result, Tensor};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Pretraining settings.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct PretrainConfig {
    /// The encoder's shape.
    pub owo: OwoConfig,
    /// Optimiser steps.
    pub steps: u64,
    /// Skeletons per step.
    pub skeletons_per_step: usize,
    /// Joint pairs per skeleton for the offset and LCA heads.
    pub pairs: usize,
    /// Probability that a skeleton is replaced by a synthetic variant.
    pub variant_probability: f64,
    /// Peak learning rate (cosine decay to a tenth, after a linear warm-up).
    pub lr: f64,
    /// Warm-up steps.
    pub warmup: u64,
    /// Seed of initialisation and sampling.
    pub seed: u64,
    /// Loss weights: offset, LCA, label.
    pub weights: [f32; 3],
    /// InfoNCE temperature.
    pub temperature: f32,
    /// Probability that a joint's semantic label is hidden from the input, so the label head
    /// must infer it from the written name and the tree.
    pub hide_label: f64,
}

impl Default for PretrainConfig {
    fn default() -> Self {
        PretrainConfig {
            owo: OwoConfig::default(),
            steps: 3000,
            skeletons_per_step: 16,
            pairs: 64,
            variant_probability: 0.75,
            lr: 1e-3,
            warmup: 100,
            seed: 0,
            weights: [1.0, 1.0, 1.0],
            temperature: 0.1,
            hide_label: 0.5,
        }
    }
}

/// The three task heads.
pub struct Heads {
    geo: FeedForward,
    query: FeedForward,
    key: FeedForward,
    node: FeedForward,
    text: FeedForward,
}

impl Heads {
    /// Creates the heads under `heads/`.
    pub fn new(params: &mut Params, dim: usize) -> Result<Heads> {
        params.scope("heads", |p| {
            Ok(Heads {
                geo: FeedForward::new(p, "geo", 2 * dim, dim, 3)?,
                query: FeedForward::new(p, "lca_query", dim, dim, dim)?,
                key: FeedForward::new(p, "lca_key", dim, dim, dim)?,
                node: FeedForward::new(p, "sem_node", dim, dim, dim)?,
                text: FeedForward::new(p, "sem_text", EMBEDDING_DIM, dim, dim)?,
            })
        })
    }
}

/// Per-skeleton supervision derived from the graphs.
pub struct Targets {
    /// Global node indices of the pair members, and each pair's skeleton.
    pairs_a: Vec<u32>,
    pairs_b: Vec<u32>,
    /// `(pairs, 3)`: rest offset from a to b.
    offsets: Vec<f32>,
    /// Local index of each pair's LCA.
    lca: Vec<u32>,
    /// `(nodes_without_globals, EMBEDDING_DIM)`: each joint's label embedding.
    label_text: Vec<f32>,
    /// Joint indices (global node numbering) of all joints, without global nodes.
    joint_nodes: Vec<u32>,
    /// Label text of each joint, in the same order.
    labels: Vec<String>,
}

impl Targets {
    /// Samples `pairs` joint pairs per skeleton (all pairs when `pairs` is `None`).
    pub fn new(graphs: &[&SkeletonGraph], batch: &GraphBatch, pairs: Option<usize>, rng: &mut impl Rng) -> Targets {
        let mut t = Targets {
            pairs_a: Vec::new(),
            pairs_b: Vec::new(),
            offsets: Vec::new(),
            lca: Vec::new(),
            label_text: Vec::new(),
            joint_nodes: Vec::new(),
            labels: Vec::new(),
        };
        for (g, &(start, joints)) in graphs.iter().zip(&batch.ranges) {
            let rest = g.rest_positions();
            let list: Vec<(usize, usize)> = match pairs {
                Some(n) => (0..n).map(|_| (rng.random_range(0..joints), rng.random_range(0..joints))).collect(),
                None => (0..joints).flat_map(|a| (0..joints).map(move |b| (a, b))).filter(|(a, b)| a < b).collect(),
            };
            for (a, b) in list {
                t.pairs_a.push((start + a) as u32);
                t.pairs_b.push((start + b) as u32);
                t.offsets.extend((rest[b] - rest[a]).to_array());
                t.lca.push(g.lca(a, b) as u32);
            }
            for j in 0..joints {
                t.joint_nodes.push((start + j) as u32);
                let k = j * 2 * EMBEDDING_DIM + EMBEDDING_DIM;
                t.label_text.extend_from_slice(&g.node_text[k..k + EMBEDDING_DIM]);
                t.labels.push(g.labels[j].clone());
            }
        }
        t
    }
}

/// Losses and head accuracies of one batch.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct HeadScores {
    /// Mean offset error, in skeleton diameters.
    pub offset_error: f32,
    /// Top-1 accuracy of the LCA head.
    pub lca_accuracy: f32,
    /// Top-1 accuracy of retrieving each joint's label among its skeleton's labels.
    pub label_accuracy: f32,
}

/// The losses (offset, LCA, label) as tensors, and the scores as numbers.
pub fn losses(
    owo: &Owo,
    heads: &Heads,
    batch: &GraphBatch,
    targets: &Targets,
    temperature: f32,
) -> Result<([Tensor; 3], HeadScores)> {
    let device = Device::Cpu;
    let h = owo.forward(batch)?;
    let n_pairs = targets.pairs_a.len();
    let a = Tensor::from_slice(&targets.pairs_a, n_pairs, &device)?;
    let b = Tensor::from_slice(&targets.pairs_b, n_pairs, &device)?;
    let (ha, hb) = (h.index_select(&a, 0)?, h.index_select(&b, 0)?);
    // Geometry: the offset from a to b (eq. 13-14).
    let predicted = heads.geo.forward(&Tensor::cat(&[&ha, &hb], D::Minus1)?)?;
    let truth = Tensor::from_slice(&targets.offsets, (n_pairs, 3), &device)?;
    let diff = (&predicted - &truth)?;
    let geo_loss = diff.sqr()?.sum(1)?.mean_all()?;
    let offset_error = diff.sqr()?.sum(1)?.sqrt()?.mean_all()?.to_scalar::<f32>()?;
    // Topology: LCA by query-key attention over the pair's skeleton (eq. 15-18).
    let queries = heads.query.forward(&(&ha + &hb)?)?;
    let keys = heads.key.forward(&h)?;
    let max_joints = batch.ranges.iter().map(|r| r.1).max().unwrap_or(1);
    let mut key_index = Vec::new();
    let mut key_mask = Vec::new();
    let mut pair_skeleton = Vec::with_capacity(n_pairs);
    for (s, &(start, joints)) in batch.ranges.iter().enumerate() {
        for j in 0..max_joints {
            key_index.push((start + j.min(joints - 1)) as u32);
            key_mask.push(if j < joints { 0.0f32 } else { -1e9 });
        }
        let pairs_here =
            targets.pairs_a.iter().filter(|&&p| (p as usize) >= start && (p as usize) < start + joints).count();
        pair_skeleton.extend(std::iter::repeat_n(s as u32, pairs_here));
    }
    let skeletons = batch.ranges.len();
    let key_index = Tensor::from_vec(key_index, skeletons * max_joints, &device)?;
    let keys = keys.index_select(&key_index, 0)?.reshape((skeletons, max_joints, ()))?;
    let mask = Tensor::from_vec(key_mask, (skeletons, max_joints), &device)?;
    let ps = Tensor::from_vec(pair_skeleton, n_pairs, &device)?;
    let pair_keys = keys.index_select(&ps, 0)?;
    let logits = queries.unsqueeze(1)?.matmul(&pair_keys.transpose(1, 2)?)?.squeeze(1)?;
    let logits = (logits + mask.index_select(&ps, 0)?)?;
    let lca = Tensor::from_slice(&targets.lca, n_pairs, &device)?;
    let lca_loss = candle_nn::loss::cross_entropy(&logits, &lca)?;
    let chosen: Vec<u32> = logits.argmax(1)?.to_vec1()?;
    let lca_accuracy = chosen.iter().zip(&targets.lca).filter(|(a, b)| a == b).count() as f32 / n_pairs.max(1) as f32;
    // Semantics: InfoNCE between node and label embeddings (eq. 19-21); joints sharing a label
    // text are all positives.
    let m = targets.joint_nodes.len();
    let nodes = Tensor::from_slice(&targets.joint_nodes, m, &device)?;
    let z_node = normalise(&heads.node.forward(&h.index_select(&nodes, 0)?)?)?;
    let text = Tensor::from_slice(&targets.label_text, (m, EMBEDDING_DIM), &device)?;
    let z_text = normalise(&heads.text.forward(&text)?)?;
    let sim = (z_node.matmul(&z_text.t()?)? / temperature as f64)?;
    let mut positives = vec![0f32; m * m];
    for i in 0..m {
        let same: Vec<usize> = (0..m).filter(|&k| targets.labels[k] == targets.labels[i]).collect();
        for &k in &same {
            positives[i * m + k] = 1.0 / same.len() as f32;
        }
    }
    let positives = Tensor::from_vec(positives, (m, m), &device)?;
    let sem_loss = (candle_nn::ops::log_softmax(&sim, 1)? * positives)?.sum_all()?.neg()? / m as f64;
    let label_accuracy = label_retrieval(&sim, batch, targets)?;
    Ok(([geo_loss, lca_loss, sem_loss?], HeadScores { offset_error, lca_accuracy, label_accuracy }))
}

fn normalise(x: &Tensor) -> Result<Tensor> {
    x.broadcast_div(&(x.sqr()?.sum_keepdim(D::Minus1)? + 1e-12)?.sqrt()?)
}

/// Top-1 label retrieval within each joint's own skeleton.
fn label_retrieval(sim: &Tensor, batch: &GraphBatch, targets: &Targets) -> Result<f32> {
    let sim: Vec<Vec<f32>> = sim.to_vec2()?;
    let mut offset = 0;
    let (mut right, mut total) = (0usize, 0usize);
    for &(_, joints) in &batch.ranges {
        for (i, row) in sim.iter().enumerate().skip(offset).take(joints) {
            let best =
                (offset..offset + joints).max_by(|&a, &b| row[a].total_cmp(&row[b])).expect("a skeleton has joints");
            right += usize::from(targets.labels[best] == targets.labels[i]);
            total += 1;
        }
        offset += joints;
    }
    Ok(right as f32 / total.max(1) as f32)
}

/// Everything pretraining needs: the model, its heads, the skeletons and the text cache.
pub struct Pretrainer {
    /// Parameters of OwO and the heads.
    pub params: Params,
    /// The encoder being trained.
    pub owo: Owo,
    heads: Heads,
    config: PretrainConfig,
    skeletons: Vec<Skeleton>,
    global_text: Vec<f32>,
    unknown_text: Vec<f32>,
}

impl Pretrainer {
    /// A fresh model over the given training skeletons (diameter-normalised or not).
    pub fn new(
        config: PretrainConfig,
        skeletons: Vec<Skeleton>,
        encoder: &mut CachedEncoder,
    ) -> std::result::Result<Pretrainer, PretrainError> {
        let mut params = Params::new(config.seed);
        let owo = Owo::new(&mut params, config.owo)?;
        let heads = Heads::new(&mut params, config.owo.dim)?;
        let global_text = encoder.encode(&[GLOBAL_NODE_TEXT])?.remove(0);
        let unknown_text = encoder.encode(&[UNKNOWN_LABEL_TEXT])?.remove(0);
        Ok(Pretrainer { params, owo, heads, config, skeletons, global_text, unknown_text })
    }

    /// The losses of training step `step` (its sample depends only on the seed and the step).
    pub fn step_losses(
        &self,
        step: u64,
        encoder: &mut CachedEncoder,
    ) -> std::result::Result<(Tensor, [f32; 3], HeadScores), PretrainError> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.config.seed.wrapping_mul(0x9E37_79B9).wrapping_add(step));
        let mut graphs = Vec::with_capacity(self.config.skeletons_per_step);
        for _ in 0..self.config.skeletons_per_step {
            let base = &self.skeletons[rng.random_range(0..self.skeletons.len())];
            let s = if rng.random_bool(self.config.variant_probability) {
                random_variant(base, &mut rng)
            } else {
                base.clone()
            };
            let mut g = SkeletonGraph::new(&s, encoder)?;
            let hidden: Vec<bool> = (0..g.joints()).map(|_| rng.random_bool(self.config.hide_label)).collect();
            g.hide_labels(&self.unknown_text, |j| hidden[j]);
            graphs.push(g);
        }
        let refs: Vec<&SkeletonGraph> = graphs.iter().collect();
        let batch = GraphBatch::new(&refs, &self.global_text, self.config.owo.freqs)?;
        let targets = Targets::new(&refs, &batch, Some(self.config.pairs), &mut rng);
        let (parts, scores) = losses(&self.owo, &self.heads, &batch, &targets, self.config.temperature)?;
        let w = self.config.weights;
        let total = (((&parts[0] * w[0] as f64)? + (&parts[1] * w[1] as f64)?)? + (&parts[2] * w[2] as f64)?)?;
        let values = [parts[0].to_scalar::<f32>()?, parts[1].to_scalar::<f32>()?, parts[2].to_scalar::<f32>()?];
        Ok((total, values, scores))
    }

    /// Head accuracies on whole skeletons (every joint pair), e.g. the zero-shot ones. With
    /// `hide_labels`, every label is hidden from the input, so label retrieval measures what OwO
    /// infers from written names and structure alone.
    pub fn evaluate(
        &self,
        skeletons: &[Skeleton],
        hide_labels: bool,
        encoder: &mut CachedEncoder,
    ) -> std::result::Result<HeadScores, PretrainError> {
        let mut graphs: Vec<SkeletonGraph> =
            skeletons.iter().map(|s| SkeletonGraph::new(s, encoder)).collect::<std::result::Result<_, _>>()?;
        if hide_labels {
            for g in &mut graphs {
                g.hide_labels(&self.unknown_text, |_| true);
            }
        }
        let mut sum = HeadScores::default();
        for g in &graphs {
            let batch = GraphBatch::new(&[g], &self.global_text, self.config.owo.freqs)?;
            let targets = Targets::new(&[g], &batch, None, &mut ChaCha8Rng::seed_from_u64(0));
            let (_, s) = losses(&self.owo, &self.heads, &batch, &targets, self.config.temperature)?;
            sum.offset_error += s.offset_error;
            sum.lca_accuracy += s.lca_accuracy;
            sum.label_accuracy += s.label_accuracy;
        }
        let n = graphs.len().max(1) as f32;
        Ok(HeadScores {
            offset_error: sum.offset_error / n,
            lca_accuracy: sum.lca_accuracy / n,
            label_accuracy: sum.label_accuracy / n,
        })
    }

    /// The learning rate at `step`: linear warm-up, then cosine decay to a tenth.
    pub fn learning_rate(&self, step: u64) -> f64 {
        schedule(self.config.lr, self.config.warmup, self.config.steps, step)
    }
}

/// Linear warm-up over `warmup` steps, then cosine decay from `peak` to `peak / 10` at `total`.
pub fn schedule(peak: f64, warmup: u64, total: u64, step: u64) -> f64 {
    if step < warmup {
        return peak * (step + 1) as f64 / warmup as f64;
    }
    let progress = ((step - warmup) as f64 / (total.saturating_sub(warmup)).max(1) as f64).min(1.0);
    peak * (0.1 + 0.9 * 0.5 * (1.0 + (std::f64::consts::PI * progress).cos()))
}

/// Why pretraining failed.
#[derive(Debug, thiserror::Error)]
pub enum PretrainError {
    /// A tensor operation failed.
    #[error(transparent)]
    Tensor(#[from] candle_core::Error),
    /// The sentence encoder failed.
    #[error(transparent)]
    Text(#[from] TextError),
}
