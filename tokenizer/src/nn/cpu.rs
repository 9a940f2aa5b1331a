//! The f32 values behind a CPU tensor, for the fused operations (`layer_norm`, `bias`,
//! `softmax`), which read and write whole rows in one pass.

use candle_core::backend::BackendStorage;
use candle_core::{CpuStorage, Layout, Result, bail};

/// The contiguous f32 values of a tensor's storage under `layout`.
pub(crate) fn values<'a>(storage: &'a CpuStorage, layout: &Layout, op: &str) -> Result<&'a [f32]> {
    let CpuStorage::F32(all) = storage else { bail!("{op} takes f32 tensors, not {:?}", storage.dtype()) };
    let Some((start, end)) = layout.contiguous_offsets() else { bail!("{op} takes contiguous tensors") };
    Ok(&all[start..end])
}
