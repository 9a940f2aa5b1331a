//! Temporal layers over `(N, T, d)` sequences, written as one 2-D matmul each: a stride-2
//! convolution is a reshape of frame pairs plus a linear layer, a kernel-3 dilated convolution is
//! a concatenation of shifted copies plus a linear layer. Candle's conv1d would run many small
//! im2col products instead.

use crate::nn::{Linear, Params, relu};
use candle_core::{D, Result, Tensor};
use serde::{Deserialize, Serialize};

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

/// How a decoder doubles its frame rate.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum Upsampling {
    /// A transposed convolution with kernel 2, stride 2: each frame writes a pair with weights of
    /// its own for each, which invites even/odd alternation (cards from before it was recorded).
    #[default]
    Pairs,
    /// Linear interpolation to the doubled rate, then a kernel-3 convolution there: every output
    /// frame is made by the same weights from its neighbours, so none can alternate with the next.
    Interpolate,
}

/// Doubles the frame rate (see [`Upsampling`]).
#[derive(Clone)]
pub struct Upsample {
    linear: Linear,
    kind: Upsampling,
}

impl Upsample {
    /// An upsampling layer of width `dim`.
    pub fn new(params: &mut Params, name: &str, dim: usize, kind: Upsampling) -> Result<Upsample> {
        let linear = match kind {
            Upsampling::Pairs => Linear::new(params, name, dim, 2 * dim)?,
            Upsampling::Interpolate => Linear::new(params, name, 3 * dim, dim)?,
        };
        Ok(Upsample { linear, kind })
    }

    /// `(N, T, d) -> (N, 2T, d)`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let (n, t, d) = x.dims3()?;
        match self.kind {
            Upsampling::Pairs => self.linear.forward(x)?.reshape((n, 2 * t, d)),
            Upsampling::Interpolate => {
                let h = interpolate(x)?;
                self.linear.forward(&Tensor::cat(&[&shift(&h, 1)?, &h, &shift(&h, -1)?], D::Minus1)?)
            }
        }
    }
}

/// `(N, T, d) -> (N, 2T, d)` by linear interpolation at the doubled rate (output frames sit a
/// quarter frame before and after each input frame; the ends repeat their frame).
pub fn interpolate(x: &Tensor) -> Result<Tensor> {
    let (n, t, d) = x.dims3()?;
    let previous = Tensor::cat(&[&x.narrow(1, 0, 1)?, &x.narrow(1, 0, t - 1)?], 1)?;
    let next = Tensor::cat(&[&x.narrow(1, 1, t - 1)?, &x.narrow(1, t - 1, 1)?], 1)?;
    let early = ((x * 0.75)? + (previous * 0.25)?)?;
    let late = ((x * 0.75)? + (next * 0.25)?)?;
    Tensor::stack(&[&early, &late], 2)?.reshape((n, 2 * t, d))
}

/// The sequence moved `k` frames later (earlier for negative `k`), zeros shifted in.
fn shift(x: &Tensor, k: isize) -> Result<Tensor> {
    let (n, t, d) = x.dims3()?;
    let m = k.unsigned_abs().min(t);
    let zeros = Tensor::zeros((n, m, d), x.dtype(), x.device())?;
    if k >= 0 {
        Tensor::cat(&[&zeros, &x.narrow(1, 0, t - m)?], 1)
    } else {
        Tensor::cat(&[&x.narrow(1, m, t - m)?, &zeros], 1)
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

#[cfg(test)]
mod upsampling_tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn interpolation_doubles_the_rate_without_alternating() {
        let x = Tensor::new(&[[[0f32], [4.0], [8.0]]], &Device::Cpu).unwrap();
        let y: Vec<f32> = interpolate(&x).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        assert_eq!(y, [0.0, 1.0, 3.0, 5.0, 7.0, 8.0]);
        // A ramp stays a ramp between the ends: equal steps, never back and forth.
        let steps: Vec<f32> = y.windows(2).map(|w| w[1] - w[0]).collect();
        assert_eq!(&steps[1..4], &[2.0, 2.0, 2.0]);
    }
}
