//! The small neural-network toolkit the models share, on candle's CPU backend.
//!
//! Written here rather than taken from `candle-nn` where candle's own pieces fall short for
//! training on the CPU: parameters initialised from a seeded generator (candle's CPU generator
//! cannot be seeded), layer norm and softmax with a backward pass (the fused ones have none), an
//! AdamW whose state can be saved (candle's is private), and linear layers that flatten to one
//! 2-D matmul (candle broadcasts the weight into many small ones otherwise).
//!
//! Layer norm, softmax, ReLU and the bias add are fused operations with their own backward pass,
//! and per-window terms are repeated by a product with ones (`repeat`): candle's backward gives
//! every graph node a zeroed buffer and an add, and sums a broadcast over leading dimensions one
//! index division per element, so fewer, larger nodes made a TAT training step 1.4x faster
//! (`cargo bench -p anymo-tokenizer --bench train_step`).

pub mod adamw;
pub mod bias;
pub mod checkpoint;
mod cpu;
pub mod flops;
pub mod layer_norm;
pub mod layers;
pub mod params;
pub mod relu;
pub mod repeat;
pub mod snapshot;
pub mod softmax;

pub use adamw::{AdamW, AdamWConfig};
pub use bias::add_bias;
pub use checkpoint::{CardError, DataRecord, ModelCard, load_card};
pub use layer_norm::LayerNorm;
pub use layers::{Activation, Attention, FeedForward, Linear, TransformerLayer};
pub use params::Params;
pub use relu::relu;
pub use repeat::{repeat_dim1, repeat_rows};
pub use softmax::softmax_with_backward;
