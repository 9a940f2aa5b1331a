//! Layer normalisation over the last dimension, as one fused operation with its own backward
//! pass. candle's fused layer norm has no backward pass, and its composite one
//! (`layer_norm_slow`) is a dozen graph nodes over the whole activation: candle's backward gives
//! each node a zeroed buffer and an add, and sums the gain's and bias's gradients over the rows
//! with an index division per element.

use super::cpu::values;
use super::params::Params;
use candle_core::{CpuStorage, CustomOp3, Layout, Result, Shape, Tensor};

const EPS: f32 = 1e-5;

/// Layer normalisation with a learned gain and bias, starting as the identity normalisation.
#[derive(Clone)]
pub struct LayerNorm {
    gain: Tensor,
    bias: Tensor,
}

impl LayerNorm {
    /// A layer norm over `dim` features.
    pub fn new(params: &mut Params, name: &str, dim: usize) -> Result<LayerNorm> {
        params
            .scope(name, |p| Ok(LayerNorm { gain: p.constant("g", &[dim], 1.0)?, bias: p.constant("b", &[dim], 0.0)? }))
    }

    /// Normalises the last dimension of `x` (f32).
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        x.contiguous()?.apply_op3(&self.gain, &self.bias, Normalise)
    }
}

/// Writes the normalised row `x̂` of `x` and returns `1 / sqrt(var + eps)`.
fn normalise_row(x: &[f32], normed: &mut [f32]) -> f32 {
    let d = x.len() as f32;
    let mean = x.iter().sum::<f32>() / d;
    normed.iter_mut().zip(x).for_each(|(n, v)| *n = v - mean);
    let variance = normed.iter().map(|c| c * c).sum::<f32>() / d;
    let inverse = 1.0 / (variance + EPS).sqrt();
    normed.iter_mut().for_each(|n| *n *= inverse);
    inverse
}

/// `(x, gain, bias) -> x̂ gain + bias`.
struct Normalise;

impl CustomOp3 for Normalise {
    fn name(&self) -> &'static str {
        "anymo-layer-norm"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (x, gain, bias) =
            (values(s1, l1, self.name())?, values(s2, l2, self.name())?, values(s3, l3, self.name())?);
        let d = gain.len();
        let mut out = vec![0f32; x.len()];
        for (row, y) in x.chunks_exact(d).zip(out.chunks_exact_mut(d)) {
            normalise_row(row, y);
            y.iter_mut().zip(gain.iter().zip(bias)).for_each(|(v, (g, b))| *v = *v * g + b);
        }
        Ok((CpuStorage::F32(out), l1.shape().clone()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        gain: &Tensor,
        _bias: &Tensor,
        _res: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let d = gain.elem_count();
        let rows = x.elem_count() / d;
        let all = x.apply_op3_no_bwd(gain, &grad.contiguous()?, &Gradients)?;
        let dx = all.narrow(0, 0, rows)?.reshape(x.shape())?;
        Ok((Some(dx), Some(all.get(rows)?), Some(all.get(rows + 1)?)))
    }
}

/// `(x, gain, dy) -> (rows + 2, d)`: the gradient of `x` by rows, then of the gain and the bias.
struct Gradients;

impl CustomOp3 for Gradients {
    fn name(&self) -> &'static str {
        "anymo-layer-norm-backward"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let (x, gain, dy) = (values(s1, l1, self.name())?, values(s2, l2, self.name())?, values(s3, l3, self.name())?);
        let d = gain.len();
        let rows = x.len() / d;
        let mut out = vec![0f32; (rows + 2) * d];
        let (dx, params) = out.split_at_mut(rows * d);
        let (mut dgain, mut dbias) = (vec![0f64; d], vec![0f64; d]);
        let (mut normed, mut dnormed) = (vec![0f32; d], vec![0f32; d]);
        for ((row, dy), dx) in x.chunks_exact(d).zip(dy.chunks_exact(d)).zip(dx.chunks_exact_mut(d)) {
            let inverse = normalise_row(row, &mut normed);
            for k in 0..d {
                dnormed[k] = dy[k] * gain[k];
                dgain[k] += f64::from(dy[k] * normed[k]);
                dbias[k] += f64::from(dy[k]);
            }
            let mean = dnormed.iter().sum::<f32>() / d as f32;
            let projection = dnormed.iter().zip(&normed).map(|(g, n)| g * n).sum::<f32>() / d as f32;
            for k in 0..d {
                dx[k] = inverse * (dnormed[k] - mean - normed[k] * projection);
            }
        }
        let (pg, pb) = params.split_at_mut(d);
        pg.iter_mut().zip(&dgain).for_each(|(p, g)| *p = *g as f32);
        pb.iter_mut().zip(&dbias).for_each(|(p, b)| *p = *b as f32);
        Ok((CpuStorage::F32(out), Shape::from((rows + 2, d))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};
    use rand::{Rng, SeedableRng};

    fn random(shape: &[usize], rng: &mut impl Rng) -> Var {
        let n = shape.iter().product();
        let v: Vec<f32> = (0..n).map(|_| rng.random_range(-2.0..2.0)).collect();
        Var::from_vec(v, shape, &Device::Cpu).unwrap()
    }

    fn close(a: &Tensor, b: &Tensor, what: &str) {
        let (a, b): (Vec<f32>, Vec<f32>) =
            (a.flatten_all().unwrap().to_vec1().unwrap(), b.flatten_all().unwrap().to_vec1().unwrap());
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() <= 1e-4 * (1.0 + y.abs()), "{what}: {x} vs {y}");
        }
    }

    #[test]
    fn values_and_gradients_match_candles_composite_layer_norm() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let (x, gain, bias) = (random(&[3, 5, 16], &mut rng), random(&[16], &mut rng), random(&[16], &mut rng));
        let weights = random(&[3, 5, 16], &mut rng);
        let fused = x.as_tensor().apply_op3(gain.as_tensor(), bias.as_tensor(), Normalise).unwrap();
        let composite =
            candle_nn::ops::layer_norm_slow(x.as_tensor(), gain.as_tensor(), bias.as_tensor(), EPS).unwrap();
        close(&fused, &composite, "values");
        let loss = |y: &Tensor| (y * weights.as_tensor()).unwrap().sum_all().unwrap().backward().unwrap();
        let (gf, gc) = (loss(&fused), loss(&composite));
        for (var, what) in [(&x, "x"), (&gain, "gain"), (&bias, "bias")] {
            close(gf.get(var).unwrap(), gc.get(var).unwrap(), what);
        }
    }

    #[test]
    fn a_constant_row_normalises_to_the_bias() {
        let x = Tensor::new(&[[2.0f32, 2.0, 2.0, 2.0]], &Device::Cpu).unwrap();
        let gain = Tensor::new(&[3.0f32, 3.0, 3.0, 3.0], &Device::Cpu).unwrap();
        let bias = Tensor::new(&[0.5f32, -1.0, 0.0, 7.0], &Device::Cpu).unwrap();
        let y = x.apply_op3(&gain, &bias, Normalise).unwrap();
        assert_eq!(y.to_vec2::<f32>().unwrap(), vec![vec![0.5, -1.0, 0.0, 7.0]]);
    }
}
