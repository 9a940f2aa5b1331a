//! Temporal layers over `(N, T, d)` sequences, written as one 2-D matmul each: a stride-2
//! convolution is a reshape of frame pairs plus a linear layer, a kernel-3 dilated convolution is
//! a concatenation of shifted copies plus a linear layer. Candle's conv1d would run many small
//! im2col products instead.

use crate::nn::{Linear, Params, relu};
use candle_core::{D, Result, Tensor};

/// Halves the frame rate: kernel 2, stride 2.
#[derive(Clone)]
pub struct Downsample {
    linear: Linear,
}

impl Downsample {
    /// A downsampling layer of width `dim`.
    pub fn new(params: &mut Params, name: &str, dim: usize) -> Result<Downsample> {
        Ok(Downsample { linear: Linear::new(params, name, 2 * dim, dim)? })
    }

    /// `(N, T, d) -> (N, T / 2, d)`; `T` must be even.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (n, t, d) = x.dims3()?;
        self.linear.forward(&x.reshape((n, t / 2, 2 * d))?)
    }
}

/// Doubles the frame rate: a transposed convolution with kernel 2, stride 2.
#[derive(Clone)]
pub struct Upsample {
    linear: Linear,
}

impl Upsample {
    /// An upsampling layer of width `dim`.
    pub fn new(params: &mut Params, name: &str, dim: usize) -> Result<Upsample> {
        Ok(Upsample { linear: Linear::new(params, name, dim, 2 * dim)? })
    }

    /// `(N, T, d) -> (N, 2T, d)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (n, t, d) = x.dims3()?;
        self.linear.forward(x)?.reshape((n, 2 * t, d))
    }
}

/// A ResNet1D block: `x + W2 relu(conv3_dilated(relu x))`.
#[derive(Clone)]
pub struct ResBlock {
    conv: Linear,
    out: Linear,
    dilation: usize,
}

impl ResBlock {
    /// A block of width `dim` whose kernel-3 convolution skips `dilation` frames.
    pub fn new(params: &mut Params, name: &str, dim: usize, dilation: usize) -> Result<ResBlock> {
        params.scope(name, |p| {
            Ok(ResBlock {
                conv: Linear::new(p, "conv", 3 * dim, dim)?,
                out: Linear::new(p, "out", dim, dim)?,
                dilation,
            })
        })
    }

    /// Applies the block to `(N, T, d)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (n, t, d) = x.dims3()?;
        let h = relu(x)?;
        let k = self.dilation.min(t);
        let zeros = Tensor::zeros((n, k, d), x.dtype(), x.device())?;
        let before = Tensor::cat(&[&zeros, &h.narrow(1, 0, t - k)?], 1)?;
        let after = Tensor::cat(&[&h.narrow(1, k, t - k)?, &zeros], 1)?;
        let y = relu(&self.conv.forward(&Tensor::cat(&[&before, &h, &after], D::Minus1)?)?)?;
        x + self.out.forward(&y)?
    }
}
