//! The error of the models' operations (generation, edits, tokens, transfer, search by
//! example), typed so that a caller tells a request the models refuse, which the client must
//! change, from a failure of the models themselves.

use crate::checkpoint::CheckpointError;
use anymo_tokenizer::text::TextError;

/// Why a model operation gave no result.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    /// A well-formed request the models cannot serve because of what was asked: an empty
    /// prompt, a duration out of range, a skeleton that cannot be animated, tokens of another
    /// checkpoint. The message says what to change; servers answer it as the client's error.
    #[error("{0}")]
    Refused(String),
    /// A checkpoint that cannot be read, or models that do not belong together.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// The sentence encoder failed.
    #[error(transparent)]
    Text(#[from] TextError),
    /// The tensor library failed while running a model.
    #[error("running the model: {0}")]
    Tensor(#[from] candle_core::Error),
    /// Anything else that went wrong inside the models (loading, skeleton graphs), with its
    /// chain of causes.
    #[error("{0:#}")]
    Failed(#[from] anyhow::Error),
}

impl ModelError {
    /// A refusal with the message the client will read.
    pub fn refused(message: impl Into<String>) -> ModelError {
        ModelError::Refused(message.into())
    }
}
