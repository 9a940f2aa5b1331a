//! Text- and skeleton-conditioned motion token generation on TAT's tokens (NEC appendix D with
//! MoMask's recipe): a masked transformer over the first RVQ layer, a residual transformer for
//! the deeper layers, an autoregressive variant behind the same trait, a length predictor,
//! token-level editing, caption augmentation for training, and the text-motion evaluator that
//! scores all of them.

pub mod anchors;
pub mod autoregressive;
pub mod condition;
pub mod corpus;
pub mod evaluator;
pub mod generate;
pub mod length;
pub mod masked;
pub mod paraphrase;
pub mod residual;
pub mod sampling;
pub mod token_model;
pub mod trunk;

pub use anchors::CaptionAnchors;
pub use condition::Condition;
pub use corpus::{Crop, TokenClip};
pub use evaluator::{Evaluator, EvaluatorConfig};
pub use generate::{GenerationError, Generator, GeneratorConfig, Request};
pub use token_model::TokenModel;
