//! An int8 copy of every vector with error bounds, so that an exact top-k search reads a
//! quarter of the bytes: a scan over the codes gives each vector's dot product with the query
//! to within a proven bound, and only vectors whose upper bound reaches the k-th best lower
//! bound are scored in f32. At 50k clips the f32 vectors are 128 MB a query against 19 MB of
//! codes, which is why the codes pay.
//!
//! With `v̂ = scale_v * code_v` and `q̂` likewise,
//! `|q·v - q̂·v̂| <= |q| |v - v̂| + |q - q̂| |v̂|`, plus a margin for f32 rounding of the exact
//! score it stands for.

/// Codes and bounds of one row set.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Sketch {
    dim: usize,
    codes: Vec<i8>,
    /// Per row: scale, |v|, |v - v̂|, |v̂|.
    rows: Vec<[f32; 4]>,
}

/// A query's codes and norms.
pub(crate) struct QuerySketch {
    codes: Vec<i8>,
    scale: f32,
    norm: f32,
    residual: f32,
}

fn norm(v: impl Iterator<Item = f32>) -> f32 {
    v.map(|x| x * x).sum::<f32>().sqrt()
}

/// Codes of `v`, its scale, and the norms of `v`, of `v - v̂` and of `v̂`.
fn quantise(v: &[f32]) -> (Vec<i8>, [f32; 4]) {
    let max = v.iter().fold(0f32, |m, x| m.max(x.abs()));
    let scale = if max > 0.0 { max / 127.0 } else { 1.0 };
    let codes: Vec<i8> = v.iter().map(|x| (x / scale).round().clamp(-127.0, 127.0) as i8).collect();
    let approx = || codes.iter().map(|&c| f32::from(c) * scale);
    let residual = norm(v.iter().zip(approx()).map(|(x, a)| x - a));
    let row = [scale, norm(v.iter().copied()), residual, norm(approx())];
    (codes, row)
}

/// Integer dot product in 32 lanes (integer sums reassociate freely, so this vectorises into
/// several independent AVX2 accumulators). Always inlined, so that it is compiled for the
/// instruction set of the scan that calls it (`vector::FirstPass`).
#[inline(always)]
fn dot_i8(a: &[i8], b: &[i8]) -> i32 {
    let mut lanes = [0i32; 32];
    let (ca, cb) = (a.chunks_exact(32), b.chunks_exact(32));
    let tail: i32 = ca.remainder().iter().zip(cb.remainder()).map(|(&x, &y)| i32::from(x) * i32::from(y)).sum();
    for (x, y) in ca.zip(cb) {
        for i in 0..32 {
            lanes[i] += i32::from(x[i]) * i32::from(y[i]);
        }
    }
    lanes.iter().sum::<i32>() + tail
}

impl Sketch {
    pub(crate) fn new(dim: usize) -> Sketch {
        Sketch { dim, codes: Vec::new(), rows: Vec::new() }
    }

    pub(crate) fn push(&mut self, v: &[f32]) {
        let (codes, row) = quantise(v);
        self.codes.extend_from_slice(&codes);
        self.rows.push(row);
    }

    pub(crate) fn set(&mut self, slot: usize, v: &[f32]) {
        let (codes, row) = quantise(v);
        self.codes[slot * self.dim..(slot + 1) * self.dim].copy_from_slice(&codes);
        self.rows[slot] = row;
    }

    /// Moves the last row into `slot` and drops the last.
    pub(crate) fn swap_remove(&mut self, slot: usize) {
        let last = self.rows.len() - 1;
        let d = self.dim;
        self.codes.copy_within(last * d..(last + 1) * d, slot * d);
        self.codes.truncate(last * d);
        self.rows.swap_remove(slot);
    }

    pub(crate) fn query(&self, q: &[f32]) -> QuerySketch {
        let (codes, [scale, norm, residual, _]) = quantise(q);
        QuerySketch { codes, scale, norm, residual }
    }

    /// Lower and upper bounds of the f32 dot product of the query with row `slot`.
    #[inline(always)]
    pub(crate) fn bounds(&self, slot: usize, q: &QuerySketch) -> (f32, f32) {
        let [scale, v_norm, v_residual, v_approx] = self.rows[slot];
        let codes = &self.codes[slot * self.dim..(slot + 1) * self.dim];
        let approx = dot_i8(codes, &q.codes) as f32 * scale * q.scale;
        // Rounding of the f32 dot product and of the bound's own arithmetic.
        let rounding = (self.dim as f32 + 8.0) * 2.5e-7 * q.norm * v_norm + 1e-30;
        let error = q.norm * v_residual + q.residual * v_approx + rounding + approx.abs() * 1e-6;
        (approx - error, approx + error)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn the_bounds_hold(
            v in proptest::collection::vec(-1.0f32..1.0, 1..70),
            q in proptest::collection::vec(-1.0f32..1.0, 70),
            scale in prop_oneof![Just(1.0f32), Just(1e-3), Just(50.0)],
        ) {
            let v: Vec<f32> = v.iter().map(|x| x * scale).collect();
            let q = &q[..v.len()];
            let mut sketch = Sketch::new(v.len());
            sketch.push(&v);
            let (low, high) = sketch.bounds(0, &sketch.query(q));
            let exact: f64 = v.iter().zip(q).map(|(a, b)| f64::from(*a) * f64::from(*b)).sum();
            prop_assert!(f64::from(low) <= exact && exact <= f64::from(high), "{low} <= {exact} <= {high}");
            prop_assert!(high - low <= 0.05 * scale * v.len() as f32);
        }
    }

    #[test]
    fn rows_follow_set_and_swap_remove() {
        let mut sketch = Sketch::new(2);
        sketch.push(&[1.0, 0.0]);
        sketch.push(&[0.0, 1.0]);
        sketch.push(&[0.6, 0.8]);
        sketch.set(0, &[-1.0, 0.0]);
        sketch.swap_remove(1);
        let q = sketch.query(&[1.0, 0.0]);
        let (low, high) = sketch.bounds(0, &q);
        assert!(low <= -1.0 && -1.0 <= high && high - low < 0.02);
        let (low, high) = sketch.bounds(1, &q);
        assert!(low <= 0.6 && 0.6 <= high);
        assert_eq!(sketch.rows.len(), 2);
        assert_eq!(sketch.codes.len(), 4);
    }
}
