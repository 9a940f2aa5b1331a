//! TAT, the topology-agnostic tokenizer (NEC 4.3, SATA 3.2-3.3): motion of any skeleton becomes
//! a sequence of residual-VQ tokens that carry no skeleton, and tokens become motion on any
//! skeleton. Also the zero-padded RVQ-VAE baseline it is measured against.

pub mod anchor;
pub mod codec;
pub mod fk;
pub mod model;
pub mod objective;
pub mod representation;
pub mod rvq;
pub mod temporal;
pub mod window;

pub use codec::{Baseline, BaselineConfig, Codec, Tat, TokenizerConfig};
pub use model::{Fusion, TatConfig};
pub use representation::{Basis, Representation};
