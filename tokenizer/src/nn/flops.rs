//! A count of the multiply-add work done by matmuls, so a benchmark can state a training step's
//! achieved FLOP/s against the machine's own dense matmul rate.

use candle_core::{DType, Device, Result, Tensor};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

static MATMUL_FLOPS: AtomicU64 = AtomicU64::new(0);

/// Records one `(m x k) @ (k x n)` product, `batch` times.
pub fn record(batch: usize, m: usize, k: usize, n: usize) {
    MATMUL_FLOPS.fetch_add((2 * batch * m * k * n) as u64, Ordering::Relaxed);
}

/// The FLOPs recorded since the last call, and a reset.
pub fn take() -> u64 {
    MATMUL_FLOPS.swap(0, Ordering::Relaxed)
}

/// This machine's dense matmul rate in FLOP/s through candle, with the threads the caller runs
/// with: a 1024x1024 f32 product, the mean of 20 after one to warm up. Benchmarks state their
/// achieved rate against it, measured in the same run.
pub fn dense_matmul_rate() -> Result<f64> {
    let n = 1024;
    let a = Tensor::ones((n, n), DType::F32, &Device::Cpu)?;
    let b = Tensor::ones((n, n), DType::F32, &Device::Cpu)?;
    a.matmul(&b)?;
    let reps = 20;
    let t = Instant::now();
    for _ in 0..reps {
        a.matmul(&b)?;
    }
    Ok((2 * n * n * n * reps) as f64 / t.elapsed().as_secs_f64())
}
