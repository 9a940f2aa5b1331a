//! Datasets for training and evaluation: the splits of EVAL.md and the window loader.

pub mod loader;
pub mod split;

pub use loader::{Batch, LoaderConfig, TrainingClip, WindowLoader};
pub use split::{Split, split_of};
