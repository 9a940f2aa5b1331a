//! A count of the multiply-add work done by matmuls, so a benchmark can state a training step's
//! achieved FLOP/s against the machine's own dense matmul rate.

use std::sync::atomic::{AtomicU64, Ordering};

static MATMUL_FLOPS: AtomicU64 = AtomicU64::new(0);

/// Records one `(m x k) @ (k x n)` product, `batch` times.
pub fn record(batch: usize, m: usize, k: usize, n: usize) {
    MATMUL_FLOPS.fetch_add((2 * batch * m * k * n) as u64, Ordering::Relaxed);
}

/// The FLOPs recorded since the last call, and a reset.
pub fn take() -> u64 {
    MATMUL_FLOPS.swap(0, Ordering::Relaxed)
}
