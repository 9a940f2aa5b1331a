//! A training run's resumable state as one safetensors file: the parameters and buffers
//! (`params/NAME`), the optimiser's moments and step count (`optimiser/NAME`), and the loop's own
//! progress as JSON in the file's metadata. One file, so a run's state can be committed and
//! replaced as a whole, and a kill mid-write never mixes two saves: it is written beside the
//! target and renamed over it.

use super::adamw::AdamW;
use super::params::Params;
use candle_core::{Device, Tensor};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The metadata key holding the loop's progress.
const PROGRESS_KEY: &str = "progress";

/// Why a snapshot cannot be written or read.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    /// Reading or writing the file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What failed.
        source: std::io::Error,
    },
    /// The file is not a safetensors file.
    #[error("{path} is not a snapshot: {source}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What the reader said.
        source: safetensors::SafeTensorError,
    },
    /// The file holds no progress record.
    #[error("{0} holds no training progress (is it a shipped checkpoint rather than a run's state?)")]
    NoProgress(PathBuf),
    /// The tensors do not fit the model or optimiser.
    #[error("{path} does not fit this model: {source}")]
    Mismatch {
        /// The file.
        path: PathBuf,
        /// What did not fit.
        source: candle_core::Error,
    },
}

/// Writes the snapshot (atomically: a temporary file beside `path`, then a rename).
pub fn save(path: &Path, params: &Params, optimiser: &AdamW, progress: &str) -> Result<(), SnapshotError> {
    let mismatch = |source| SnapshotError::Mismatch { path: path.to_path_buf(), source };
    let mut tensors: Vec<(String, Tensor)> =
        params.tensors().into_iter().map(|(name, t)| (format!("params/{name}"), t)).collect();
    tensors
        .extend(optimiser.tensors().map_err(mismatch)?.into_iter().map(|(name, t)| (format!("optimiser/{name}"), t)));
    let tensors = tensors
        .into_iter()
        .map(|(name, t)| Ok((name, t.contiguous()?)))
        .collect::<candle_core::Result<Vec<_>>>()
        .map_err(mismatch)?;
    let metadata = HashMap::from([(PROGRESS_KEY.to_string(), progress.to_string())]);
    let tmp = path.with_extension("safetensors.tmp");
    safetensors::serialize_to_file(tensors, Some(metadata), &tmp)
        .map_err(|source| SnapshotError::Format { path: tmp.clone(), source })?;
    std::fs::rename(&tmp, path).map_err(|source| SnapshotError::Io { path: path.to_path_buf(), source })
}

/// The progress a snapshot records, or `None` when there is no file at `path`.
pub fn progress(path: &Path) -> Result<Option<String>, SnapshotError> {
    let bytes = match std::fs::read(path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(SnapshotError::Io { path: path.to_path_buf(), source }),
    };
    progress_of(path, &bytes).map(Some)
}

fn progress_of(path: &Path, bytes: &[u8]) -> Result<String, SnapshotError> {
    let (_, metadata) = safetensors::SafeTensors::read_metadata(bytes)
        .map_err(|source| SnapshotError::Format { path: path.to_path_buf(), source })?;
    metadata
        .metadata()
        .as_ref()
        .and_then(|m| m.get(PROGRESS_KEY).cloned())
        .ok_or_else(|| SnapshotError::NoProgress(path.to_path_buf()))
}

/// Restores parameters and optimiser from a snapshot; returns its progress and the buffers
/// (tensors of `params/` that are no trainable parameter, such as codebooks).
pub fn load(
    path: &Path,
    params: &mut Params,
    optimiser: &mut AdamW,
) -> Result<(String, HashMap<String, Tensor>), SnapshotError> {
    let bytes = std::fs::read(path).map_err(|source| SnapshotError::Io { path: path.to_path_buf(), source })?;
    let progress = progress_of(path, &bytes)?;
    let mismatch = |source| SnapshotError::Mismatch { path: path.to_path_buf(), source };
    let all = candle_core::safetensors::load_buffer(&bytes, &Device::Cpu).map_err(mismatch)?;
    let (mut model, mut moments) = (HashMap::new(), HashMap::new());
    for (name, t) in all {
        if let Some(rest) = name.strip_prefix("params/") {
            model.insert(rest.to_string(), t);
        } else if let Some(rest) = name.strip_prefix("optimiser/") {
            moments.insert(rest.to_string(), t);
        }
    }
    let buffers = params.assign(model).map_err(mismatch)?;
    optimiser.assign(&moments).map_err(mismatch)?;
    Ok((progress, buffers))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nn::AdamWConfig;

    #[test]
    fn a_snapshot_restores_parameters_buffers_moments_and_progress() {
        let dir = std::env::temp_dir().join(format!("anymo-snapshot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("state.safetensors");
        assert!(progress(&path).unwrap().is_none(), "no file, no progress");

        let mut params = Params::new(3);
        let w = params.normal("w", &[4], 1.0).unwrap();
        params.set_buffer("codebook", Tensor::new(&[7f32, 8.0], &Device::Cpu).unwrap());
        let mut optimiser = AdamW::new(&params, AdamWConfig::default()).unwrap();
        let grads = w.sqr().unwrap().sum_all().unwrap().backward().unwrap();
        optimiser.step(&params, &grads, 0.1).unwrap();
        save(&path, &params, &optimiser, r#"{"step":1}"#).unwrap();
        assert_eq!(progress(&path).unwrap().as_deref(), Some(r#"{"step":1}"#));

        let mut other = Params::new(9);
        other.normal("w", &[4], 1.0).unwrap();
        let mut restored = AdamW::new(&other, AdamWConfig::default()).unwrap();
        let (progress, buffers) = load(&path, &mut other, &mut restored).unwrap();
        assert_eq!(progress, r#"{"step":1}"#);
        assert_eq!(buffers["codebook"].to_vec1::<f32>().unwrap(), [7.0, 8.0]);
        let values = |p: &Params| p.vars().next().unwrap().1.as_tensor().to_vec1::<f32>().unwrap();
        assert_eq!(values(&other), values(&params));
        assert_eq!(restored.steps(), 1);
        let (a, b) = (optimiser.tensors().unwrap(), restored.tensors().unwrap());
        assert_eq!(a["v/w"].to_vec1::<f32>().unwrap(), b["v/w"].to_vec1::<f32>().unwrap());

        // A parameter of another shape is refused, naming the file.
        let mut wrong = Params::new(0);
        wrong.normal("w", &[5], 1.0).unwrap();
        let mut wrong_optimiser = AdamW::new(&wrong, AdamWConfig::default()).unwrap();
        let error = load(&path, &mut wrong, &mut wrong_optimiser).unwrap_err().to_string();
        assert!(error.contains("state.safetensors") && error.contains("[5]"), "{error}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
