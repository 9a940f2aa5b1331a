//! Repetition of a tensor along one dimension as a batched outer product with a column of ones.
//!
//! The values equal `broadcast_as` (the product of one 1.0 with each value is exact), but the
//! backward pass differs: candle sums the gradient of a broadcast over a leading dimension with an
//! index division per element, which was 15% of a TAT training step (`perf record` of
//! `cargo bench -p anymo-tokenizer --bench train_step`), while the gradient of this product is one
//! matrix-vector product per batch.

use candle_core::{Result, Tensor};

/// `v (B, 1, ...)` repeated `n` times along dimension 1: `(B, n, ...)`.
pub fn repeat_dim1(v: &Tensor, n: usize) -> Result<Tensor> {
    let dims = v.dims();
    assert!(dims.len() >= 2 && dims[1] == 1, "repeat_dim1 takes (B, 1, ...), not {dims:?}");
    let batch = dims[0];
    let rest: usize = dims[2..].iter().product();
    let ones = Tensor::ones((batch, n, 1), v.dtype(), v.device())?;
    let mut out = dims.to_vec();
    out[1] = n;
    ones.matmul(&v.reshape((batch, 1, rest))?)?.reshape(out)
}

/// `v (d)` repeated as every row of `(rows, d)`.
pub fn repeat_rows(v: &Tensor, rows: usize) -> Result<Tensor> {
    let d = v.elem_count();
    repeat_dim1(&v.reshape((1, 1, d))?, rows)?.reshape((rows, d))
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    #[test]
    fn repeats_exactly_and_sums_the_gradient() {
        let v = Var::from_vec(vec![0.1f32, -2.5, 3.75, 1e-7, 4.0, -0.3], (2, 1, 3), &Device::Cpu).unwrap();
        let repeated = repeat_dim1(v.as_tensor(), 4).unwrap();
        let expected = v.as_tensor().broadcast_as((2, 4, 3)).unwrap();
        assert_eq!(repeated.dims(), &[2, 4, 3]);
        assert_eq!(repeated.to_vec3::<f32>().unwrap(), expected.to_vec3::<f32>().unwrap());
        let weights = Tensor::arange(0f32, 24.0, &Device::Cpu).unwrap().reshape((2, 4, 3)).unwrap();
        let grads = (repeated * &weights).unwrap().sum_all().unwrap().backward().unwrap();
        let grad: Vec<f32> = grads.get(&v).unwrap().flatten_all().unwrap().to_vec1().unwrap();
        // d/dv_bc of sum_t w[b, t, c] v[b, c] = sum_t w[b, t, c].
        assert_eq!(grad, vec![18.0, 22.0, 26.0, 66.0, 70.0, 74.0]);
    }
}
