//! The two trainable motion codecs behind one trait: TAT (OwO-conditioned, virtual-joint RVQ)
//! and the zero-padded RVQ-VAE baseline of NEC Table 1.

use super::model::{Decoder, Encoder, Fusion, OUTPUT_DIMS, TatConfig};
use super::objective::{LossWeights, Prediction, Prepared, RootStats};
use super::representation::Representation;
use super::rvq::{Rvq, RvqConfig};
use super::temporal::{Downsample, ResBlock, Upsample, Upsampling};
use crate::nn::{LayerNorm, Linear, Params};
use crate::owo::graph::{GraphBatch, SkeletonGraph, sinusoidal};
use crate::owo::{Owo, OwoConfig};
use anymo_motion::features::ROT_DIMS;
use candle_core::{D, Device, Result, Tensor};

use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// A codec's output for a batch: the prediction, the commitment loss and the tokens.
pub struct Reconstruction {
    /// The decoded motion.
    pub prediction: Prediction,
    /// RVQ commitment loss.
    pub commitment: Tensor,
    /// `(B * T', layers)` codes.
    pub codes: Vec<Vec<u32>>,
}

/// What every codec trains and saves: its parameters, its quantiser, and what its loss reads.
pub struct Trained {
    params: Params,
    rvq: Rvq,
    root: RootStats,
    weights: LossWeights,
}

/// A trainable motion tokenizer.
pub trait Codec {
    /// Encodes, quantises and decodes a batch of one skeleton (`graph` names its joints).
    fn reconstruct(
        &mut self,
        batch: &Prepared,
        graph: &SkeletonGraph,
        training: bool,
        rng: &mut dyn rand::RngCore,
    ) -> Result<Reconstruction>;
    /// The trained state.
    fn trained(&self) -> &Trained;
    /// The trained state, mutable.
    fn trained_mut(&mut self) -> &mut Trained;
    /// The trainable parameters (with buffers such as codebooks).
    fn params(&self) -> &Params {
        &self.trained().params
    }
    /// Mutable access, for loading.
    fn params_mut(&mut self) -> &mut Params {
        &mut self.trained_mut().params
    }
    /// Copies non-gradient state (codebooks) into the parameter buffers before saving.
    fn sync_buffers(&mut self) -> Result<()> {
        let t = self.trained_mut();
        t.rvq.save_into(&mut t.params, "rvq")
    }
    /// Restores non-gradient state from the tensors loading the parameters left over.
    fn restore_buffers(&mut self, tensors: &HashMap<String, Tensor>) -> Result<()> {
        self.trained_mut().rvq.load_from(tensors, "rvq")
    }
    /// Root statistics the codec normalises with.
    fn root_stats(&self) -> &RootStats {
        &self.trained().root
    }
    /// Loss weights.
    fn weights(&self) -> &LossWeights {
        &self.trained().weights
    }
}

/// Everything that defines a TAT checkpoint.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TokenizerConfig {
    /// Encoder/decoder shape.
    pub tat: TatConfig,
    /// Quantiser.
    pub rvq: RvqConfig,
    /// The frozen skeleton encoder's shape.
    pub owo: OwoConfig,
    /// Sinusoidal frequencies of the rest offset in the joint condition.
    pub offset_freqs: usize,
    /// Frames per window.
    pub window: usize,
    /// Frames shared by consecutive windows.
    pub overlap: usize,
    /// Root feature statistics.
    pub root: RootStats,
    /// Loss weights.
    pub weights: LossWeights,
    /// The joint frames motion is read in (cards from before it was recorded: the rig's own).
    #[serde(default)]
    pub representation: Representation,
}

impl TokenizerConfig {
    /// The default shape for given root statistics, fusion and representation.
    pub fn new(root: RootStats, fusion: Fusion, representation: Representation) -> TokenizerConfig {
        let owo = OwoConfig::default();
        let offset_freqs = 4;
        TokenizerConfig {
            tat: TatConfig {
                dim: 128,
                heads: 4,
                ff: 256,
                blocks: 1,
                spatial_layers: 2,
                condition_dim: owo.dim + 6 * offset_freqs,
                fusion,
                upsampling: Upsampling::Interpolate,
            },
            rvq: RvqConfig::default(),
            owo,
            offset_freqs,
            window: 64,
            overlap: 16,
            root,
            weights: LossWeights::default(),
            representation,
        }
    }
}

/// TAT: the topology-agnostic tokenizer with its frozen OwO.
pub struct Tat {
    config: TokenizerConfig,
    trained: Trained,
    encoder: Encoder,
    decoder: Decoder,
    owo: Owo,
    global_text: Vec<f32>,
}

impl Tat {
    /// A fresh TAT over a frozen OwO (`owo_params` holds its weights, pretrained or not).
    pub fn new(config: TokenizerConfig, seed: u64, owo_params: &mut Params, global_text: Vec<f32>) -> Result<Tat> {
        let owo = Owo::new(owo_params, config.owo)?;
        let mut params = Params::new(seed);
        let encoder = Encoder::new(&mut params, &config.tat, config.rvq.dim)?;
        let decoder = Decoder::new(&mut params, &config.tat, config.rvq.dim)?;
        let rvq = Rvq::new(config.rvq);
        let trained = Trained { params, rvq, root: config.root, weights: config.weights };
        Ok(Tat { config, trained, encoder, decoder, owo, global_text })
    }

    /// The configuration.
    pub fn config(&self) -> &TokenizerConfig {
        &self.config
    }

    /// The per-joint condition `(B, J, c)`: OwO embeddings of each window's skeleton (its own,
    /// possibly augmented, rest offsets) beside sinusoidal features of those offsets.
    pub fn condition(&self, graph: &SkeletonGraph, offsets: &Tensor) -> Result<Tensor> {
        let (b, j, _) = offsets.dims3()?;
        let rows: Vec<Vec<Vec<f32>>> = offsets.to_vec3()?;
        let mut graphs = Vec::with_capacity(b);
        let mut waves = Vec::with_capacity(b * j * 6 * self.config.offset_freqs);
        for window in &rows {
            let mut g = graph.clone();
            g.offsets = window.iter().map(|o| glam::Vec3::new(o[0], o[1], o[2])).collect();
            for o in &g.offsets {
                sinusoidal(*o, self.config.offset_freqs, &mut waves);
            }
            graphs.push(g);
        }
        let refs: Vec<&SkeletonGraph> = graphs.iter().collect();
        let batch = GraphBatch::new(&refs, &self.global_text, self.config.owo.freqs)?;
        let embedded = self.owo.embed(&batch)?;
        let joints = Tensor::stack(&embedded.iter().map(|e| e.joints.clone()).collect::<Vec<_>>(), 0)?;
        let waves = Tensor::from_vec(waves, (b, j, 6 * self.config.offset_freqs), &Device::Cpu)?;
        Tensor::cat(&[&joints, &waves], D::Minus1)
    }

    /// Codes `(B * T', layers)` of prepared windows.
    pub fn encode(&mut self, input: &Tensor, condition: &Tensor) -> Result<Vec<Vec<u32>>> {
        Ok(self.encode_with_latent(input, condition)?.1)
    }

    /// The encoder's output before quantisation `(B, T', dim)` and the codes `(B * T', layers)`.
    pub fn encode_with_latent(&mut self, input: &Tensor, condition: &Tensor) -> Result<(Tensor, Vec<Vec<u32>>)> {
        let latent = self.encoder.forward(input, condition)?;
        let (b, t, c) = latent.dims3()?;
        let q = self.trained.rvq.forward(&latent.reshape((b * t, c))?, false, &mut rand::rng())?;
        Ok((latent, q.codes))
    }

    /// OwO's global embedding of a skeleton: what the generator is conditioned on.
    pub fn skeleton_embedding(&self, graph: &SkeletonGraph) -> Result<Vec<f32>> {
        let batch = GraphBatch::new(&[graph], &self.global_text, self.config.owo.freqs)?;
        self.owo.embed(&batch)?.remove(0).global.to_vec1()
    }

    /// Decodes codes `(B * T', layers)` for `B` windows onto the skeleton of `condition`.
    pub fn decode(&self, codes: &[Vec<u32>], windows: usize, condition: &Tensor) -> Result<Prediction> {
        let latent = self.trained.rvq.decode(codes)?;
        let t = codes.len() / windows;
        let out = self.decoder.forward(&latent.reshape((windows, t, self.config.rvq.dim))?, condition)?;
        split_output(&out)
    }
}

/// Splits decoder output `(B, T, J, OUTPUT_DIMS)` into rotations, root (from the root joint) and
/// contact logits.
fn split_output(out: &Tensor) -> Result<Prediction> {
    debug_assert_eq!(out.dim(D::Minus1).ok(), Some(OUTPUT_DIMS));
    Ok(Prediction {
        rotations: out.narrow(D::Minus1, 0, ROT_DIMS)?,
        root: out.narrow(2, 0, 1)?.squeeze(2)?.narrow(D::Minus1, ROT_DIMS, 4)?,
        contacts: Some(out.narrow(D::Minus1, ROT_DIMS + 4, 1)?.squeeze(D::Minus1)?),
    })
}

impl Codec for Tat {
    fn reconstruct(
        &mut self,
        batch: &Prepared,
        graph: &SkeletonGraph,
        training: bool,
        rng: &mut dyn rand::RngCore,
    ) -> Result<Reconstruction> {
        let condition = self.condition(graph, &batch.offsets)?;
        let latent = self.encoder.forward(&batch.input, &condition)?;
        let (b, t, c) = latent.dims3()?;
        let q = self.trained.rvq.forward(&latent.reshape((b * t, c))?, training, rng)?;
        let out = self.decoder.forward(&q.latent.reshape((b, t, c))?, &condition)?;
        Ok(Reconstruction { prediction: split_output(&out)?, commitment: q.commitment, codes: q.codes })
    }
    fn trained(&self) -> &Trained {
        &self.trained
    }
    fn trained_mut(&mut self) -> &mut Trained {
        &mut self.trained
    }
}

/// The zero-padded RVQ-VAE baseline's shape.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct BaselineConfig {
    /// Joints every skeleton is padded to.
    pub max_joints: usize,
    /// Width of the 1-D convolutional trunk.
    pub dim: usize,
    /// Downsampling blocks.
    pub blocks: usize,
    /// How the decoder doubles its frame rate (cards from before it was recorded: pairs).
    #[serde(default)]
    pub upsampling: Upsampling,
    /// Quantiser.
    pub rvq: RvqConfig,
    /// Root statistics.
    pub root: RootStats,
    /// Loss weights.
    pub weights: LossWeights,
    /// The joint frames motion is read in (cards from before it was recorded: the rig's own).
    #[serde(default)]
    pub representation: Representation,
}

/// NEC Table 1's "RVQ-VAE (zero pad)": joints padded to the corpus maximum, flattened per frame,
/// a 1-D convolutional encoder and decoder, the same RVQ and losses as TAT.
pub struct Baseline {
    config: BaselineConfig,
    trained: Trained,
    input: Linear,
    down: Vec<(Downsample, ResBlock, ResBlock)>,
    norm: LayerNorm,
    to_code: Linear,
    from_code: Linear,
    up: Vec<(ResBlock, ResBlock, Upsample)>,
    output: Linear,
}

impl Baseline {
    /// A fresh baseline.
    pub fn new(config: BaselineConfig, seed: u64) -> Result<Baseline> {
        let mut p = Params::new(seed);
        let d = config.dim;
        let frame = config.max_joints * ROT_DIMS + 4;
        let input = Linear::new(&mut p, "input", frame, d)?;
        let down = (0..config.blocks)
            .map(|i| {
                Ok((
                    Downsample::new(&mut p, &format!("down{i}"), d)?,
                    ResBlock::new(&mut p, &format!("down{i}/res0"), d, 1)?,
                    ResBlock::new(&mut p, &format!("down{i}/res1"), d, 3)?,
                ))
            })
            .collect::<Result<_>>()?;
        let norm = LayerNorm::new(&mut p, "norm", d)?;
        let to_code = Linear::new(&mut p, "to_code", d, config.rvq.dim)?;
        let from_code = Linear::new(&mut p, "from_code", config.rvq.dim, d)?;
        let up = (0..config.blocks)
            .map(|i| {
                Ok((
                    ResBlock::new(&mut p, &format!("up{i}/res0"), d, 3)?,
                    ResBlock::new(&mut p, &format!("up{i}/res1"), d, 1)?,
                    Upsample::new(&mut p, &format!("up{i}"), d, config.upsampling)?,
                ))
            })
            .collect::<Result<_>>()?;
        let output = Linear::with_std(&mut p, "output", d, frame, true, 0.01)?;
        let rvq = Rvq::new(config.rvq);
        let trained = Trained { params: p, rvq, root: config.root, weights: config.weights };
        Ok(Baseline { config, trained, input, down, norm, to_code, from_code, up, output })
    }

    /// The configuration.
    pub fn config(&self) -> &BaselineConfig {
        &self.config
    }
}

impl Codec for Baseline {
    fn reconstruct(
        &mut self,
        batch: &Prepared,
        _graph: &SkeletonGraph,
        training: bool,
        rng: &mut dyn rand::RngCore,
    ) -> Result<Reconstruction> {
        let (b, t, j, _) = batch.rotations.dims4()?;
        let max = self.config.max_joints;
        if j > max {
            candle_core::bail!("the baseline pads to {max} joints; this skeleton has {j}");
        }
        let mut rot = batch.rotations.reshape((b, t, j * ROT_DIMS))?;
        if j < max {
            rot = Tensor::cat(
                &[&rot, &Tensor::zeros((b, t, (max - j) * ROT_DIMS), rot.dtype(), rot.device())?],
                D::Minus1,
            )?;
        }
        let x = Tensor::cat(&[&rot, &batch.root], D::Minus1)?;
        let mut h = self.input.forward(&x)?;
        for (down, r0, r1) in &self.down {
            h = r1.forward(&r0.forward(&down.forward(&h)?)?)?;
        }
        let latent = self.to_code.forward(&self.norm.forward(&h)?)?;
        let (_, tq, c) = latent.dims3()?;
        let q = self.trained.rvq.forward(&latent.reshape((b * tq, c))?, training, rng)?;
        let mut h = self.from_code.forward(&q.latent.reshape((b, tq, c))?)?;
        for (r0, r1, up) in &self.up {
            h = up.forward(&r1.forward(&r0.forward(&h)?)?)?;
        }
        let out = self.output.forward(&h)?;
        let rotations = out.narrow(D::Minus1, 0, j * ROT_DIMS)?.reshape((b, t, j, ROT_DIMS))?;
        let root = out.narrow(D::Minus1, max * ROT_DIMS, 4)?;
        Ok(Reconstruction {
            prediction: Prediction { rotations, root, contacts: None },
            commitment: q.commitment,
            codes: q.codes,
        })
    }
    fn trained(&self) -> &Trained {
        &self.trained
    }
    fn trained_mut(&mut self) -> &mut Trained {
        &mut self.trained
    }
}
