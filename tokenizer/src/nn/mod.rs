//! The small neural-network toolkit the models share, on candle's CPU backend.
//!
//! Written here rather than taken from `candle-nn` where candle's own pieces fall short for
//! training on the CPU: parameters initialised from a seeded generator (candle's CPU generator
//! cannot be seeded), layer norm and softmax with a backward pass (the fused ones have none), an
//! AdamW whose state can be saved (candle's is private), and linear layers that flatten to one
//! 2-D matmul (candle broadcasts the weight into many small ones otherwise).

pub mod adamw;
pub mod checkpoint;
pub mod flops;
pub mod layers;
pub mod params;

pub use adamw::{AdamW, AdamWConfig};
pub use checkpoint::{CardError, DataRecord, ModelCard, load_card};
pub use layers::{Activation, Attention, FeedForward, LayerNorm, Linear, TransformerLayer};
pub use params::Params;
