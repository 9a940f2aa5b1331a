//! anymo's model registry: the checkpoints (in a folder or built into the binary) and their
//! typed model cards; every use of the models (tokens and transfer, generation and edits on a
//! user's skeleton, search over the store); the training recipes and loops; and the
//! evaluations of `../shared/docs/EVAL.md`.

pub mod card;
pub mod checkpoint;
pub mod codecs;
pub mod data;
pub mod error;
pub mod eval;
pub mod generation;
pub mod quality;
pub mod recipe;
pub mod search;
pub mod studio;
pub mod tokens;
pub mod train;
