//! TAT's encoder and decoder (NEC 4.3 with SATA 3.2-3.3): per-joint motion features modulated
//! by the joint's OwO embedding, spatio-temporal blocks over the joints plus one virtual joint,
//! and a decoder that broadcasts the quantised virtual joint to the target skeleton's joints.

use super::temporal::{Downsample, ResBlock, Upsample, Upsampling, interpolate};
use crate::nn::{LayerNorm, Linear, Params, TransformerLayer, relu, repeat_dim1, repeat_rows};
use candle_core::{D, Result, Tensor};
use serde::{Deserialize, Serialize};

/// How joint identity enters the motion features.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Fusion {
    /// SATA's gated FiLM: `x + sigmoid(Wg c) * (LN(x) (1 + gamma) + beta)`.
    Film,
    /// NEC's addition: `x + Proj(h)`.
    Additive,
}

/// Input features per joint: rot6D, normalised root features (root joint only), position
/// relative to the root in the heading frame, its velocity.
pub const INPUT_DIMS: usize = 6 + 4 + 3 + 3;
/// Output features per joint: rot6D, root features (read from the root joint), contact logit.
pub const OUTPUT_DIMS: usize = 6 + 4 + 1;

/// TAT's shape.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct TatConfig {
    /// Width of joint features.
    pub dim: usize,
    /// Attention heads.
    pub heads: usize,
    /// Feed-forward width of the spatial transformers.
    pub ff: usize,
    /// Spatio-temporal blocks; each halves the frame rate (after the input layer's halving).
    pub blocks: usize,
    /// Spatial transformer layers per block.
    pub spatial_layers: usize,
    /// Width of the skeleton condition (OwO embedding + sinusoidal rest offset).
    pub condition_dim: usize,
    /// How the condition enters.
    pub fusion: Fusion,
    /// How the decoder doubles its frame rate (cards from before it was recorded: pairs).
    #[serde(default)]
    pub upsampling: Upsampling,
}

impl TatConfig {
    /// Frames per token: the input layer halves the rate, then every block halves it.
    pub fn frames_per_token(&self) -> usize {
        2 << self.blocks
    }
}

/// The parts of gated FiLM (SATA eq. 2-3).
struct Film {
    norm: LayerNorm,
    scale_shift: Linear,
    gate: Linear,
}

/// Gated FiLM or additive fusion of a per-joint condition into per-joint features.
struct Modulation {
    condition: Linear,
    film: Option<Film>,
}

impl Modulation {
    fn new(p: &mut Params, name: &str, condition_dim: usize, dim: usize, fusion: Fusion) -> Result<Modulation> {
        p.scope(name, |p| {
            let film = match fusion {
                Fusion::Film => Some(Film {
                    norm: LayerNorm::new(p, "norm", dim)?,
                    scale_shift: Linear::new(p, "scale_shift", dim, 2 * dim)?,
                    gate: Linear::new(p, "gate", dim, dim)?,
                }),
                Fusion::Additive => None,
            };
            Ok(Modulation { condition: Linear::new(p, "condition", condition_dim, dim)?, film })
        })
    }

    /// `x (B, T, J, d)`, `condition (B, J, c)`. The per-window terms are repeated over time
    /// before they meet `x` (see [`repeat_dim1`]).
    fn forward(&self, x: &Tensor, condition: &Tensor) -> Result<Tensor> {
        let t = x.dim(1)?;
        let along_time = |v: &Tensor| repeat_dim1(&v.unsqueeze(1)?, t);
        let c = relu(&self.condition.forward(condition)?)?;
        match &self.film {
            None => x + along_time(&c)?,
            Some(film) => {
                let d = c.dim(D::Minus1)?;
                let ss = film.scale_shift.forward(&c)?;
                let (scale, shift) =
                    (along_time(&ss.narrow(D::Minus1, 0, d)?)?, along_time(&ss.narrow(D::Minus1, d, d)?)?);
                // candle's sigmoid is a custom op with a backward pass (unlike its fused softmax and
                // layer norm); `tokenizer/tests/training.rs` checks the gate's weights learn.
                let gate = along_time(&candle_nn::ops::sigmoid(&film.gate.forward(&c)?)?)?;
                let modulated = ((film.norm.forward(x)? * (scale + 1.0)?)? + shift)?;
                x + (modulated * gate)?
            }
        }
    }
}

/// Spatial attention over the joints of every frame: `(B, T, J, d)`.
fn spatial(layers: &[TransformerLayer], x: &Tensor) -> Result<Tensor> {
    let (b, t, j, d) = x.dims4()?;
    let mut y = x.reshape((b * t, j, d))?;
    for layer in layers {
        y = layer.forward(&y)?;
    }
    y.reshape((b, t, j, d))
}

/// Runs temporal layers on every joint's sequence: `(B, T, J, d) -> (B, T', J, d)`.
fn temporal(x: &Tensor, f: impl Fn(&Tensor) -> Result<Tensor>) -> Result<Tensor> {
    let (b, t, j, d) = x.dims4()?;
    let seq = x.transpose(1, 2)?.contiguous()?.reshape((b * j, t, d))?;
    let out = f(&seq)?;
    let t2 = out.dim(1)?;
    out.reshape((b, j, t2, d))?.transpose(1, 2)?.contiguous()
}

struct EncoderBlock {
    down: Downsample,
    res: [ResBlock; 2],
    spatial: Vec<TransformerLayer>,
}

struct DecoderBlock {
    spatial: Vec<TransformerLayer>,
    res: [ResBlock; 2],
    up: Upsample,
}

/// The encoder: motion of any skeleton -> one latent per token step (the virtual joint).
pub struct Encoder {
    input: Linear,
    modulation: Modulation,
    virtual_joint: Tensor,
    blocks: Vec<EncoderBlock>,
    norm: LayerNorm,
    output: Linear,
}

/// The decoder: latents + a target skeleton's condition -> per-joint features.
pub struct Decoder {
    latent: Linear,
    modulation: Modulation,
    blocks: Vec<DecoderBlock>,
    res: ResBlock,
    output: Linear,
    upsampling: Upsampling,
}

fn spatial_stack(p: &mut Params, c: &TatConfig) -> Result<Vec<TransformerLayer>> {
    (0..c.spatial_layers).map(|i| TransformerLayer::new(p, &format!("spatial{i}"), c.dim, c.heads, c.ff)).collect()
}

impl Encoder {
    /// Creates the encoder under `encoder/`; latents have `code_dim` features.
    pub fn new(params: &mut Params, c: &TatConfig, code_dim: usize) -> Result<Encoder> {
        params.scope("encoder", |p| {
            let blocks = (0..c.blocks)
                .map(|i| {
                    p.scope(&format!("block{i}"), |p| {
                        Ok(EncoderBlock {
                            down: Downsample::new(p, "down", c.dim)?,
                            res: [ResBlock::new(p, "res0", c.dim, 1)?, ResBlock::new(p, "res1", c.dim, 3)?],
                            spatial: spatial_stack(p, c)?,
                        })
                    })
                })
                .collect::<Result<_>>()?;
            Ok(Encoder {
                input: Linear::new(p, "input", 2 * INPUT_DIMS, c.dim)?,
                modulation: Modulation::new(p, "modulation", c.condition_dim, c.dim, c.fusion)?,
                virtual_joint: p.normal("virtual_joint", &[c.dim], 0.02)?,
                blocks,
                norm: LayerNorm::new(p, "norm", c.dim)?,
                output: Linear::new(p, "output", c.dim, code_dim)?,
            })
        })
    }

    /// `input (B, T, J, INPUT_DIMS)`, `condition (B, J, c)` -> latents `(B, T / 2^(blocks+1), code)`.
    /// The first layer reads frame pairs (a stride-2 convolution), so no full-rate feature map
    /// of the model's width is ever built.
    pub fn forward(&self, input: &Tensor, condition: &Tensor) -> Result<Tensor> {
        let (b, t, j, c) = input.dims4()?;
        let pairs = input.reshape((b, t / 2, 2, j, c))?.transpose(2, 3)?.reshape((b, t / 2, j, 2 * c))?;
        let t = t / 2;
        let x = self.modulation.forward(&self.input.forward(&pairs)?, condition)?;
        let d = x.dim(D::Minus1)?;
        let v = repeat_rows(&self.virtual_joint, b * t)?.reshape((b, t, 1, d))?;
        let mut x = Tensor::cat(&[&x, &v], 2)?;
        for block in &self.blocks {
            x = temporal(&x, |s| block.res[1].forward(&block.res[0].forward(&block.down.forward(s)?)?))?;
            x = spatial(&block.spatial, &x)?;
        }
        let j = x.dim(2)?;
        let v = x.narrow(2, j - 1, 1)?.squeeze(2)?;
        self.output.forward(&self.norm.forward(&v)?)
    }
}

impl Decoder {
    /// Creates the decoder under `decoder/`.
    pub fn new(params: &mut Params, c: &TatConfig, code_dim: usize) -> Result<Decoder> {
        params.scope("decoder", |p| {
            let blocks = (0..c.blocks)
                .map(|i| {
                    p.scope(&format!("block{i}"), |p| {
                        Ok(DecoderBlock {
                            spatial: spatial_stack(p, c)?,
                            res: [ResBlock::new(p, "res0", c.dim, 3)?, ResBlock::new(p, "res1", c.dim, 1)?],
                            up: Upsample::new(p, "up", c.dim, c.upsampling)?,
                        })
                    })
                })
                .collect::<Result<_>>()?;
            Ok(Decoder {
                latent: Linear::new(p, "latent", code_dim, c.dim)?,
                modulation: Modulation::new(p, "modulation", c.condition_dim, c.dim, c.fusion)?,
                blocks,
                res: ResBlock::new(p, "res", c.dim, 1)?,
                output: match c.upsampling {
                    Upsampling::Pairs => Linear::with_std(p, "output", c.dim, 2 * OUTPUT_DIMS, true, 0.01)?,
                    Upsampling::Interpolate => Linear::with_std(p, "output", c.dim, OUTPUT_DIMS, true, 0.01)?,
                },
                upsampling: c.upsampling,
            })
        })
    }

    /// `latent (B, T', code)`, target `condition (B, J, c)` -> `(B, T' 2^(blocks+1), J, OUTPUT_DIMS)`.
    /// The last doubling is the output layer writing frame pairs, or, when interpolating,
    /// interpolation before the last residual block and the output layer.
    pub fn forward(&self, latent: &Tensor, condition: &Tensor) -> Result<Tensor> {
        let z = self.latent.forward(latent)?.unsqueeze(2)?;
        let (b, t, _, d) = z.dims4()?;
        let joints = condition.dim(1)?;
        let per_joint = repeat_dim1(&z.reshape((b * t, 1, d))?, joints)?.reshape((b, t, joints, d))?;
        let x = self.modulation.forward(&per_joint, condition)?;
        let mut x = Tensor::cat(&[&x, &z], 2)?;
        for block in &self.blocks {
            x = spatial(&block.spatial, &x)?;
            x = temporal(&x, |s| block.up.forward(&block.res[1].forward(&block.res[0].forward(s)?)?))?;
        }
        let x = x.narrow(2, 0, joints)?;
        if self.upsampling == Upsampling::Interpolate {
            let x = temporal(&x, |s| self.res.forward(&interpolate(s)?))?;
            return self.output.forward(&x);
        }
        let x = temporal(&x, |s| self.res.forward(s))?;
        let (b, t, j, _) = x.dims4()?;
        self.output.forward(&x)?.reshape((b, t, j, 2, OUTPUT_DIMS))?.transpose(2, 3)?.reshape((
            b,
            2 * t,
            j,
            OUTPUT_DIMS,
        ))
    }
}
