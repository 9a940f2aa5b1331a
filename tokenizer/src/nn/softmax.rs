//! Softmax over the last dimension with a backward pass, as one operation each way. candle's
//! fused `softmax_last_dim` has no backward pass, and its composite `softmax` is five graph nodes
//! over every attention score (max, subtract, exp, sum, divide), each of which candle's backward
//! gives a zeroed buffer and an add.

use super::cpu::values;
use candle_core::{CpuStorage, CustomOp1, CustomOp2, Layout, Result, Shape, Tensor};

/// Softmax over the last dimension of `x` (f32).
pub fn softmax_with_backward(x: &Tensor) -> Result<Tensor> {
    x.contiguous()?.apply_op1(Softmax)
}

struct Softmax;

impl CustomOp1 for Softmax {
    fn name(&self) -> &'static str {
        "anymo-softmax"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = values(storage, layout, self.name())?;
        let width = *layout.dims().last().unwrap_or(&1);
        let mut out = vec![0f32; x.len()];
        for (row, y) in x.chunks_exact(width).zip(out.chunks_exact_mut(width)) {
            let max = row.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let mut total = 0.0;
            for (y, v) in y.iter_mut().zip(row) {
                // A row that is all -inf (fully masked) gives zeros, not NaN.
                *y = if max == f32::NEG_INFINITY { 0.0 } else { (v - max).exp() };
                total += *y;
            }
            if total > 0.0 {
                y.iter_mut().for_each(|y| *y /= total);
            }
        }
        Ok((CpuStorage::F32(out), layout.shape().clone()))
    }

    fn bwd(&self, _x: &Tensor, res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(res.apply_op2_no_bwd(&grad.contiguous()?, &SoftmaxGradient)?))
    }
}

/// `(y, dy) -> y (dy - sum(dy y))` by rows: the gradient of the input of a softmax.
struct SoftmaxGradient;

impl CustomOp2 for SoftmaxGradient {
    fn name(&self) -> &'static str {
        "anymo-softmax-backward"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (y, dy) = (values(s1, l1, self.name())?, values(s2, l2, self.name())?);
        let width = *l1.dims().last().unwrap_or(&1);
        let mut out = vec![0f32; y.len()];
        for ((y, dy), dx) in y.chunks_exact(width).zip(dy.chunks_exact(width)).zip(out.chunks_exact_mut(width)) {
            let dot: f32 = y.iter().zip(dy).map(|(a, b)| a * b).sum();
            dx.iter_mut().zip(y.iter().zip(dy)).for_each(|(dx, (y, dy))| *dx = y * (dy - dot));
        }
        Ok((CpuStorage::F32(out), l1.shape().clone()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{D, Device, Var};
    use rand::{Rng, SeedableRng};

    #[test]
    fn values_and_gradients_match_candles_composite_softmax() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let v: Vec<f32> = (0..4 * 3 * 7).map(|_| rng.random_range(-4.0..4.0)).collect();
        let w: Vec<f32> = (0..4 * 3 * 7).map(|_| rng.random_range(-1.0..1.0)).collect();
        let x = Var::from_vec(v, (4, 3, 7), &Device::Cpu).unwrap();
        let weights = Tensor::from_vec(w, (4, 3, 7), &Device::Cpu).unwrap();
        let fused = softmax_with_backward(x.as_tensor()).unwrap();
        let composite = candle_nn::ops::softmax(x.as_tensor(), D::Minus1).unwrap();
        let loss = |y: &Tensor| (y * &weights).unwrap().sum_all().unwrap().backward().unwrap();
        let pairs = [
            (fused.clone(), composite.clone()),
            (loss(&fused).get(&x).unwrap().clone(), loss(&composite).get(&x).unwrap().clone()),
        ];
        for (a, b) in pairs {
            let (a, b): (Vec<f32>, Vec<f32>) =
                (a.flatten_all().unwrap().to_vec1().unwrap(), b.flatten_all().unwrap().to_vec1().unwrap());
            for (p, q) in a.iter().zip(&b) {
                assert!((p - q).abs() < 1e-6, "{p} vs {q}");
            }
        }
    }

    #[test]
    fn rows_sum_to_one_and_masked_entries_get_nothing() {
        let x = Tensor::new(&[[0.0f32, f32::NEG_INFINITY, 1.0], [f32::NEG_INFINITY; 3]], &Device::Cpu).unwrap();
        let y = softmax_with_backward(&x).unwrap().to_vec2::<f32>().unwrap();
        let e = 1f32.exp();
        assert_eq!(y[0], vec![1.0 / (1.0 + e), 0.0, e / (1.0 + e)]);
        assert_eq!(y[1], vec![0.0; 3]);
    }
}
