//! Layers with a backward pass for every parameter, shaped for few large matmuls.

use super::bias::add_bias;
use super::layer_norm::LayerNorm;
use super::params::Params;
use super::relu::relu;
use super::softmax::softmax_with_backward;
use candle_core::{Result, Tensor};

/// `y = x W + b` over the last dimension. Inputs of any rank are flattened to one 2-D matmul.
#[derive(Clone)]
pub struct Linear {
    weight: Tensor,
    bias: Option<Tensor>,
    out: usize,
}

impl Linear {
    /// A layer from `input` to `output` features, weights ~ N(0, 1/input).
    pub fn new(params: &mut Params, name: &str, input: usize, output: usize) -> Result<Linear> {
        Self::with_bias(params, name, input, output, true)
    }

    /// A layer with or without a bias.
    pub fn with_bias(params: &mut Params, name: &str, input: usize, output: usize, bias: bool) -> Result<Linear> {
        Self::with_std(params, name, input, output, bias, (1.0 / input as f32).sqrt())
    }

    /// A layer whose weights start at N(0, std²): a small `std` makes an output head start near
    /// zero, so early losses measure the data, not the initialisation.
    pub fn with_std(
        params: &mut Params,
        name: &str,
        input: usize,
        output: usize,
        bias: bool,
        std: f32,
    ) -> Result<Linear> {
        params.scope(name, |p| {
            let weight = p.normal("w", &[input, output], std)?;
            let bias = if bias { Some(p.constant("b", &[output], 0.0)?) } else { None };
            Ok(Linear { weight, bias, out: output })
        })
    }

    /// Applies the layer to the last dimension of `x`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let mut dims = x.dims().to_vec();
        let input = *dims.last().expect("at least one dimension");
        let rows = x.elem_count() / input;
        super::flops::record(1, rows, input, self.out);
        let y = x.reshape((rows, input))?.matmul(&self.weight)?;
        let y = match &self.bias {
            Some(b) => add_bias(&y, b)?,
            None => y,
        };
        *dims.last_mut().expect("at least one dimension") = self.out;
        y.reshape(dims)
    }
}

/// The non-linearity between the layers of a [`FeedForward`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Activation {
    /// GELU (tanh approximation): smooth, but its forward and backward cost about a tenth of a
    /// tokenizer training step on the CPU.
    Gelu,
    /// ReLU: cheap.
    Relu,
}

/// Two linear layers with an activation between them.
#[derive(Clone)]
pub struct FeedForward {
    up: Linear,
    down: Linear,
    activation: Activation,
}

impl FeedForward {
    /// `dim -> hidden -> output` with GELU.
    pub fn new(params: &mut Params, name: &str, dim: usize, hidden: usize, output: usize) -> Result<FeedForward> {
        Self::with_activation(params, name, dim, hidden, output, Activation::Gelu)
    }

    /// `dim -> hidden -> output` with the given activation.
    pub fn with_activation(
        params: &mut Params,
        name: &str,
        dim: usize,
        hidden: usize,
        output: usize,
        activation: Activation,
    ) -> Result<FeedForward> {
        params.scope(name, |p| {
            Ok(FeedForward {
                up: Linear::new(p, "up", dim, hidden)?,
                down: Linear::new(p, "down", hidden, output)?,
                activation,
            })
        })
    }

    /// Applies both layers.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let h = self.up.forward(x)?;
        let h = match self.activation {
            Activation::Gelu => h.gelu()?,
            Activation::Relu => relu(&h)?,
        };
        self.down.forward(&h)
    }
}

/// Multi-head self-attention over sequences `(N, L, dim)`.
#[derive(Clone)]
pub struct Attention {
    qkv: Linear,
    out: Linear,
    heads: usize,
}

impl Attention {
    /// Attention with `heads` heads of `dim / heads` features.
    pub fn new(params: &mut Params, name: &str, dim: usize, heads: usize) -> Result<Attention> {
        assert_eq!(dim % heads, 0, "{dim} features do not split into {heads} heads");
        params.scope(name, |p| {
            Ok(Attention { qkv: Linear::new(p, "qkv", dim, 3 * dim)?, out: Linear::new(p, "out", dim, dim)?, heads })
        })
    }

    /// Every position attends to every position of its own sequence.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.forward_masked(x, None)
    }

    /// Attention where `mask (L, L)`, added to the scores, blocks pairs with `-inf` (a causal
    /// mask for autoregressive models).
    pub fn forward_masked(&self, x: &Tensor, mask: Option<&Tensor>) -> Result<Tensor> {
        let (n, l, dim) = x.dims3()?;
        let head = dim / self.heads;
        let qkv = self.qkv.forward(x)?.reshape((n, l, 3, self.heads, head))?.permute((2, 0, 3, 1, 4))?;
        let q = qkv.get(0)?.contiguous()?.reshape((n * self.heads, l, head))?;
        let k = qkv.get(1)?.contiguous()?.reshape((n * self.heads, l, head))?;
        let v = qkv.get(2)?.contiguous()?.reshape((n * self.heads, l, head))?;
        super::flops::record(2 * n * self.heads, l, head, l);
        let mut scores = (q.matmul(&k.t()?)? * (1.0 / (head as f64).sqrt()))?;
        if let Some(mask) = mask {
            scores = scores.broadcast_add(mask)?;
        }
        let weights = softmax_with_backward(&scores)?;
        let mixed = weights.matmul(&v)?.reshape((n, self.heads, l, head))?.transpose(1, 2)?.reshape((n, l, dim))?;
        self.out.forward(&mixed)
    }
}

/// A pre-norm transformer encoder layer: `x + attn(LN x)`, then `x + ff(LN x)`.
#[derive(Clone)]
pub struct TransformerLayer {
    norm1: LayerNorm,
    attention: Attention,
    norm2: LayerNorm,
    ff: FeedForward,
}

impl TransformerLayer {
    /// A layer of width `dim` with `heads` heads and a feed-forward of `hidden` features.
    pub fn new(params: &mut Params, name: &str, dim: usize, heads: usize, hidden: usize) -> Result<TransformerLayer> {
        params.scope(name, |p| {
            Ok(TransformerLayer {
                norm1: LayerNorm::new(p, "norm1", dim)?,
                attention: Attention::new(p, "attn", dim, heads)?,
                norm2: LayerNorm::new(p, "norm2", dim)?,
                ff: FeedForward::with_activation(p, "ff", dim, hidden, dim, Activation::Relu)?,
            })
        })
    }

    /// Applies the layer to `(N, L, dim)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.forward_masked(x, None)
    }

    /// Applies the layer with an attention mask (see [`Attention::forward_masked`]).
    pub fn forward_masked(&self, x: &Tensor, mask: Option<&Tensor>) -> Result<Tensor> {
        let x = (x + self.attention.forward_masked(&self.norm1.forward(x)?, mask)?)?;
        &x + self.ff.forward(&self.norm2.forward(&x)?)?
    }
}
