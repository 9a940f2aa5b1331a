//! Adding a bias to every row, as one operation whose backward pass sums the gradient's columns
//! in one pass. As a broadcast add, candle's backward sums over the rows with an index division
//! per element (15% of a TAT training step, by `perf record` of
//! `cargo bench -p anymo-tokenizer --bench train_step`).

use super::cpu::values;
use candle_core::{CpuStorage, CustomOp1, CustomOp2, Layout, Result, Shape, Tensor};

/// `x (..., d) + bias (d)`.
pub fn add_bias(x: &Tensor, bias: &Tensor) -> Result<Tensor> {
    x.contiguous()?.apply_op2(bias, AddBias)
}

struct AddBias;

impl CustomOp2 for AddBias {
    fn name(&self) -> &'static str {
        "anymo-add-bias"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (x, bias) = (values(s1, l1, self.name())?, values(s2, l2, self.name())?);
        let mut out = x.to_vec();
        for row in out.chunks_exact_mut(bias.len()) {
            row.iter_mut().zip(bias).for_each(|(v, b)| *v += b);
        }
        Ok((CpuStorage::F32(out), l1.shape().clone()))
    }

    fn bwd(&self, x: &Tensor, bias: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let grad = grad.contiguous()?;
        let sums = grad.apply_op1_no_bwd(&ColumnSums { width: bias.elem_count() })?;
        Ok((Some(grad.reshape(x.shape())?), Some(sums)))
    }
}

/// The sums of the columns of rows `width` wide.
struct ColumnSums {
    width: usize,
}

impl CustomOp1 for ColumnSums {
    fn name(&self) -> &'static str {
        "anymo-column-sums"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = values(storage, layout, self.name())?;
        let mut sums = vec![0f32; self.width];
        for row in x.chunks_exact(self.width) {
            sums.iter_mut().zip(row).for_each(|(s, v)| *s += v);
        }
        Ok((CpuStorage::F32(sums), Shape::from(self.width)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    #[test]
    fn adds_the_bias_and_sums_its_gradient() {
        let x = Var::from_vec((0..12).map(|v| v as f32).collect(), (2, 2, 3), &Device::Cpu).unwrap();
        let bias = Var::from_vec(vec![0.5f32, -1.0, 2.0], 3, &Device::Cpu).unwrap();
        let y = add_bias(x.as_tensor(), bias.as_tensor()).unwrap();
        let expected = x.as_tensor().broadcast_add(bias.as_tensor()).unwrap();
        assert_eq!(y.to_vec3::<f32>().unwrap(), expected.to_vec3::<f32>().unwrap());
        let weights = Tensor::arange(1f32, 13.0, &Device::Cpu).unwrap().reshape((2, 2, 3)).unwrap();
        let grads = (y * &weights).unwrap().sum_all().unwrap().backward().unwrap();
        assert_eq!(grads.get(&bias).unwrap().to_vec1::<f32>().unwrap(), vec![22.0, 26.0, 30.0]);
        assert_eq!(grads.get(&x).unwrap().to_vec3::<f32>().unwrap(), weights.to_vec3::<f32>().unwrap());
    }
}
