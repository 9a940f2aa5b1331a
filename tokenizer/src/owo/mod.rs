//! OwO, the ontology-aware skeleton graph encoder (NEC 4.2, appendix C.2-C.3): every joint of a
//! skeleton gets an identity embedding from its name, its place in the tree and its rest offsets,
//! and the skeleton gets a global embedding. Pretrained by self-supervision, then frozen; the
//! tokenizer reads skeletons only through it.

pub mod graph;
pub mod model;
pub mod pretrain;
pub mod variants;

pub use graph::{GraphBatch, SkeletonGraph};
pub use model::{Owo, OwoConfig, SkeletonEmbedding};
