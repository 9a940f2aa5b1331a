//! ReLU with its backward pass as one operation each way. candle's backward of `relu` builds a
//! zero tensor, compares, converts the mask to floats and multiplies: four passes over the
//! activation, on every ReLU of a TAT step.

use super::cpu::values;
use candle_core::{CpuStorage, CustomOp1, CustomOp2, Layout, Result, Shape, Tensor};

/// `max(x, 0)` (f32), whose gradient passes where `x >= 0`, as candle's does.
pub fn relu(x: &Tensor) -> Result<Tensor> {
    x.contiguous()?.apply_op1(Relu)
}

struct Relu;

impl CustomOp1 for Relu {
    fn name(&self) -> &'static str {
        "anymo-relu"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = values(storage, layout, self.name())?;
        Ok((CpuStorage::F32(x.iter().map(|v| v.max(0.0)).collect()), layout.shape().clone()))
    }

    fn bwd(&self, x: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        Ok(Some(x.apply_op2_no_bwd(&grad.contiguous()?, &ReluGradient)?))
    }
}

/// `(x, dy) -> dy where x >= 0, else 0`.
struct ReluGradient;

impl CustomOp2 for ReluGradient {
    fn name(&self) -> &'static str {
        "anymo-relu-backward"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (x, dy) = (values(s1, l1, self.name())?, values(s2, l2, self.name())?);
        let dx = x.iter().zip(dy).map(|(x, dy)| if *x >= 0.0 { *dy } else { 0.0 }).collect();
        Ok((CpuStorage::F32(dx), l1.shape().clone()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    #[test]
    fn values_and_gradients_equal_candles_relu() {
        let v = vec![-2.0f32, -0.0, 0.0, 0.5, 3.0, -1e-9];
        let x = Var::from_vec(v, (2, 3), &Device::Cpu).unwrap();
        let weights = Tensor::new(&[[1.0f32, 2.0, 3.0], [4.0, 5.0, 6.0]], &Device::Cpu).unwrap();
        let ours = relu(x.as_tensor()).unwrap();
        let theirs = x.as_tensor().relu().unwrap();
        assert_eq!(ours.to_vec2::<f32>().unwrap(), theirs.to_vec2::<f32>().unwrap());
        let grad = |y: &Tensor| {
            let grads = (y * &weights).unwrap().sum_all().unwrap().backward().unwrap();
            grads.get(&x).unwrap().to_vec2::<f32>().unwrap()
        };
        assert_eq!(grad(&ours), grad(&theirs));
        assert_eq!(grad(&ours), vec![vec![0.0, 2.0, 3.0], vec![4.0, 5.0, 0.0]]);
    }
}
