//! The OwO network: node and edge initialisation (NEC eq. C.3-C.6) and graph-attention blocks
//! with edge updates (eq. 7-12), multi-head.

use super::graph::{GraphBatch, NODE_INPUT_DIM};
use crate::nn::{FeedForward, LayerNorm, Linear, Params, relu};
use candle_core::{D, Result, Tensor};
use serde::{Deserialize, Serialize};

/// OwO's shape.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct OwoConfig {
    /// Width of node and edge features.
    pub dim: usize,
    /// Graph-attention blocks.
    pub blocks: usize,
    /// Attention heads per block.
    pub heads: usize,
    /// Sinusoidal frequencies per offset axis.
    pub freqs: usize,
}

impl Default for OwoConfig {
    fn default() -> Self {
        OwoConfig { dim: 128, blocks: 4, heads: 4, freqs: 8 }
    }
}

/// Eq. 10's edge update and its FFN; the last block has none, since nothing reads its edges.
struct EdgeUpdate {
    src: Linear,
    dst: Linear,
    ff: FeedForward,
    norm: LayerNorm,
}

struct Block {
    node: Linear,
    score: Linear,
    score_edge: Linear,
    value: Linear,
    node_ff: FeedForward,
    node_norm: LayerNorm,
    edge: Option<EdgeUpdate>,
    heads: usize,
}

impl Block {
    fn new(p: &mut Params, name: &str, dim: usize, heads: usize, updates_edges: bool) -> Result<Block> {
        p.scope(name, |p| {
            let edge = if updates_edges {
                Some(EdgeUpdate {
                    src: Linear::with_bias(p, "edge_src", dim, dim, false)?,
                    dst: Linear::with_bias(p, "edge_dst", dim, dim, false)?,
                    ff: FeedForward::new(p, "edge_ff", dim, 2 * dim, dim)?,
                    norm: LayerNorm::new(p, "edge_norm", dim)?,
                })
            } else {
                None
            };
            Ok(Block {
                node: Linear::with_bias(p, "node", dim, dim, false)?,
                score: Linear::with_bias(p, "score", dim, 2 * heads, false)?,
                score_edge: Linear::with_bias(p, "score_edge", dim, heads, false)?,
                value: Linear::new(p, "value", 2 * dim, dim)?,
                node_ff: FeedForward::new(p, "node_ff", dim, 2 * dim, dim)?,
                node_norm: LayerNorm::new(p, "node_norm", dim)?,
                edge,
                heads,
            })
        })
    }

    /// One block over nodes `(N, d)` and edges `(E, d)`.
    fn forward(&self, h: &Tensor, e: &Tensor, src: &Tensor, dst: &Tensor) -> Result<(Tensor, Tensor)> {
        let (n, d) = h.dims2()?;
        let edges = e.dim(0)?;
        let heads = self.heads;
        let wh = self.node.forward(h)?;
        // a^T [W h_j || W h_k || e_kj], split into its node and edge parts (eq. 8).
        let s = self.score.forward(&wh)?;
        let s_target = s.narrow(1, 0, heads)?.contiguous()?.index_select(dst, 0)?;
        let s_source = s.narrow(1, heads, heads)?.contiguous()?.index_select(src, 0)?;
        let scores = candle_nn::ops::leaky_relu(&((s_target + s_source)? + self.score_edge.forward(e)?)?, 0.2)?;
        // Softmax over each node's incoming edges; the shift is constant per head, so exact.
        let shift = scores.max_keepdim(0)?.detach();
        let weights = scores.broadcast_sub(&shift)?.exp()?;
        let totals = Tensor::zeros((n, heads), weights.dtype(), weights.device())?.index_add(dst, &weights, 0)?;
        let alpha = (weights / totals.index_select(dst, 0)?)?;
        // Messages W_v [h_k || e_kj] (eq. 9), weighted and summed per target (eq. 7).
        let h_source = h.index_select(src, 0)?;
        let values =
            self.value.forward(&Tensor::cat(&[&h_source, e], D::Minus1)?)?.reshape((edges, heads, d / heads))?;
        let messages = values.broadcast_mul(&alpha.unsqueeze(2)?)?.reshape((edges, d))?;
        let gathered = Tensor::zeros((n, d), h.dtype(), h.device())?.index_add(dst, &messages, 0)?;
        // FFN and residual layer norm (eq. 11-12).
        let h_next = self.node_norm.forward(&(h + relu(&self.node_ff.forward(&gathered)?)?)?)?;
        // Edge update (eq. 10), then the same FFN and norm.
        let e_next = match &self.edge {
            Some(u) => {
                let e_tilde =
                    ((e + u.src.forward(&wh.index_select(dst, 0)?)?)? + u.dst.forward(&wh.index_select(src, 0)?)?)?;
                u.norm.forward(&(&e_tilde + u.ff.forward(&e_tilde)?)?)?
            }
            None => e.clone(),
        };
        Ok((h_next, e_next))
    }
}

/// The skeleton graph encoder.
pub struct Owo {
    config: OwoConfig,
    node_init: Linear,
    edge_init: Linear,
    blocks: Vec<Block>,
}

impl Owo {
    /// Creates OwO's parameters under `owo/` in `params`.
    pub fn new(params: &mut Params, config: OwoConfig) -> Result<Owo> {
        params.scope("owo", |p| {
            let d = config.dim;
            Ok(Owo {
                config,
                node_init: Linear::new(p, "node_init", NODE_INPUT_DIM, d)?,
                edge_init: Linear::new(p, "edge_init", 2 * d + 6 * config.freqs, d)?,
                blocks: (0..config.blocks)
                    .map(|i| Block::new(p, &format!("block{i}"), d, config.heads, i + 1 < config.blocks))
                    .collect::<Result<_>>()?,
            })
        })
    }

    /// The configuration.
    pub fn config(&self) -> OwoConfig {
        self.config
    }

    /// Node embeddings `(N, dim)` for every joint and global node of the batch.
    pub fn forward(&self, batch: &GraphBatch) -> Result<Tensor> {
        let mut h = self.node_init.forward(&batch.nodes)?;
        let edge_in = Tensor::cat(
            &[&h.index_select(&batch.src, 0)?, &h.index_select(&batch.dst, 0)?, &batch.edge_offsets],
            D::Minus1,
        )?;
        let mut e = self.edge_init.forward(&edge_in)?;
        for block in &self.blocks {
            (h, e) = block.forward(&h, &e, &batch.src, &batch.dst)?;
        }
        Ok(h)
    }
}

/// One skeleton's embeddings, detached from any training graph.
#[derive(Clone, Debug)]
pub struct SkeletonEmbedding {
    /// `(joints, dim)`.
    pub joints: Tensor,
    /// `(dim,)`: the global node.
    pub global: Tensor,
}

impl Owo {
    /// Embeds skeletons one batch at a time, for frozen use downstream.
    pub fn embed(&self, batch: &GraphBatch) -> Result<Vec<SkeletonEmbedding>> {
        let h = self.forward(batch)?.detach();
        batch
            .ranges
            .iter()
            .map(|&(start, joints)| {
                Ok(SkeletonEmbedding { joints: h.narrow(0, start, joints)?, global: h.get(start + joints)? })
            })
            .collect()
    }
}
