//! Motion search. So far: the vector index (exact scan behind a trait, persisted, updated in
//! place) and reciprocal rank fusion. The tantivy full-text side, filters over clip metadata and
//! the `anymo search` command come with the rest of the search issue.

pub mod fusion;
pub mod vector;

pub use fusion::reciprocal_rank_fusion;
pub use vector::{ExactIndex, Hit, IndexError, VectorIndex};
