//! Motion search: a tantivy full-text index and exact vector indexes (caption embeddings and
//! motion embeddings) over a motion library, fused by reciprocal rank fusion under metadata
//! filters, persisted on disk and updated in place. The crate knows nothing of the store or of
//! the models that make the vectors; `anymo-services` feeds it.

pub mod benchmark;
pub mod document;
pub mod filter;
pub mod fusion;
pub mod library;
pub mod metrics;
mod sketch;
pub mod text;
pub mod vector;

pub use document::ClipDocument;
pub use filter::Filter;
pub use fusion::reciprocal_rank_fusion;
pub use library::{Entry, Found, Library, Page, Query, Ranks, SearchError, Space, Spaces, Weights};
pub use text::Snippet;
pub use vector::{ExactIndex, Hit, IndexError, VectorIndex};
