//! Preparing clips for the models: semantic joint labels, cleaning and normalisation (NEC
//! appendix B), and augmentation (NEC appendix C.1). None of it touches what users get back.

pub mod augment;
pub mod clean;
pub mod labels;
