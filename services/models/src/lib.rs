//! Training, evaluation and use of anymo's motion models: data from a manifest, the training
//! loops with resumable checkpoints, the evaluation protocol of EVAL.md and the shipped
//! checkpoints.

pub mod card;
pub mod checkpoint;
pub mod codecs;
pub mod data;
pub mod evaluate;
pub mod generation;
pub mod generation_eval;
pub mod search;
pub mod studio;
pub mod tokens;
pub mod train;
