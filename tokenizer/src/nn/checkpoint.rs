//! Model cards: the JSON that travels beside every shipped safetensors file and says what the
//! weights are, what data made them (and under which licences), and how well they do.

use serde::{Deserialize, Serialize};
use std::path::Path;

/// What a checkpoint is and where it came from. `C` is the configuration's type: the typed
/// struct of one kind of model where the reader knows the kind, JSON where it does not.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ModelCard<C = serde_json::Value> {
    /// Which model (`owo`, `tat`, `baseline`).
    pub model: String,
    /// The model's configuration, enough to rebuild it.
    pub config: C,
    /// The training data: manifest path, its blake3 hash, clips and skeletons used.
    pub data: DataRecord,
    /// Optimiser steps taken.
    pub steps: u64,
    /// Figures measured on the checkpoint, with the command that measured them.
    pub metrics: serde_json::Value,
    /// The command that trained it.
    pub command: String,
}

/// The data a checkpoint was trained on.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Default)]
pub struct DataRecord {
    /// The manifest or folder read.
    pub source: String,
    /// blake3 of the manifest file (empty for a folder).
    pub manifest_blake3: String,
    /// Licences of the clips used (a model inherits the strictest).
    pub licences: Vec<String>,
    /// Clips used for training.
    pub clips: usize,
    /// Distinct skeleton topologies among them.
    pub skeletons: usize,
}

/// Errors reading a model card.
#[derive(Debug, thiserror::Error)]
pub enum CardError {
    /// The file could not be read.
    #[error("cannot read model card {path}: {source}")]
    Io {
        /// The card's path.
        path: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not a model card.
    #[error("model card {path} is not valid: {source}")]
    Json {
        /// The card's path.
        path: String,
        /// The cause.
        source: serde_json::Error,
    },
}

/// Reads a model card.
pub fn load_card(path: &Path) -> Result<ModelCard, CardError> {
    let text =
        std::fs::read_to_string(path).map_err(|source| CardError::Io { path: path.display().to_string(), source })?;
    serde_json::from_str(&text).map_err(|source| CardError::Json { path: path.display().to_string(), source })
}

impl<C: Serialize> ModelCard<C> {
    /// Writes the card as pretty JSON.
    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        let text = serde_json::to_string_pretty(self).expect("a card serialises");
        std::fs::write(path, text + "\n")
    }
}
